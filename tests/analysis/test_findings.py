"""The gates a claim must pass before a report prints it, on synthetic cases made to pass
and to fail: a twistless torus only where a frequency turns by more than its own drift
between neighbouring regular cells on one fundamental, never along seeded starts; a
resonance only within the frequencies' drift and not an n:1 relation between two of them;
a spread only where the ensemble's orbits separate; a family's stable stretch only where
no index nears +-1 faster than it moves between members; all and none only by the count;
an island only where the grid encloses it; an onset's uncertainty from its parts."""
import numpy as np
import pytest

from survey.analysis.findings import (decorrelated, family_stability, how_many, islands, regions,
                                     resonant, twists)
from survey.analysis.onset import budget
from survey.catalog.regimes import Regime

X = np.linspace(0.0, 2.0, 21)
NAMES = ["shape_1", "shape_2"]


def turning(drift=0.0, regime=None, axis="delta"):
    """shape_1 turns at x = 1.3 (a minimum), shape_2 grows: one finding each."""
    nu = np.stack([(X - 1.3) ** 2 + 0.5, 0.2 + 0.1 * X], axis=-1)
    regime = np.full(X.size, Regime.TORUS) if regime is None else regime
    return {f.key: f for f in twists(X, nu, np.full(nu.shape, drift), regime, axis, NAMES)}


def test_a_frequency_that_turns_above_its_drift_is_a_twistless_torus():
    found = turning()
    assert found["twist.shape_1"].passed and found["twist.shape_1"].numbers["at"] == [1.3]
    assert "turns" in found["twist.shape_1"].text()
    assert found["twist.shape_2"].passed and found["twist.shape_2"].numbers["turns"] == 0
    assert "changes monotonically" in found["twist.shape_2"].text()


def test_steps_within_the_drift_prove_nothing():
    """Steps of 1e-2 around the turn against a drift of 1e-2 per cell: not seen to move."""
    found = turning(drift=1e-2)
    assert found["twist.shape_1"].numbers["turns"] == 0
    flat = turning(drift=1.0)["twist.shape_2"]
    assert not flat.passed and flat.text().startswith("Not established")


def test_no_twist_across_a_cell_of_another_regime():
    regime = np.full(X.size, Regime.TORUS)
    regime[13] = Regime.CHAOTIC                 # the turn's middle cell
    assert turning(regime=regime)["twist.shape_1"].numbers["turns"] == 0


def test_a_relabelled_fundamental_is_no_twist():
    """A column that jumps from 4.98 to 1.71 between neighbours (two fundamentals swapped
    by the labelling) and back is not a frequency turning."""
    nu = np.stack([np.where(X < 1.0, 4.98 + 0.01 * X, 1.71 - 0.01 * X),
                   0.2 + 0.1 * X], axis=-1)
    found = twists(X, nu, np.zeros(nu.shape), np.full(X.size, Regime.TORUS), "delta", NAMES)
    assert found[0].numbers["turns"] == 0


def test_nothing_turns_along_seeded_starts():
    found = turning(axis="seed")
    assert len(found) == 1 and "no order" in next(iter(found.values())).text()


@pytest.mark.parametrize("m, nu, drift, expected", [
    ([2, -3, 0], [0.3, 0.2, 0.47], [1e-9, 1e-9, 0.0], True),       # 2:3 within the drift
    ([2, -3, 0], [0.3, 0.2 + 1e-6, 0.47], [1e-9, 1e-9, 0.0], False),   # off it by more
    ([1, -2, 0], [0.4, 0.2, 0.47], [1e-9, 1e-9, 0.0], False),      # a harmonic, 2:1
    ([1, -1, 0], [0.2, 0.2, 0.47], [1e-9, 1e-9, 0.0], False),      # a symmetry's 1:1
    ([1, 1, -1], [0.1, 0.2, 0.3], [1e-9, 1e-9, 1e-9], True),       # three frequencies
    ([0, 0, 0], [0.1, 0.2, 0.3], [1e-9, 1e-9, 1e-9], False),       # none searched
])
def test_a_resonance_is_within_the_drift_and_no_harmonic(m, nu, drift, expected):
    assert bool(resonant(np.array(m), np.array(nu), np.array(drift))) is expected


def test_an_ensemble_that_cannot_separate_by_its_horizon_is_no_sample():
    """ln(1e9) = 20.7: at FTLE 0.1 orbits 1e-9 apart separate by t ~ 207, within half of
    T = 2000; at FTLE 0.004 by ~5200, past it: that cell's spread is flagged."""
    irregular = np.array([True, True, False])
    fast = decorrelated([0.1, 0.2, 0.0], [2000.0] * 3, 1e-9, irregular)
    assert fast.passed and fast.numbers["slow"] == 0
    slow = decorrelated([0.1, 0.004, 0.0], [2000.0] * 3, 1e-9, irregular)
    assert not slow.passed and slow.numbers["slow"] == 1
    assert "not that of independent orbits" in slow.text()


def test_a_stable_stretch_is_established_only_where_the_members_resolve_it():
    """Two stable stretches split by an unstable member; in the first, one index goes
    from 0.9 to 0.999 between members (nearer +-1 than it moves: it may leave the band and
    come back unseen), in the second every index stays well inside."""
    p = np.arange(7.0)
    real = np.array([[0.5, 0.8], [0.5, 0.9], [0.5, 0.999], [0.5, 1.2], [0.1, 0.3],
                     [0.12, 0.31], [0.14, 0.32]])
    stable = np.all(np.abs(real) <= 1, axis=1)
    first, second = family_stability(p, real, np.zeros(real.shape), stable, "energy")
    assert not first.passed and first.numbers["members"] == 3
    assert "between 1 pair of neighbouring members" in first.text()
    assert second.passed and second.text() == "Linearly stable for energy from 4 to 6 (3 members)"


def test_all_and_none_only_where_the_count_supports_them():
    assert how_many(51, 51) == "all 51" and how_many(0, 51) == "none of 51"
    assert how_many(50, 51) == "50 of 51" and how_many(0, 0) == "0 of 0"
    assert how_many(49, 49, "2 failed") == "all 49 (2 failed left out)"


def test_an_island_is_a_regular_region_the_grid_encloses():
    """A regular block ringed by chaos is an island; the same block moved to the grid's
    edge is not (it may go on beyond the grid), nor is a region touching the edge by one
    cell, nor one touching the inaccessible cells (the shell's end, not another regime);
    regions are connected along the axes, not diagonally."""
    C, T = Regime.CHAOTIC, Regime.TORUS
    grid = np.full((6, 7), C)
    grid[2:4, 2:5] = T                          # enclosed: 6 cells
    grid[0, 0] = T                              # a corner: cut by the edge
    found = islands(grid)
    assert found.passed and found.numbers == {"islands": 1, "edge": 1, "sizes": [6]}
    grid[2:4, 2:5] = C
    grid[1:3, 4:7] = T                          # reaches the right edge
    found = islands(grid)
    assert not found.passed and "touches its edge" in found.text()
    assert not islands(np.full((3, 3), C)).passed
    shell = np.full((6, 7), C)
    shell[2:4, 2:5] = T
    shell[4, 3] = Regime.INACCESSIBLE           # where the energy shell ends: an edge too
    assert not islands(shell).passed
    diagonal = np.full((5, 5), C)
    diagonal[1, 1] = diagonal[2, 2] = diagonal[3, 3] = T
    assert islands(diagonal).numbers["sizes"] == [1, 1, 1]
    line = np.array([T, C, T, T, C, T])         # along one axis: the middle run only
    assert [(list(c), e) for c, e in regions(line == T)] == \
        [([0], False), ([2, 3], True), ([5], False)]


def test_an_onset_budget_adds_its_contributions_and_fails_without_an_onset():
    found = {"estimate": 4.17, "error": 0.0003}
    b = budget(found, {"seed": {"estimate": 4.1704}, "rounding": {"estimate": 4.17}})
    assert [p[0] for p in b.parts] == ["step", "seed", "rounding"]
    assert b.total == pytest.approx(np.hypot(0.0003, 0.0004))
    lost = budget(found, {"horizon": None})
    assert lost.parts[1][1] == np.inf and lost.total == np.inf
