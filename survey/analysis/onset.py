"""Where a one-parameter family leaves the tori, and the runs of equal regimes along it."""
from __future__ import annotations

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


def runs(values) -> list[tuple[int, int]]:
    """(first, last) index of each run of equal values."""
    edges = np.flatnonzero(np.diff(values)) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges - 1, [len(values) - 1]])
    return list(zip(starts.tolist(), ends.tolist()))
