"""Where a one-parameter family leaves the tori, and the runs of equal regimes along it."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..catalog.regimes import IRREGULAR, REGULAR


def onset(x: np.ndarray, regime: np.ndarray) -> dict | None:
    """Where a one-parameter family leaves the tori: the last regular cell before the first
    irregular one (chaotic or sticky), and from where on every cell is irregular. None if
    the family never changes."""
    regular, irregular = np.isin(regime, REGULAR), np.isin(regime, IRREGULAR)
    if not regular.any() or not irregular.any():
        return None
    first_bad = int(np.flatnonzero(irregular)[0])
    before = np.flatnonzero(regular[:first_bad])
    if not before.size:
        return None
    last_good = int(before[-1])
    solid = first_bad
    for i in range(regime.size - 1, -1, -1):
        if not irregular[i]:
            solid = i + 1
            break
    return {"last_regular": float(x[last_good]), "first_irregular": float(x[first_bad]),
            "estimate": 0.5 * (x[last_good] + x[first_bad]),
            "error": 0.5 * abs(x[first_bad] - x[last_good]),
            "all_irregular_from": float(x[solid]) if solid < x.size else None}


def verdicts_at(history: np.ndarray, level: int) -> np.ndarray:
    """Each cell's verdict at horizon `level` of its regime_history (..., horizon): the last
    one decided up to that level (a cell not run longer kept its verdict; -1 if none)."""
    upto = history[..., :level + 1]
    decided = np.sum(upto >= 0, axis=-1)
    return np.where(decided > 0, np.take_along_axis(
        upto, np.maximum(decided - 1, 0)[..., None], -1)[..., 0], -1)


def onset_over_horizons(x: np.ndarray, regime: np.ndarray, history: np.ndarray,
                        factors) -> dict | None:
    """The onset of the final verdicts with an uncertainty that also covers how far it
    still moved with the horizon: half the grid step, or its distance to the onset at the
    horizon before the last (each cell's verdict there), whichever is larger. `by_horizon`:
    (horizon factor, the onset from the verdicts at that horizon, or None) for T/2, T, ...
    -- an onset still moving by the last horizon is not converged, and this says by how
    much."""
    found = onset(x, regime)
    if found is None:
        return None
    by = [(f, onset(x, verdicts_at(history, k))) for k, f in enumerate(factors)]
    shifts = [abs(o["estimate"] - found["estimate"]) for _, o in by[-2:-1] if o is not None]
    return {**found, "by_horizon": [(f, None if o is None else o["estimate"]) for f, o in by],
            "error": max([found["error"], *shifts])}


def runs(values) -> list[tuple[int, int]]:
    """(first, last) index of each run of equal values."""
    edges = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges - 1, [len(values) - 1]])
    return list(zip(starts.tolist(), ends.tolist()))


class Budget(NamedTuple):
    """An onset's uncertainty, contribution by contribution: `parts` (what, its size, the
    onset that variant found or None) -- the grid's half-step or the bisection's last
    half-interval, then each [check] variant's shift of the estimate -- and `total`, their
    root sum of squares (independent sources); infinite where a variant finds no onset at
    all, for then the onset itself is not established."""
    estimate: float
    parts: list
    total: float


def budget(found: dict, variants: dict) -> Budget:
    """The Budget of an onset `found` (onset or onset_over_horizons) against the onsets
    its [check] variants found, by name (None: that run has no onset)."""
    parts = [("step", found["error"], None)]
    for name, other in variants.items():
        shift = np.inf if other is None else abs(other["estimate"] - found["estimate"])
        parts.append((name, shift, None if other is None else other["estimate"]))
    total = float(np.sqrt(sum(p[1] ** 2 for p in parts)))
    return Budget(found["estimate"], parts, total)
