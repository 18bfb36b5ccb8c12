"""Refinement as a pure function of the cells' results (analysis.refine), against regime
fields whose boundaries are known exactly."""
import numpy as np
import pytest

from survey.analysis.refine import Lattice, Rule, boundaries, plan
from survey.catalog.regimes import Regime

TORUS, CHAOTIC, UNDETERMINED = int(Regime.TORUS), int(Regime.CHAOTIC), int(Regime.UNDETERMINED)


def run(lattice, rule, field, rng=None, batch=None):
    """Refine to the end with `field(point) -> (regime, value)` standing in for the cells'
    integrations: each round computes the needed cells, all of them, or (rng) a random
    part of at most `batch` -- results arriving in any order."""
    coords = [lattice.axis_values(k) for k in range(len(lattice.base))]
    known, rounds = {}, 0
    while True:
        p = plan(lattice, rule, known)
        if p.done:
            return p, known, rounds
        todo = p.needed
        assert todo.size, "not done, yet nothing needed"
        if rng is not None:
            todo = rng.permutation(todo)[:rng.integers(1, batch + 1)]
        for cell in todo.tolist():
            at = lattice.indices(cell)
            known[cell] = field(*[c[i] for c, i in zip(coords, at)])
        rounds += 1


def step_at(x_star):
    return lambda x: (TORUS if x < x_star else CHAOTIC, np.nan)


def test_the_lattice_keeps_the_grid_and_halves_its_intervals():
    base = np.array([0.0, 0.1, 0.3, 1.0])          # uneven
    lat = Lattice((base,), 3)
    x = lat.axis_values(0)
    assert x.size == 3 * 8 + 1
    assert np.array_equal(x[::8], base)             # the grid itself, bit for bit
    assert np.all(np.diff(x) > 0)
    np.testing.assert_allclose(x[1:8], 0.1 * np.arange(1, 8) / 8, rtol=1e-15)
    assert lat.level(np.arange(9)).tolist() == [0, 3, 2, 3, 1, 3, 2, 3, 0]
    lat2 = Lattice((base, np.array([1.0, 2.0])), 2)
    ids = lat2.ids(np.array([4, 2, 1]), np.array([2, 0, 4]))
    assert lat2.level(ids).tolist() == [1, 1, 2]    # a node's level: its finest index
    assert lat2.base_ids().size == 8


@pytest.mark.parametrize("x_star", [0.4137, 0.5, 0.0001, 0.999])
def test_one_axis_bisects_a_boundary_to_the_last_level(x_star):
    """A step from torus to chaos at x_star: after the grid of 11 points, each level adds
    one cell, and the boundary is located to the finest spacing."""
    lat = Lattice((np.linspace(0.0, 1.0, 11),), 5)
    p, known, _ = run(lat, Rule(), step_at(x_star))
    assert p.cells.size == 11 + 5
    x = lat.axis_values(0)[p.cells]
    regime = np.array([known[c][0] for c in p.cells.tolist()])
    [b] = boundaries(x, regime, lat.level(p.cells))
    assert b["left"] < x_star <= b["right"]
    assert b["error"] == pytest.approx(0.1 / 2 ** 5 / 2)
    assert b["into"] == "irregular" and b["level"] == 5


def test_tolerance_stops_the_bisection():
    lat = Lattice((np.linspace(0.0, 1.0, 11),), 10)
    p, known, _ = run(lat, Rule(tolerance=0.01), step_at(0.4137))
    x = lat.axis_values(0)[p.cells]
    [b] = boundaries(x, np.array([known[c][0] for c in p.cells.tolist()]),
                     lat.level(p.cells))
    assert 0.005 < b["right"] - b["left"] <= 0.01        # 0.1 / 2^4 = 0.00625


def test_the_cells_do_not_depend_on_the_order_results_arrive_in():
    """Results arriving one by one, in random order and batches, give the cells all at
    once give -- also where the budget ends the refinement inside a level."""
    lat = Lattice((np.linspace(0.0, 1.0, 9),), 6)

    def field(x):
        # several boundaries and an undetermined patch
        if 0.2 < x < 0.2137 or 0.61 < x < 0.7:
            return CHAOTIC, np.nan
        return (UNDETERMINED if 0.8 < x < 0.801 else TORUS), np.nan
    for rule in (Rule(), Rule(by="regime"), Rule(max_cells=20)):
        reference, _, _ = run(lat, rule, field)
        for seed in range(5):
            p, _, _ = run(lat, rule, field, np.random.default_rng(seed), batch=3)
            assert np.array_equal(p.cells, reference.cells)
    assert reference.cells.size <= 20


def test_the_budget_ends_refinement_before_a_level_that_would_pass_it():
    lat = Lattice((np.linspace(0.0, 1.0, 11),), 6)
    field = lambda x: ((TORUS if int(x * 37) % 2 else CHAOTIC), np.nan)   # many boundaries
    full, _, _ = run(lat, Rule(), field)
    levels = lat.level(full.cells)
    for budget in (11, 25, 40):
        p, _, _ = run(lat, Rule(max_cells=budget), field)
        kept = lat.level(p.cells)
        top = kept.max()
        # whole levels only: every cell of the full refinement up to the top level kept
        assert np.array_equal(p.cells, full.cells[levels <= top])
        assert p.cells.size <= budget
        assert top == levels.max() or budget < full.cells[levels <= top + 1].size
    assert lat.level(run(lat, Rule(max_cells=25), field)[0].cells).max() < levels.max()


def test_an_indicator_jump_splits_where_classes_agree():
    """A dip of an indicator inside one regime (to 0.01 from 0.2, narrower than two grid
    steps): found by its jumps, not by the regimes; by a ratio the refinement goes on while
    neighbours differ by more than its factor, so the minimum is found to about that
    factor -- with a fraction of the cells of the finest uniform grid."""
    lat = Lattice((np.linspace(0.0, 1.0, 11),), 8)
    field = lambda x: (CHAOTIC, 0.2 - 0.19 * np.exp(-((x - 0.3337) / 0.05) ** 2))
    flat, _, _ = run(lat, Rule(), field)
    assert flat.cells.size == 11
    p, known, _ = run(lat, Rule(indicator="ftle", ratio=1.1), field)
    values = np.array([known[c][1] for c in p.cells.tolist()])
    x = lat.axis_values(0)[p.cells]
    assert p.cells.size < 0.1 * lat.shape[0]
    assert values.min() < 0.011 and abs(x[np.argmin(values)] - 0.3337) < 0.01
    # an absolute jump of 0.02 stops once neighbours differ by less, far from it
    p, known, _ = run(lat, Rule(indicator="ftle", jump=0.02), field)
    assert min(known[c][1] for c in p.cells.tolist()) > 0.011


def test_two_axes_refine_the_squares_a_boundary_crosses():
    """A disk of tori in a chaotic square: the squares the circle crosses are split to the
    last level, the others are not; far fewer cells than the finest uniform grid."""
    lat = Lattice((np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9)), 3)
    r0 = 0.6137
    field = lambda x, y: (TORUS if x * x + y * y < r0 * r0 else CHAOTIC, np.nan)
    p, known, _ = run(lat, Rule(), field)
    assert p.cells.size < 0.5 * np.prod(lat.shape)
    assert lat.level(p.cells).max() == 3
    # every finest square (spacing 2/64) the circle crosses has its four corners computed
    xs, ys = lat.axis_values(0), lat.axis_values(1)
    have = set(p.cells.tolist())
    for i in range(lat.shape[0] - 1):
        for j in range(lat.shape[1] - 1):
            corners = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
            inside = [xs[a] ** 2 + ys[b] ** 2 < r0 * r0 for a, b in corners]
            if len(set(inside)) > 1:
                assert all(int(lat.ids(a, b)) in have for a, b in corners), (i, j)
    # and results in any order give the same cells
    again, _, _ = run(lat, Rule(), field, np.random.default_rng(1), batch=4)
    assert np.array_equal(again.cells, p.cells)


def test_boundaries_skip_undecided_cells():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    regime = np.array([TORUS, UNDETERMINED, CHAOTIC, CHAOTIC, TORUS])
    found = boundaries(x, regime, np.zeros(5, dtype=int))
    assert [(b["left"], b["right"], b["into"]) for b in found] == [
        (0.0, 2.0, "irregular"), (3.0, 4.0, "regular")]
