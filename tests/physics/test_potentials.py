"""The perimetric and areal potentials against the side-length reference (N = 3, 4;
d = 2, 3; unequal masses), near collinear triangles, and bad names. The battery every term
passes (finite differences, bounds) is tests/physics/test_terms.py."""
import numpy as np
import pytest
import reference
from conftest import full_rhs

from survey.physics.geometry import perimeter
from survey.physics.system import System
from survey.physics.terms import make_potential

PARAMS = {  # non-default parameters, so that no special case (k = 2) hides a bug
    "perimetric_power": dict(coupling=0.7, exponent=3.0),
    "perimetric_yukawa": dict(coupling=2.0, gamma=0.3),
    "perimetric_barrier": dict(alpha=1.5, beta=0.4),
    "areal_power": dict(coupling=1.3, exponent=2.5),
    "areal_yukawa": dict(coupling=1.0, gamma=0.5),
    "areal_barrier": dict(alpha=2.0, beta=1.0),
}
CASES = [(name, N, d) for name in PARAMS for N in (3, 4) for d in (2, 3)]


def make_case(name, N, d, seed=0):
    rng = np.random.default_rng(seed)
    system = System.create(masses=rng.uniform(0.5, 2.0, N), dim=d, potential=name,
                           **PARAMS[name])
    y = rng.normal(size=system.n)
    return system, y


@pytest.mark.parametrize("name,N,d", CASES)
def test_kernel_agrees_with_numpy_reference(name, N, d):
    system, y = make_case(name, N, d, seed=3)
    rng = np.random.default_rng(4)
    tangent = rng.normal(size=system.n)
    state = np.concatenate([y, tangent])
    ref = reference.rhs(state, system, n_tangent=1)
    np.testing.assert_allclose(full_rhs(system, state, n_tan=1), ref, rtol=1e-6,
                               atol=1e-7 * np.abs(ref).max())
    assert system.energy(y) - system.kinetic_energy(y) == pytest.approx(
        reference.potential(y[:system.n // 2].reshape(N, d), system), rel=1e-12)


def test_forces_stay_finite_and_bisect_near_collinear_triangle():
    """Vector forms keep full accuracy where the side-length chain rule loses it."""
    system = System.create()
    eps = 1e-9
    q = np.array([[-1.0, 0.0], [0.3, eps], [1.0, 0.0]])
    y = system.state(q, np.zeros((3, 2)))
    F = full_rhs(system, y)[6:].reshape(3, 2)
    P = perimeter(*system.triangle(y))
    # middle body: unit vectors to its neighbours nearly cancel, leaving a force of order eps
    assert abs(F[1, 0]) < 1e-8 * P and np.all(np.isfinite(F))
    # end bodies: U'(P) times two nearly parallel unit vectors
    np.testing.assert_allclose(F[0], [2 * P, 0.0], atol=1e-8 * P)


def test_areal_forces_are_parallel_to_altitudes():
    system = System.create(potential="areal_barrier")
    q = np.array([[0.1, -0.4], [1.3, 0.2], [-0.2, 0.9]])
    F = full_rhs(system, system.state(q, np.zeros((3, 2))))[6:].reshape(3, 2)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        assert abs(np.dot(F[i], q[k] - q[j])) < 1e-13 * np.linalg.norm(F[i])
    np.testing.assert_allclose(F.sum(axis=0), 0.0, atol=1e-14)


@pytest.mark.parametrize("bad,match", [
    (("perimetric_cubic", {}), "unknown triplet potential"),
    (("perimetric_power", {"k": 2}), "no parameter 'k'"),
    (("perimetric_yukawa", {"gamma": -1.0}), "gamma"),
    (("areal_power", {"coupling": "x"}), "finite number"),
])
def test_bad_potential_names_and_parameters(bad, match):
    with pytest.raises(ValueError, match=match):
        make_potential(*bad)


def test_a_triangles_three_reciprocals_from_one_division_at_every_scale():
    """forces.reciprocals: each side's 1 / L within a few units of roundoff, for triangles
    from 1e-300 to 1e300 across (where the sides' plain product under- or overflows: the
    isosceles plane restarts a triple collision with all three near 1e-150) and with one
    side 1e-300 times the others; and, where nothing under- or overflows, the bits of the
    unscaled products (the scaling by a power of two is exact)."""
    from survey.physics.forces import reciprocals
    rng = np.random.default_rng(3)
    for scale in (1e-300, 1e-150, 1e-20, 1.0, 1e20, 1e150, 1e300):
        for _ in range(20):
            q = rng.normal(size=(3, 2)) * scale
            L = [float(np.hypot(*(q[(i + 1) % 3] - q[i]))) for i in range(3)]
            r = reciprocals(*L)
            assert all(abs(ri * Li - 1.0) < 1e-15 for ri, Li in zip(r, L)), (scale, L, r)
            if 1e-20 <= scale <= 1e20:
                p = 1.0 / (L[0] * (L[1] * L[2]))
                assert r == (p * (L[1] * L[2]), p * (L[0] * L[2]), p * (L[0] * L[1]))
    thin = reciprocals(1.0, 1.0, 1e-300)
    assert thin == pytest.approx((1.0, 1.0, 1e300), rel=1e-15)
