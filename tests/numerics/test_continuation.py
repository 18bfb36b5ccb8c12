"""Pseudo-arclength continuation stays on its branch: on synthetic families whose answer is
known, y^2 - p^2 = eps. For eps > 0 two branches pass a small gap (2 sqrt(eps)) apart
where they nearly cross, and the other branch runs straight on where this one turns: a
predictor along the tangent lands beside the other branch, the tangent and chord barely
turn, and only the family's orientation (the sign of det [A; t]) says that the corrector
changed branch. For eps = 0 they cross: a branch point on the family, reported as one."""
import numpy as np
import pytest

from survey.numerics.continuation import follow


def hyperbola(eps):
    """solve(x, row, target) of the family y^2 - p^2 = eps in x = (y, p): Newton on the
    equation bordered by row . x = target; (member, x, A) or None."""
    def solve(x, row, target):
        x = np.array(x, dtype=float)
        for _ in range(40):
            y, p = x
            A = np.array([[2.0 * y, -2.0 * p]])
            F, r = y * y - p * p - eps, target - row @ x
            if abs(F) < 1e-13 and abs(r) < 1e-13:
                return x.copy(), x.copy(), A
            x = x + np.linalg.solve(np.vstack([A, row]), [-F, r])
            if not np.all(np.isfinite(x)):
                return None
        return None
    return solve


@pytest.mark.parametrize("steps", [2, 4, 8, 16])
def test_a_family_does_not_cross_a_small_gap_to_the_branch_that_runs_straight_on(steps):
    """From y = +sqrt(1 + eps) at p = -1 to p = 1, eps = 1e-4: every member on the upper
    branch (y > 0), its lowest at the gap, y = sqrt(eps), and no branch point reported.
    Before the orientation test, the family ran on along y = -sqrt(p^2 + eps) and ended at
    y = -1, called complete."""
    eps = 1e-4
    branch = follow(hyperbola(eps), np.array([np.sqrt(1 + eps), -1.0]), 1.0, steps, {})
    y = np.array([m[0][0] for m in branch.members])
    assert branch.complete and branch.members[-1][0][1] == pytest.approx(1.0)
    assert np.all(y > 0)
    assert y.min() == pytest.approx(np.sqrt(eps), rel=1e-2)
    assert not branch.found


def test_a_branch_point_on_the_family_is_found_and_passed():
    """eps = 0: the branches y = -p and y = p cross at the origin. The family from (1, -1)
    goes straight through it (a branch point, bisected to where the orientation changes)
    and on to (-1, 1)."""
    branch = follow(hyperbola(0.0), np.array([1.0, -1.0]), 1.0, 4, {})
    assert branch.complete
    (at,) = branch.found
    assert at.test == "branch point" and np.linalg.norm(at.x) < 1e-6
    assert branch.members[-1][0] == pytest.approx([-1.0, 1.0])


def test_a_crossings_accuracy_is_its_distance_from_an_independent_estimate():
    """Where an index passes +1 the bisection reads the sign of b - 1 at the crossing,
    where a colliding pair knows b only to ~1e-8; the members either side know it to
    1e-12, and the zero of b - 1 interpolated between them is a second estimate: the
    accuracy printed is how far the two lie apart (never less than the bracket)."""
    from types import SimpleNamespace as NS

    from survey.numerics.continuation import Located
    from survey.numerics.periodic import _accuracy

    def orbit(p):      # one pair through +1 at p = 2 (b = 1 + 17 (2 - p)), one elliptic
        return NS(indices=np.array([-0.3 + 0j, 1.0 + 17.0 * (2.0 - p) + 0j]),
                  index_error=1e-12)
    before, after = orbit(1.9999), orbit(2.0001)
    where = {id(before): 1.9999, id(after): 2.0001}
    bisected = Located("circle", before, after, np.array([0.0, 2.0 + 3e-9]), 1e-13,
                       orbit(2.0))
    assert _accuracy(bisected, where, 1.0) == pytest.approx(3e-9, rel=1e-3)
    exact = bisected._replace(x=np.array([0.0, 2.0]))
    assert _accuracy(exact, where, 1.0) == pytest.approx(2e-12)       # the floor
    fold = bisected._replace(test="fold", width=1e-6)
    assert _accuracy(fold, where, 1.0) == pytest.approx(1e-6)          # the bracket
