"""Fundamental frequencies labelled across a grid: NAFF lists a cell's shape frequencies in
the order it found their lines, so one family of tori shows as several branches. Here each
regular cell's shape frequencies are put in the order that continues its labelled
neighbours', so that a column of `frequency_labelled` is one frequency followed through
the grid (the rotation, a reconstruction phase, keeps its column). Where a labelled
frequency turns along a family is a finding (analysis.findings.twists)."""
from __future__ import annotations

from collections import deque

import numpy as np

from ..catalog.regimes import REGULAR
from ..catalog.variables import V


def labelled(ds, regime=None) -> np.ndarray:
    """`frequency` (..., fundamental) with each regular cell's shape frequencies permuted to
    match its grid neighbours (the mean of those already labelled, by relative distance);
    NaN in cells that are not regular. Cells are labelled breadth-first from the first
    regular cell of each connected patch (C order); a patch that no labelled cell touches
    continues the mean of every cell labelled before it."""
    f = np.abs(ds[V.frequency].values.astype(float))
    names = [str(n) for n in ds["fundamental_name"].values]
    shape_cols = [i for i, n in enumerate(names) if n.startswith("shape")]
    grid = f.shape[:-1]
    regime = ds[V.regime].values if regime is None else regime
    flat = f.reshape(-1, f.shape[-1])
    ok = (np.isin(regime, REGULAR).reshape(-1)
          & np.isfinite(flat[:, shape_cols]).any(axis=1))
    out = np.full_like(flat, np.nan)
    done = np.zeros(ok.size, dtype=bool)
    steps = [s for a in range(len(grid)) for s in _neighbours(grid, a)]
    for seed in np.flatnonzero(ok):
        if done[seed]:
            continue
        before = out[done][:, shape_cols]
        reference = _mean(before) if before.size else None
        _assign(out, flat, seed, shape_cols, reference)
        done[seed] = True
        queue = deque([seed])
        while queue:
            cell = queue.popleft()
            for step in steps:
                nxt = step(cell)
                if nxt is None or not ok[nxt] or done[nxt]:
                    continue
                near = [c for s in steps if (c := s(nxt)) is not None and done[c]]
                reference = _mean(out[near][:, shape_cols])
                _assign(out, flat, nxt, shape_cols, reference)
                done[nxt] = True
                queue.append(nxt)
    return out.reshape(f.shape)


def _mean(rows):
    """Column means over the finite entries (NaN where a column has none)."""
    known = np.isfinite(rows)
    count = known.sum(axis=0)
    total = np.where(known, rows, 0.0).sum(axis=0)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _neighbours(grid, axis):
    """The two steps along one grid axis, as functions of a flat index (None off the grid)."""
    stride = int(np.prod(grid[axis + 1:], dtype=int))
    size = grid[axis]

    def step(sign):
        def go(cell):
            at = (cell // stride) % size + sign
            return cell + sign * stride if 0 <= at < size else None
        return go
    return [step(-1), step(+1)]


def _assign(out, flat, cell, cols, reference):
    """Row `cell` of out: flat's row with its shape frequencies in the columns that match
    `reference` best (greedy on relative distance; with no reference, fastest first)."""
    out[cell] = flat[cell]
    values = flat[cell, cols]
    known = [i for i in range(len(cols)) if np.isfinite(values[i])]
    if reference is None or not np.isfinite(reference).any():
        order = sorted(known, key=lambda i: -values[i])
        slots = list(range(len(order)))
    else:
        pairs = sorted((abs(values[i] - reference[j]) / reference[j], i, j)
                       for i in known for j in range(len(cols)) if np.isfinite(reference[j]))
        order, slots = [], []
        for _, i, j in pairs:
            if i not in order and j not in slots:
                order.append(i)
                slots.append(j)
        free = [j for j in range(len(cols)) if j not in slots]
        for i in known:
            if i not in order:
                order.append(i)
                slots.append(free.pop(0))
    row = np.full(len(cols), np.nan)
    for i, j in zip(order, slots):
        row[j] = values[i]
    out[cell, cols] = row
