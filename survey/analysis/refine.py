"""Adaptive refinement: which cells a refined survey adds where its cells disagree.

The cells of a refined survey are nodes of a lattice: each interval of the base grid's axes
halved `levels` times. A node's id is its flat (C order) index on that lattice, so an id
names the same point whatever order cells are found, computed or stored in, and a node's
level is the refinement step that first reaches it (0: the base grid).

- One axis: an interval between two cells is split -- its midpoint added -- where they
  disagree, while it is wider than `tolerance` and its midpoint is within `levels`: each
  regime boundary is bisected.
- Two axes: a square of four cells is split into four -- its edge midpoints and centre
  added -- where any two of its corners disagree.

What counts as disagreement (`Rule`): verdict classes that differ (regular, irregular, or
neither), or regimes that differ, or an indicator that jumps by more than `jump` or changes
by more than the factor `ratio`.

Which cells a refined survey holds is a pure function of the results of the cells it holds
(`plan`): level by level, each level whole or not at all within `max_cells`. So a survey
may compute a level's cells as soon as their parents are known (without waiting for the
rest of their level), resume from any subset of its cells, and `verify` can recompute the
cell set from an archive's own regimes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, NamedTuple

import numpy as np

from ..catalog.regimes import IRREGULAR, REGULAR
from ..catalog.variables import V

# what a cell contributes to the decisions: (regime, indicator value)
Known = Mapping[int, tuple[int, float]]


@dataclass(frozen=True)
class Lattice:
    """The nodes a refined survey can hold: base axis values (strictly increasing), each
    interval halved `levels` times."""

    base: tuple[np.ndarray, ...]
    levels: int

    @property
    def step(self) -> int:
        return 1 << self.levels

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple((b.size - 1) * self.step + 1 for b in self.base)

    def axis_values(self, axis: int) -> np.ndarray:
        """Coordinates of the lattice's nodes along an axis: base[i] + (base[i+1] - base[i])
        r / 2^levels, exactly base[i] at r = 0."""
        b = self.base[axis]
        i, r = np.divmod(np.arange(self.shape[axis]), self.step)
        inner = np.minimum(i, b.size - 2)
        frac = np.where(i < b.size - 1, r, self.step) / self.step
        values = b[inner] + (b[inner + 1] - b[inner]) * frac
        return np.where(r == 0, b[i], values)

    def indices(self, ids) -> tuple[np.ndarray, ...]:
        return np.unravel_index(np.asarray(ids, dtype=np.int64), self.shape)

    def ids(self, *indices) -> np.ndarray:
        return np.ravel_multi_index(indices, self.shape)

    def level(self, ids) -> np.ndarray:
        """The refinement step that first reaches each node: 0 on the base grid, else
        levels minus the trailing zero bits of its finest index off the base grid (the
        largest over its axes)."""
        out = np.zeros(np.shape(ids), dtype=np.int64)
        for j in self.indices(ids):
            r = j % self.step
            tz = np.zeros_like(r)
            for bit in range(self.levels):
                tz += (r % (2 << bit) == 0) & (r != 0)
            out = np.maximum(out, np.where(r == 0, 0, self.levels - tz))
        return out

    def base_ids(self) -> np.ndarray:
        grids = np.meshgrid(*[np.arange(b.size) * self.step for b in self.base],
                            indexing="ij")
        return np.sort(self.ids(*grids).ravel())


@dataclass(frozen=True)
class Rule:
    """When two cells disagree, and the limits of refinement."""

    by: str = "class"           # "class" (regular / irregular / neither) or V.regime
    indicator: str = ""         # and where this indicator jumps by more than `jump`,
    jump: float = np.inf
    ratio: float = np.inf       # or changes by more than this factor (positive values)
    tolerance: float = 0.0      # one axis: intervals no wider than this are not split
    max_cells: int = 1 << 62    # cells in all, the base grid's included

    def disagree(self, values: list[tuple[int, float]]) -> bool:
        regimes = [r for r, _ in values]
        keys = _classes(regimes) if self.by == "class" else regimes
        if len(set(keys)) > 1:
            return True
        x = [v for _, v in values if np.isfinite(v)]
        if len(x) < len(values):
            return False
        if min(x) > 0 and max(x) / min(x) > self.ratio:
            return True
        return max(x) - min(x) > self.jump


def _classes(regimes) -> list[int]:
    return [1 if r in REGULAR else 2 if r in IRREGULAR else 0 for r in regimes]


def known_from(ids, regime, values) -> dict[int, tuple[int, float]]:
    """What cells contribute to the decisions, by lattice id: (regime, indicator value)."""
    return dict(zip(np.asarray(ids).tolist(), zip(np.asarray(regime).tolist(),
                                                  np.asarray(values, dtype=float).tolist())))


class Plan(NamedTuple):
    cells: np.ndarray       # ids of the refined set, sorted, as far as it is decided
    needed: np.ndarray      # ids in it not known yet
    done: bool              # every decision taken: `cells` is the refined survey's set


def plan(lattice: Lattice, rule: Rule, known: Known) -> Plan:
    """The refined set that the known cells decide, level by level: a level's intervals
    (one axis) or squares (two) are split where their corners disagree; the level's new
    cells join if the total stays within max_cells, else refinement ends before it. An
    interval or square with a corner not yet known is pending: the cells its level adds
    are then a lower bound, enough to go on with (they join if the bound fits; once
    everything is known, `done`, the set is exact)."""
    if len(lattice.base) not in (1, 2):
        raise ValueError("refinement runs over one or two axes")
    cells = set(lattice.base_ids().tolist())
    if len(cells) > rule.max_cells:
        raise ValueError(f"the base grid has {len(cells)} cells, more than max_cells")
    items = _base_items(lattice)
    x = lattice.axis_values(0) if rule.tolerance > 0 and len(lattice.base) == 1 else None
    pending = False
    for level in range(lattice.levels):
        size = lattice.step >> level
        new, nxt = set(), []
        for item in items:
            corners = _corners(item, size, lattice)
            if any(c not in known for c in corners):
                pending = True
                continue
            if rule.disagree([known[c] for c in corners]) and _wide(item, size, x, rule):
                kids, sub = _split(item, size, lattice)
                new.update(kids)
                nxt += sub
        if not new or len(cells) + len(new) > rule.max_cells:
            break
        cells |= new
        items = nxt
    ids = np.array(sorted(cells), dtype=np.int64)
    needed = np.array([c for c in ids.tolist() if c not in known], dtype=np.int64)
    return Plan(ids, needed, not pending and not needed.size)


def _base_items(lattice: Lattice) -> list[tuple[int, ...]]:
    """The base grid's intervals or squares, by their lowest corner's lattice indices."""
    starts = [np.arange(b.size - 1) * lattice.step for b in lattice.base]
    return [tuple(int(v) for v in p) for p in np.stack(
        np.meshgrid(*starts, indexing="ij"), -1).reshape(-1, len(starts))]


def _corners(item, size, lattice) -> list[int]:
    if len(item) == 1:
        return [item[0], item[0] + size]
    i, j = item
    n = lattice.shape[1]
    return [i * n + j, (i + size) * n + j, i * n + j + size, (i + size) * n + j + size]


def _wide(item, size, x, rule) -> bool:
    """Whether an interval (of the lattice's coordinates x) is still wider than the
    tolerance (squares, or no tolerance: always)."""
    return x is None or x[item[0] + size] - x[item[0]] > rule.tolerance


def _split(item, size, lattice):
    """The cells that split an interval (its midpoint) or a square (edge midpoints and
    centre), and its halves or quarters."""
    h = size // 2
    if len(item) == 1:
        a = item[0]
        return {a + h}, [(a,), (a + h,)]
    i, j = item
    n = lattice.shape[1]
    kids = {(i + h) * n + j, i * n + j + h, (i + h) * n + j + h, (i + size) * n + j + h,
            (i + h) * n + j + size}
    return kids, [(i, j), (i + h, j), (i, j + h), (i + h, j + h)]


def boundaries(x: np.ndarray, regime: np.ndarray, level: np.ndarray) -> list[dict]:
    """Along one axis (cells sorted by x): each place where the verdict class changes
    between neighbouring decided cells (regular or irregular; undetermined and failed
    cells are skipped), located at the midpoint of the two with half their distance as
    its uncertainty -- after bisection, the bisection's last width."""
    cls = np.asarray(_classes(np.asarray(regime).tolist()))
    decided = np.flatnonzero(cls > 0)
    out = []
    for a, b in zip(decided[:-1], decided[1:]):
        if cls[a] != cls[b]:
            out.append({"left": float(x[a]), "right": float(x[b]),
                        "at": 0.5 * (x[a] + x[b]), "error": 0.5 * abs(x[b] - x[a]),
                        "into": "irregular" if cls[b] == 2 else "regular",
                        "level": int(max(level[a], level[b]))})
    return out


def as_grid(ds):
    """A refined survey over one axis as the one-axis grid it is: its cells, sorted along
    the axis, with the axis as their dimension (uneven: finer where it was refined), so
    that everything that reads a grid reads it. Any other Dataset is returned as it is."""
    if "cell" in ds.dims and "level" in ds.coords:
        axes = str(ds.attrs.get("grid_axes", "")).split()
        if len(axes) == 1 and axes[0] in ds.coords:
            return ds.swap_dims({"cell": axes[0]})
    return ds


def refined_axes(ds) -> list[str]:
    """The grid axes a refined survey's cells spread over ([] if it is not one)."""
    if "cell" not in ds.dims or "level" not in ds.coords:
        return []
    return [a for a in str(ds.attrs.get("grid_axes", "")).split() if a in ds.coords]


def painted(ds):
    """A refined survey over two axes as a picture on a grid: (x, y, rows), x and y the
    axis values its cells occupy, rows[i, j] the position along `cell` of the cell whose
    square -- its level's spacing, centred on it -- holds the grid point (x[i], y[j]),
    finer cells drawn over coarser ones: each point shows the cell nearest it in the
    refinement. Per-cell values v are drawn as v[rows]."""
    a, b = refined_axes(ds)
    shape = tuple(int(n) for n in ds["cell"].attrs["lattice_shape"])
    step = 1 << int(ds["cell"].attrs["max_level"])
    ids, level = ds["cell"].values, ds["level"].values
    ii, jj = np.unravel_index(ids, shape)
    I, first_i = np.unique(ii, return_index=True)
    J, first_j = np.unique(jj, return_index=True)
    rows = np.full((I.size, J.size), -1, dtype=np.int64)
    for c in np.lexsort((ids, level)):          # coarse first, finer over it
        h = (step >> int(level[c])) / 2
        i0, i1 = np.searchsorted(I, ii[c] - h), np.searchsorted(I, ii[c] + h, "right")
        j0, j1 = np.searchsorted(J, jj[c] - h), np.searchsorted(J, jj[c] + h, "right")
        rows[i0:i1, j0:j1] = c
    return ds[a].values[first_i], ds[b].values[first_j], rows


def cell_values(ds, idx) -> dict[str, float]:
    """The grid axes' values at cell `idx` (its index in the archive's cells), refined
    survey or not."""
    status = ds[V.status]
    return {a: float(ds[a].broadcast_like(status).transpose(*status.dims).values[idx])
            for a in refined_axes(ds) or list(status.dims)}


def cell_label(ds, idx) -> str:
    """'delta=4.2, energy=90': where cell `idx` lies on the grid axes."""
    return ", ".join(f"{a}={v:g}" for a, v in cell_values(ds, idx).items())
