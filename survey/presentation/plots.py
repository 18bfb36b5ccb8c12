"""Figures of a survey archive (matplotlib, no pyplot state).

Conventions: axes carry symbols and units, not long names; continuous indicators use
perceptually uniform colour maps with the clipping range written in the colourbar label;
regimes use a categorical palette; cells whose run did not finish (or that have no start)
are masked in their own colours with their counts in the legend -- never drawn as a value
of the indicator; point clouds are rasterised. Every function returns Figures; `draw`
writes a survey's, `save` any others.
"""
from __future__ import annotations

import itertools
import json
import textwrap
import warnings
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from ..analysis.classify import (horizon, regular_share, separation_share, stored_config,
                                 stored_table)
from ..analysis.refine import as_grid, painted, refined_axes
from ..catalog.indicators import OWNER, REGISTRY
from ..catalog.regimes import IRREGULAR, REGULAR, Regime, Thresholds
from ..catalog.status import Status
from ..catalog.variables import ENSEMBLE_MIN, V, label
from .sections import (
    MAX_SHELLS,
    crossing_surface,
    place_legends,
    section,
    section_axes,
    section_slice,
    shells,
    slice_slab,
)
from .style import REGIME_COLOURS, STATUS_COLOURS, grid_axes, map_axes, per_cell

# the indicators drawn as maps (and in one-axis scans), in the registry's order
MAPS = [(i.headline, i.map) for i in REGISTRY if i.map is not None]


def _on_grid(ds):
    """(x, y, grid) of a map: its axis values, and grid(v) -> per-cell values v on them
    (a refined survey's cells painted as the squares of their levels: analysis.refine)."""
    if refined_axes(ds):
        x, y, rows = painted(ds)
        return x, y, lambda v: np.asarray(v)[rows]
    a, b = grid_axes(ds)
    return ds[a].values, ds[b].values, np.asarray


def _cell_xy(ds, idx, a, b) -> tuple[float, float]:
    """Where cell `idx` (its index in the archive's cells) lies on a map over a and b."""
    flat = np.ravel_multi_index(idx, ds[V.status].shape)
    return float(per_cell(ds, a)[flat]), float(per_cell(ds, b)[flat])


def figure_plan(ds, variables=None, special=None, slice_at=None) -> dict[str, Callable]:
    """The figures that fit the archive's grid, each as the call that draws it (titled):
    maps for two axes, scans for one, the section, convergence histories and the
    frequency map where the data exist. special: the special solutions its cells start
    on, marked on the regime map and the scans; slice_at: the section coordinates a grid
    over the others fixes, for its overlay of crossings -- both, unless given, as the
    archive stores them (stored_special). A refined survey over one axis is drawn as the
    uneven grid it is (analysis.refine.as_grid)."""
    stored, fixed = stored_special(ds)
    special = stored if special is None else special
    slice_at = fixed if slice_at is None else slice_at
    ds = as_grid(ds)
    axes = grid_axes(ds)
    out = {}
    names = [m for m in MAPS if m[0] in ds and (variables is None or m[0] in variables)]
    if "seed" in axes and len(axes) > 1:    # seeded starts per point: their regular share
        if V.regime in ds and len(axes) in (2, 3):
            out["regular_share"] = partial(regular_share_figure, ds)
    elif len(map_axes(ds)) == 2:
        if V.regime in ds and (variables is None or V.regime in variables):
            out["map_regime"] = partial(regime_map, ds, special)
        for name, style in names:       # a map with no value would be all mask
            if np.isfinite(ds[name].values).any():
                out[f"map_{name}"] = partial(indicator_map, ds, name, style.cmap,
                                             style.clip, style.log)
        if _height_axis(ds) is not None:
            out["map_regime_height"] = partial(regime_height_map, ds)
        if V.escape_time in ds and np.any(ds[V.status].values == Status.ESCAPED):
            out["map_escape"] = partial(escape_map, ds)
        if all(f"crossing_{a}" in ds for a in map_axes(ds)) and V.megno in ds \
                and np.isfinite(ds[V.megno].values).any():
            style = OWNER[V.megno].map
            out["map_megno_section"] = partial(indicator_map, ds, V.megno, style.cmap,
                                               style.clip, style.log, overlay=True,
                                               slice_at=slice_at or {})
    elif len(axes) == 1 and axes[0] != "seed":      # seeds are in no order: no scan
        out["scan"] = partial(scan, ds, [n for n, _ in names] if variables is None
                              else variables, special)
    if section_axes(ds) and int(np.nansum(ds[V.n_crossings].values)) > 0 \
            and len(shells(ds)) <= MAX_SHELLS:
        out["section"] = partial(section, ds)
        if len(shells(ds)) == 1 and crossing_surface(ds)[0] == "phi":   # the 4-D section, sliced
            out["section_slice"] = partial(section_slice, ds)
    if V.megno_history in ds and np.isfinite(ds[V.megno_history].values).any():
        out["convergence"] = partial(convergence, ds)
    if V.closest_approach in ds and V.ftle in ds and np.any(ds[V.ftle].values > 0):
        out["approach"] = partial(approach_figure, ds)
    if V.frequency in ds and V.regime in ds and sum(
            str(n).startswith("shape") for n in ds["fundamental_name"].values) >= 3:
        # frequencies mean something on regular cells; the map needs three of them
        regular = np.isin(ds[V.regime].values, REGULAR)
        if np.isfinite(ds[V.frequency].values[regular]).any():
            out["frequency_map"] = partial(frequency_map, ds)
    title = survey_title(ds)
    return {name: partial(_titled, draw, title) for name, draw in out.items()}


def _titled(draw, title) -> Figure:
    fig = draw()
    # wrapped to the figure's width (about 15 characters of small text an inch): a title
    # wider than its figure is cut off at both ends
    fig.suptitle(textwrap.fill(title, int(15 * fig.get_figwidth())), fontsize="small",
                 color="0.25")
    return fig


def figures(ds, variables=None, special=None, slice_at=None) -> dict[str, Figure]:
    """The figures of figure_plan, drawn."""
    return {name: draw() for name, draw in
            figure_plan(ds, variables, special, slice_at).items()}


def term_label(term: dict) -> str:
    """An interactions entry as a figure or report names it: the built-in term's name,
    or a formula's U = ..."""
    return term.get("potential") or f"U = {term['expression']}"


def survey_title(ds) -> str:
    """What every survey figure is of: the survey, its family and potential, T, and what
    varies over the grid (of a Dataset without a stored config: its title and grid)."""
    axes = map_axes(ds)
    varies = (f"; {', '.join(axes)} varied over {ds[V.status].size} cells" if axes
              else "; one cell")
    if "level" in ds.coords:
        varies += f" (refined to level {int(ds['level'].max())})"
    config = stored_config(ds)
    if not config:
        return f"{ds.attrs.get('title', 'survey')}{varies}"
    system = config["system"]
    if "interactions" in system:
        potential = " + ".join(term_label(t) + (" (m_i m_j)" if t.get(
            "mass_weighted") else "") for t in system["interactions"])
    else:
        potential = system["potential"]
    T = float(config["integration"]["t_final"])
    longest = float(np.nanmax(ds[V.regime_horizon].values)) if V.regime_horizon in ds and \
        np.isfinite(ds[V.regime_horizon].values).any() else T
    extended = f" (verdicts in doubt to {longest:g})" if longest > T else ""
    return (f"{config['survey']['name']}: {config['initial']['family']} family under "
            f"{potential}, T = {T:g}{extended}{varies}")


# seconds at least that `draw` waits for its second process once its own share is drawn
PATIENCE = 60.0


def draw(ds, folder, stem: str, variables=None, special=None, slice_at=None) -> list[Path]:
    """The figures of figure_plan written as STEM_NAME.png into `folder`, every other one
    drawn in a second process forked for them: matplotlib's layout and rendering are most
    of a report's time, on one core (the default survey's five figures: 2.2 s). The
    archive is read into memory first (two processes never read one file). A second
    process that fails, or takes far longer than this one's share, leaves its figures to
    this one."""
    import multiprocessing
    import time
    ds.load()
    plan = figure_plan(ds, variables, special, slice_at)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {name: folder / f"{stem}_{name}.png" for name in plan}
    names = list(plan)
    # (a daemonic process, such as a worker's, may not have children)
    theirs = names[1::2] if "fork" in multiprocessing.get_all_start_methods() and \
        not multiprocessing.current_process().daemon else []
    beside = None
    if theirs:
        beside = multiprocessing.get_context("fork").Process(
            target=_save, args=(plan, theirs, paths), name="figures", daemon=True)
        beside.start()
    began = time.perf_counter()
    _save(plan, [n for n in names if n not in theirs], paths)
    if beside is not None:
        beside.join(max(PATIENCE, 4 * (time.perf_counter() - began)))
        if beside.exitcode != 0:        # failed, or still running
            beside.kill()
            beside.join()
            _save(plan, theirs, paths)
    return [paths[name] for name in names]


def _save(plan, names, paths):
    for name in names:
        plan[name]().savefig(paths[name], dpi=130)


def save(figs: dict[str, Figure], folder, stem: str) -> list[Path]:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figs.items():
        path = folder / f"{stem}_{name}.png"
        fig.savefig(path, dpi=130)
        paths.append(path)
    return paths


def _unfinished(ds) -> np.ndarray:
    return ~np.isin(ds[V.status].values, [Status.OK, Status.EVENT])


def _mask_layer(ax, ds, x, y, grid=np.asarray, skip=()):
    """Cells whose run did not finish, in their status colours (but the statuses `skip`);
    legend handles with counts."""
    status = ds[V.status].values
    handles = []
    for s, colour in STATUS_COLOURS.items():
        where = (status == s) & (s not in skip)
        if where.any():
            on = grid(where)
            rgba = np.zeros(on.shape + (4,))
            rgba[on] = _rgba(colour)
            ax.pcolormesh(x, y, np.moveaxis(rgba, 0, 1) if rgba.ndim == 3 else rgba,
                          shading="nearest")
            handles.append(Patch(color=colour, label=f"{s.name.lower()} ({int(where.sum())})"))
    return handles


def confidence_shade(ds) -> np.ndarray:
    """How much of a regime's colour a cell gets: 0.35 + 0.65 x its confidence (the share
    of the lines of evidence for it), full where the regime is undetermined (its
    confidence is 0 by definition) or a status (collision, inaccessible), or where no
    confidence is stored."""
    if V.regime_confidence not in ds:
        return np.ones(ds[V.status].shape)
    c = np.nan_to_num(ds[V.regime_confidence].values.astype(float), nan=1.0)
    decided = np.isin(ds[V.regime].values, REGULAR + IRREGULAR)
    return np.where(decided, 0.35 + 0.65 * np.clip(c, 0.0, 1.0), 1.0)


def unconfirmed(ds) -> np.ndarray:
    """Cells whose regular or irregular verdict is not that of the horizon before (regime
    history): claimed to their horizon only."""
    if V.regime_stable not in ds:
        return np.zeros(ds[V.status].shape, dtype=bool)
    decided = np.isin(ds[V.regime].values, REGULAR + IRREGULAR)
    return decided & (ds[V.regime_stable].values == 0)


UNCONFIRMED = dict(hatch="////", facecolor="none", edgecolor="0.15", lw=0)


def _hatch_cells(ax, x, y, mask):
    """Hatch the cells of a map where mask holds (cell edges halfway between centres)."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    ex, ey = _edges(x), _edges(y)
    boxes = [Rectangle((ex[i], ey[j]), ex[i + 1] - ex[i], ey[j + 1] - ey[j])
             for i, j in zip(*np.nonzero(mask))]
    if boxes:
        ax.add_collection(PatchCollection(boxes, match_original=False, **UNCONFIRMED))


def _rgba(colour):
    from matplotlib.colors import to_rgba
    return to_rgba(colour)


def _two_axis_figure(ds):
    fig = Figure(figsize=(9.0, 5.0), layout="constrained")
    gs = fig.add_gridspec(1, 2, width_ratios=[4, 1.1])
    ax, hist = fig.add_subplot(gs[0]), fig.add_subplot(gs[1])
    a, b = map_axes(ds)
    ax.set_xlabel(label(a))
    ax.set_ylabel(label(b))
    if refined_axes(ds):
        ax.set_title(f"{ds.sizes['cell']} cells, refined to level {int(ds['level'].max())}: "
                     "each drawn over the square of its level's spacing", fontsize="small")
    return (fig, ax, hist, *_on_grid(ds))


def stored_special(ds) -> tuple[list[dict], dict]:
    """The special solutions an archive's cells start on and the section slice its grid
    fixes, as the survey stored them (pipeline.special.report_attributes; none in an
    archive written before they were stored)."""
    special = json.loads(ds.attrs.get("special_cells", "[]"))
    for s in special:
        s["index"] = tuple(s["index"])
    return special, json.loads(ds.attrs.get("section_slice", "{}"))


def _special_marks(special) -> list[tuple[tuple, str, str]]:
    """(cell index, marker, legend label) per special solution: a star for a relative
    equilibrium, a circle for a homographic periodic orbit, with its stability."""
    out = []
    for s in special:
        if s["kind"] == "equilibrium":
            what = "relative equilibrium, " + ("linearly stable" if s["stable"] else "unstable")
            out.append((s["index"], "*", what))
        else:
            out.append((s["index"], "o", f"homographic periodic orbit, {s['orbit_kind']}"))
    return out


def _mark_handles(marks) -> list:
    labels = list(dict.fromkeys((m, text) for _, m, text in marks))
    return [Line2D([], [], marker=m, ls="none", mfc="none", mec="k", mew=1.3, ms=9,
                   label=f"{text} ({sum(1 for _, mm, t in marks if (mm, t) == (m, text))})")
            for m, text in labels]


def dissociation_lines(ds, ax, axes, at=None) -> list:
    """A dashed line where a map's or scan's energy axis (one of `axes`) crosses the
    dissociation energy (pipeline.special.dissociation_energy: below it no body can
    leave); at: (values, positions) where an uneven scan draws a cell a step. Its legend
    handle, or none."""
    e = json.loads(ds.attrs.get("dissociation_energy", "null"))
    if e is None or "energy" not in axes:
        return []
    values = at[0] if at is not None else ds["energy"].values
    if not values.min() <= e <= values.max():
        return []
    where = float(np.interp(e, *at)) if at is not None else e
    line = dict(color="k", ls="--", lw=1.2)
    (ax.axvline if list(axes).index("energy") == 0 else ax.axhline)(where, **line)
    return [Line2D([], [], **line, label=f"dissociation energy {e:.6g}: below it no body "
                                         "can leave")]


def regime_map(ds, special=()) -> Figure:
    fig, ax, hist, x, y, grid = _two_axis_figure(ds)
    regime = ds[V.regime].values
    colours = [REGIME_COLOURS[r] for r in Regime]
    cmap = ListedColormap(colours)
    norm = BoundaryNorm(np.arange(len(Regime) + 1) - 0.5, len(Regime))
    # paler where fewer lines of evidence support the regime: a cell 1 of 5 lines called
    # chaotic is not drawn like one all 5 did
    rgba = cmap(norm(grid(regime)))
    rgba[..., :3] = 1.0 - grid(confidence_shade(ds))[..., None] * (1.0 - rgba[..., :3])
    ax.pcolormesh(x, y, np.moveaxis(rgba, 0, 1) if rgba.ndim == 3 else rgba,
                  shading="nearest")
    doubt = unconfirmed(ds)
    _hatch_cells(ax, x, y, grid(doubt))
    counts = [(r, int(np.sum(regime == r))) for r in Regime]
    handles = [Patch(color=REGIME_COLOURS[r], label=f"{r.name.lower()} ({n})")
               for r, n in counts if n]
    handles += _scale_free_lines(ds, ax, x, y, grid)
    handles += dissociation_lines(ds, ax, map_axes(ds))
    marks = _special_marks(special)
    for idx, marker, _ in marks:     # black on a white halo: seen on any colour
        at = _cell_xy(ds, idx, *map_axes(ds))
        ax.plot(*at, marker, ms=9, mfc="none", mec="w", mew=3.0)
        ax.plot(*at, marker, ms=9, mfc="none", mec="k", mew=1.3)
    handles += _mark_handles(marks)
    if doubt.any():
        handles.append(Patch(**UNCONFIRMED, label=f"not confirmed at the horizon before "
                                                  f"({int(doubt.sum())})"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1), fontsize="small",
              title="regime (cells);\npaler: fewer lines of\nevidence vote for it")
    hist.barh([r.name.lower() for r, n in counts if n], [n for r, n in counts if n],
              color=[REGIME_COLOURS[r] for r, n in counts if n])
    hist.set_xlabel("cells")
    hist.yaxis.tick_right()
    if not refined_axes(ds):
        ax.set_title("regime of each cell", fontsize="medium")
    return fig


def _height_axis(ds):
    """For a map over the energy and a parameter whose starts' potential energy U_0 is one
    number per parameter value (starts at that system's equilibrium) and moves with it:
    (the parameter, U_0 per value of it); else None. The energy's meaning then changes
    across the map, and the height above U_0 is the axis that compares like with like."""
    if V.start_potential not in ds or refined_axes(ds) or "energy" not in grid_axes(ds) \
            or len(grid_axes(ds)) != 2:
        return None
    other = next(a for a in grid_axes(ds) if a != "energy")
    u = ds[V.start_potential].transpose(other, "energy").values
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)      # all-NaN rows: inaccessible
        low, high = np.nanmin(u, axis=1), np.nanmax(u, axis=1)
    scale = np.nanmax(np.abs(u)) if np.isfinite(u).any() else 0.0
    known = np.isfinite(low)
    if known.sum() < 2 or np.any(high[known] - low[known] > 1e-9 * max(scale, 1.0)) or \
            np.ptp(low[known]) <= 1e-9 * max(scale, 1.0):
        return None
    return other, low


def regime_height_map(ds) -> Figure:
    """The regime map over the parameter and the height of E above the starts' potential
    energy U_0 (_height_axis): each column shifted down by its own U_0, so that a band
    just above each system's minimum lines up across the parameter."""
    other, u0 = _height_axis(ds)
    fig = Figure(figsize=(9.0, 5.0), layout="constrained")
    ax = fig.add_subplot()
    x, energy = ds[other].values, ds["energy"].values
    regime = ds[V.regime].transpose(other, "energy").values
    shade = confidence_shade(ds.transpose(other, "energy", ...))
    cmap = ListedColormap([REGIME_COLOURS[r] for r in Regime])
    norm = BoundaryNorm(np.arange(len(Regime) + 1) - 0.5, len(Regime))
    half = 0.5 * np.diff(x).min() if x.size > 1 else 0.5
    for i in np.flatnonzero(np.isfinite(u0)):
        rgba = cmap(norm(regime[i]))
        rgba[:, :3] = 1.0 - shade[i][:, None] * (1.0 - rgba[:, :3])
        up = energy - u0[i] >= 0               # below U_0 no start exists
        ax.pcolormesh([x[i] - half, x[i] + half], _edges(energy[up] - u0[i]),
                      rgba[up][:, None, :], shading="flat")
    counts = [(r, int(np.sum(regime == r))) for r in Regime if r != Regime.INACCESSIBLE]
    handles = [Patch(color=REGIME_COLOURS[r], label=f"{r.name.lower()} ({n})")
               for r, n in counts if n]
    below = int(np.sum(regime == Regime.INACCESSIBLE))
    if below:
        handles.append(Patch(color="none", label=f"{below} inaccessible cells\n(E < U_0), "
                                                 "not drawn"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1),
              fontsize="small", title="regime (cells)")
    ax.set_xlabel(label(other))
    ax.set_ylabel("E - U_0: height of the energy above the starts' potential energy\n"
                  "(E - E_min for starts at the equilibrium)")
    ax.set_title("regime against the height above each system's start: the same map with "
                 "each column lowered by its own U_0", fontsize="small")
    return fig


def _edges(c) -> np.ndarray:
    """Cell edges halfway between centres (and as far beyond the ends)."""
    c = np.asarray(c, dtype=float)
    if c.size == 1:
        return np.array([c[0] - 0.5, c[0] + 0.5])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])


def regular_share_figure(ds) -> Figure:
    """Several seeded starts per grid point: the share of each point's decided starts that
    are regular -- a map over two axes (points with none decided masked, each labelled
    k/n), or along one axis with its 95% Wilson interval as a bar (and a [reference]
    table's published shares beside it)."""
    share = regular_share(ds)
    points = [a for a in grid_axes(ds) if a != "seed"]
    starts = ds.sizes["seed"]
    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    ax = fig.add_subplot()
    if len(points) == 2:
        a, b = points
        values = share.share.transpose(a, b).values
        mesh = ax.pcolormesh(ds[a].values, ds[b].values, values.T, cmap="RdYlBu", vmin=0,
                             vmax=1, shading="nearest")
        blank = ~np.isfinite(values)
        if blank.any():
            _hatch_cells(ax, ds[a].values, ds[b].values, blank)
        fig.colorbar(mesh, ax=ax, label=f"regular share of the decided starts (of {starts} "
                                         f"per point)")
        ax.set_xlabel(label(a))
        ax.set_ylabel(label(b))
        if blank.any():
            ax.legend(handles=[Patch(**UNCONFIRMED, label=f"no start decided: none "
                                                          f"accessible, or all undetermined "
                                                          f"({int(blank.sum())})")],
                      loc="upper right", fontsize="small", framealpha=0.9)
    else:
        (a,) = points
        x = ds[a].values
        y = share.share.values
        ax.errorbar(x, y, yerr=np.maximum(0.0, [y - share.share_low.values,
                                                share.share_high.values - y]),
                    fmt="o", ms=4, color="#1f77b4", ecolor="0.4", capsize=2,
                    label=f"regular share of the decided starts ({starts} per point), "
                          "95% Wilson interval")
        reference = stored_table(ds, "reference")
        if reference:
            spread = reference["spread"]
            ax.errorbar(reference["at"], reference["regular_share"],
                        yerr=spread if spread else None, fmt="s", ms=5, mfc="none",
                        color="#d62728", capsize=3,
                        label="published: " + reference["source"].split(":")[0].strip())
            if reference.get("crossings"):
                own = separation_share(ds, reference["crossings"], reference["growth"])
                shift = 0.01 * float(np.ptp(x) or 1.0)
                v = own.share.values
                ax.errorbar(x + shift, v, yerr=np.maximum(0.0, [v - own.share_low.values,
                                                               own.share_high.values - v]),
                            fmt="D", ms=4, color="#2ca02c", ecolor="#2ca02c", capsize=2,
                            label=f"their criterion on survey's orbits (growth < "
                                  f"{reference['growth']:g} by crossing "
                                  f"{reference['crossings']}), 95% interval")
        ax.set_ylim(-0.03, 1.03)
        ax.set_xlabel(label(a))
        ax.set_ylabel("regular share")
        ax.legend(fontsize="small", loc="best")
    blank = int(np.sum(share.decided.values == 0))
    ax.set_title(f"{starts} seeded starts per point: the regular share" + (
        f" ({blank} point{'s' * (blank > 1)} with none decided: not drawn)" if blank else ""),
        fontsize="medium")
    return fig


def _scale_free_lines(ds, ax, x, y, grid=np.asarray) -> list:
    """On a map over energy of a homogeneous potential: dashed lines of equal
    scale_free_energy, along which the cells' energy shells are one phase portrait rescaled
    (their starts are different points of it); their legend entry."""
    if V.scale_free_energy not in ds or "energy" not in map_axes(ds):
        return []
    eps = ds[V.scale_free_energy].values
    if np.sum(np.isfinite(eps)) < 4 or np.nanmin(eps) == np.nanmax(eps):
        return []
    # levels at quantiles of the cells' values: lines where the cells are, not where the
    # range is widest
    levels = np.unique([float(f"{v:.2g}") for v in
                        np.nanquantile(eps, np.linspace(0.08, 0.92, 7))])
    lines = ax.contour(x, y, grid(eps).T, levels=levels, colors="0.25", linewidths=0.7,
                       linestyles="dashed")
    ax.clabel(lines, fmt="%.3g", fontsize="x-small")
    return [Line2D([], [], color="0.25", lw=0.7, ls="--",
                   label="equal E |J|^(-2k/(k+2)):\nshells with one phase\nportrait, rescaled")]


def indicator_map(ds, name, cmap="viridis", clip=None, log=False, overlay=False,
                  slice_at=None) -> Figure:
    """An indicator over the two grid axes with its histogram; `overlay`: when the axes are
    section coordinates, the section crossings in the slab of the slice the grid is (the
    other coordinates at slice_at) drawn on top."""
    fig, ax, hist, x, y, grid = _two_axis_figure(ds)
    values = ds[name].values.astype(float)
    shown = np.where(_unfinished(ds), np.nan, values)
    finite = shown[np.isfinite(shown)]
    if log:
        finite = finite[finite > 0]
    lo, hi = clip if clip else (np.nanmin(finite) if finite.size else 0.0,
                                np.nanmax(finite) if finite.size else 1.0)
    from matplotlib.colors import LogNorm, Normalize
    norm = LogNorm(max(lo, 1e-6), max(hi, 2e-6)) if log else Normalize(lo, hi)
    mesh = ax.pcolormesh(x, y, grid(np.clip(shown, lo if not log else -np.inf, hi)).T,
                         cmap=cmap, norm=norm, shading="nearest")
    handles = _mask_layer(ax, ds, x, y, grid)
    if overlay:
        a, b = map_axes(ds)
        keep, slab = slice_slab(ds, slice_at or {})
        ax.scatter(ds[f"crossing_{a}"].values.ravel()[keep],
                   ds[f"crossing_{b}"].values.ravel()[keep],
                   s=2.0 if keep.sum() < 20000 else 0.3, lw=0, color="black", alpha=0.6,
                   rasterized=True)
        whole = not slice_at        # two degrees of freedom: the grid is the section itself
        handles.append(Patch(color="black", alpha=0.6, label="section crossings" + (
            "" if whole else " in the slice's slab")))
        ax.set_xlabel(ax.get_xlabel() + "\n" + textwrap.fill(
            f"the grid is the 2-D section itself; drawn: every crossing ({int(keep.sum())})"
            if whole else f"the grid is a 2-D slice of the 4-D section; drawn: the crossings "
                          f"in its slab {slab}", 75), fontsize="small")
        ax.set_xlim(x.min(), x.max())
        ax.set_ylim(y.min(), y.max())
    where = f"clipped to [{lo:g}, {hi:g}]" if clip else f"range [{lo:.3g}, {hi:.3g}]"
    cb = fig.colorbar(mesh, ax=ax, location="right", pad=0.02)
    cb.set_label(f"{label(name)}, {where}" + (", log scale" if log else ""))
    if handles:
        ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3,
                  fontsize="small", title="masked cells", frameon=False)
    values = shown.ravel()
    values = values[np.isfinite(values)]
    if log:
        values = values[values > 0]
    hist.hist(np.clip(values, norm.vmin, norm.vmax),
              bins=np.geomspace(norm.vmin, norm.vmax, 31) if log
              else np.linspace(norm.vmin, norm.vmax, 31),
              orientation="horizontal", color="0.3")
    hist.set_yscale("log" if log else "linear")
    hist.set_ylim(norm.vmin, norm.vmax)
    hist.set_xlabel("cells")
    hist.set_ylabel(label(name) + (" (clipped)" if clip else ""))
    hist.yaxis.set_label_position("right")
    hist.yaxis.tick_right()
    return fig


def scan(ds, names, special=()) -> Figure:
    """Indicators along a one-axis grid, each cell's orbit with the 5-95% range of its
    ensemble (the orbit and its perturbed starts) as a bar, and the regime shaded behind
    (the paper's LyapunovSides and LyapunovScanEquil); the special solutions' cells
    marked."""
    a = grid_axes(ds)[0]
    values = ds[a].values
    steps = np.diff(values)
    # a grid that crowds somewhere (steps differing by more than 10x) is drawn cell by
    # cell, its values as tick labels, so that no stretch of it packs into a few pixels
    uneven = values.size > 2 and bool(np.all(steps > 0)) and steps.max() > 10 * steps.min()
    x = np.arange(values.size, dtype=float) if uneven else values
    names = [n for n in names if n in ds]
    fig = Figure(figsize=(8.0, 2.3 * max(len(names), 1) + 0.6), layout="constrained")
    axes = fig.subplots(max(len(names), 1), 1, sharex=True, squeeze=False)[:, 0]
    edges = np.concatenate([[x[0] - (x[1] - x[0]) / 2 if x.size > 1 else x[0] - 0.5],
                            (x[1:] + x[:-1]) / 2,
                            [x[-1] + (x[-1] - x[-2]) / 2 if x.size > 1 else x[0] + 0.5]])
    regime = ds[V.regime].values if V.regime in ds else None
    doubt = unconfirmed(ds)
    for ax, name in zip(axes, names):
        if regime is not None:
            shade = confidence_shade(ds)
            for r in Regime:
                for i in np.flatnonzero(regime == r):
                    ax.axvspan(edges[i], edges[i + 1], color=REGIME_COLOURS[r],
                               alpha=0.22 * shade[i], lw=0)
            for i in np.flatnonzero(doubt):
                ax.axvspan(edges[i], edges[i + 1], **UNCONFIRMED, alpha=0.35)
        y = np.where(_unfinished(ds), np.nan, ds[name].values.astype(float))
        common = _at_common_horizon(ds, name)
        longer = np.zeros(y.shape, dtype=bool)
        if common is not None:      # like with like: every cell at T, the longer runs apart
            at_T, T, longer = common
            final = np.where(longer, y, np.nan)
            y = np.where(longer, at_T, y)
        ax.plot(x, y, "o-", ms=2.5, lw=0.8, color="k", label=None if common is None else
                f"every cell at T = {T:g}" if np.isfinite(y[longer]).all() else
                f"the cells run to T = {T:g}")
        for (i,), marker, _ in _special_marks(special):
            ax.plot(x[i], y[i], marker, ms=10, mfc="none", mec="k", mew=1.3, zorder=4)
        band = _ensemble_range(ds, name)
        if band is not None:
            low, high, note = band
            ax.vlines(x[~longer], low[~longer], high[~longer], color="0.4", lw=0.7,
                      label=note)
            if longer.any():
                ax.vlines(x[longer], low[longer], high[longer], color="tab:orange", lw=0.7)
        if longer.any():
            factors = np.unique(np.round(horizon(ds)[longer] / T, 6))
            ax.plot(x[longer], final[longer], "^", ms=4, color="tab:orange", zorder=3,
                    label=f"cells run longer, at {', '.join(f'{f:g}' for f in factors)} T "
                          f"({int(longer.sum())})")
        dissociation = dissociation_lines(ds, ax, [a], (values, x) if uneven else None)
        for level, style, text in _reference_lines(ds, name, common is not None):
            if np.ndim(level):        # per cell: each at its own horizon
                ax.plot(x, level, color="0.3", ls=style, lw=0.8, label=text,
                        drawstyle="steps-mid")
            else:
                ax.axhline(level, color="0.3", ls=style, lw=0.8, label=text)
        if name in (V.ftle, V.megno) and _positive(y):
            ax.set_yscale("log")
            _below_log_axis(ax, x, y, *([final] if longer.any() else []))
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.0, 1.0),
                      frameon=False)
        if not np.isfinite(y).any():
            ax.text(0.5, 0.5, "no value: no cell finished", transform=ax.transAxes,
                    ha="center", va="center", color="0.3")
        ax.set_ylabel(label(name))
    axes[-1].set_xlabel(label(a) + (" (one cell per step: the grid is unevenly spaced)"
                                    if uneven else ""))
    if uneven:
        every = max(1, values.size // 8)
        axes[-1].set_xticks(x[::every], [f"{v:g}" for v in values[::every]], rotation=35,
                            ha="right", rotation_mode="anchor")
    if regime is not None:
        present = [r for r in Regime if np.any(regime == r)]
        # the figure's legend, below the panels: the layout makes room for it and for
        # each panel's legend of lines beside it
        handles = [Patch(color=REGIME_COLOURS[r], alpha=0.4,
                         label=f"{r.name.lower()} ({int(np.sum(regime == r))})")
                   for r in present]
        if doubt.any():
            handles.append(Patch(**UNCONFIRMED, label=f"not confirmed ({int(doubt.sum())})"))
        handles += _mark_handles(_special_marks(special))
        handles += dissociation
        fig.legend(handles=handles, loc="outside lower center", fontsize="small",
                   ncol=min(len(handles), 4), frameon=False,
                   title="regime (cells); paler where fewer lines of evidence vote for it")
    return fig


def _ensemble_range(ds, name):
    """(5% quantiles, 95% quantiles, legend text) of an indicator's ensembles, or None."""
    if f"{name}_ensemble" not in ds or V.ensemble_orbits not in ds:
        return None
    stats = list(ds["ensemble_statistic_name"].values.astype(str))
    q = ds[f"{name}_ensemble"].values
    low, high = q[..., stats.index("q05")], q[..., stats.index("q95")]
    if not np.isfinite(high - low).any() or not np.any(high > low):
        return None
    orbits = ds[V.ensemble_orbits].values
    n = int(np.max(orbits)) if (orbits > 0).any() else 0
    note = f"5-95% of {n} orbits" + (" (indicative)" if n < ENSEMBLE_MIN else "")
    return low, high, note


def _at_common_horizon(ds, name):
    """(the value at the archive's first horizon T of the cells run longer -- from their
    history, which the longer run carries from the same start; NaN where the indicator
    keeps none --, T, the cells run longer), or None where no cell ran longer."""
    if V.regime_horizon not in ds:
        return None
    reached = horizon(ds)
    if not np.isfinite(reached).any():
        return None
    T = float(np.nanmin(reached))
    longer = np.isfinite(reached) & (reached > T * (1 + 1e-9))
    if not longer.any():
        return None
    history = f"{name}_history"
    if history not in ds:
        return np.full(longer.shape, np.nan), T, longer
    times = ds["history_time"].values
    k = int(np.argmin(np.abs(times - T)))
    return ds[history].values[..., k].astype(float), T, longer


def _reference_lines(ds, name, common: bool = False):
    """Where the indicator's votes change (dashed: regular side, dotted: chaotic side):
    (level, line style, legend text). A level in units of ln(T)/T is per cell, at the time
    each reached, where those differ (cells decided at a longer horizon) -- unless every
    cell is drawn at the first horizon (`common`), where it is one."""
    th = Thresholds.from_table(stored_table(ds))
    for indicator in REGISTRY:
        vote = indicator.vote
        if vote is None or vote.variable != name:
            continue
        levels = [getattr(th, f"{vote.thresholds}_{side}") for side in ("regular", "chaotic")]
        unit = ""
        if vote.per_torus_rate:
            if V.t_end not in ds:
                return []
            t = ds[V.t_end].values.astype(float)
            if common:
                t = np.where(np.isfinite(t), np.nanmin(horizon(ds)), np.nan)
            T = float(np.nanmax(t)) if np.isfinite(t).any() else np.nan
            if not T > 0:
                return []
            if np.nanmin(t) < T:
                unit = [f" ({level:g} ln T / T, T each cell's)" for level in levels]
                with np.errstate(invalid="ignore", divide="ignore"):
                    rate = np.where(t > 1, np.log(t) / t, np.nan)
                return [(level * rate, style, f"{side} vote{unit[k]}") for k, (level, style,
                        side) in enumerate(zip(levels, ("--", ":"), ("regular", "chaotic")))]
            unit = [f" ({level:g} ln T / T)" for level in levels]
            levels = [level * np.log(T) / T for level in levels]
        return [(level, style, f"{side} vote {level:.3g}{unit[k] if unit else ''}")
                for k, (level, style, side) in enumerate(zip(levels, ("--", ":"),
                                                              ("regular", "chaotic")))]
    return []


def _below_log_axis(ax, x, *ys):
    """Values a log axis cannot show (<= 0, e.g. a FTLE that shrank) marked at its bottom
    edge, counted in the legend, instead of silently falling off (ys: the values drawn
    at x, the line's and the longer runs')."""
    with np.errstate(invalid="ignore"):
        off = np.any([np.isfinite(y) & (y <= 0) for y in ys], axis=0)
    if off.any():
        ax.plot(x[off], np.full(off.sum(), 0.0), "v", color="tab:purple", ms=4,
                transform=ax.get_xaxis_transform(), clip_on=False,
                label=f"<= 0, off the log axis ({int(off.sum())})")


def _positive(values) -> bool:
    """Whether a log axis has anything to show."""
    values = np.asarray(values, dtype=float)
    return bool(np.any(np.isfinite(values) & (values > 0)))


def convergence(ds, cells=None) -> Figure:
    """Indicator histories of chosen cells (default: one of each regime present): has the
    indicator converged by the end of the run?"""
    flat = {name: ds[name].values.reshape(-1, ds.sizes["history_time"])
            for name in (V.ftle_history, V.megno_history, V.sali_history) if name in ds}
    t = ds["history_time"].values
    regime = ds[V.regime].values.ravel() if V.regime in ds else None
    if cells is None:
        cells = [int(np.flatnonzero(regime == r)[0]) for r in Regime
                 if regime is not None and np.any(regime == r)
                 and r not in (Regime.INACCESSIBLE, Regime.COLLISION)][:6]
    fig = Figure(figsize=(7.5, 2.4 * len(flat) + 0.5), layout="constrained")
    axes = fig.subplots(len(flat), 1, sharex=True, squeeze=False)[:, 0]
    coords = cell_labels(ds)
    for ax, (name, values) in zip(axes, flat.items()):
        for c in cells:
            colour = REGIME_COLOURS[Regime(regime[c])] if regime is not None else None
            ax.plot(t, values[c], color=colour, lw=1.2,
                    label=coords[c] + (f" ({Regime(regime[c]).name.lower()})"
                                       if regime is not None else ""))
        ax.set_ylabel(label(name.replace("_history", "")))
        if name == V.sali_history and _positive(values[cells]):
            ax.set_yscale("log")
        if name == V.ftle_history and _positive(values[cells]):
            # a FTLE history crosses zero early on: logarithmic above ln(T)/T, linear
            # below it, so no stretch of it falls off the axis
            ax.set_yscale("symlog", linthresh=float(np.log(t[-1]) / t[-1]))
        if name == V.ftle_history:
            ax.plot(t, np.log(t) / t, "k:", lw=1, label=r"$\ln t / t$ (torus)")
    # below the panels, not in the first: long cell labels would cover its curves
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncol=2,
               fontsize="x-small", frameon=False)
    axes[-1].set_xlabel("t")
    return fig


def cell_labels(ds) -> list[str]:
    """'delta=4.2, energy=90' for every cell, in flat C order."""
    axes = map_axes(ds)
    values = [per_cell(ds, a) for a in axes]
    return [", ".join(f"{a}={v[i]:.6g}" for a, v in zip(axes, values))
            for i in range(ds[V.status].size)]


def frequency_map(ds, order: int = 5) -> Figure:
    """The frequency map of the regular cells: the first two labelled shape frequencies
    divided by the third (frequency_labelled: one column follows one frequency across the
    grid; the rotation, not a frequency of the reduced flow, divides nothing), with the
    resonance lines m1 x + m2 y + m3 = 0 of order |m| <= `order` -- the Arnold web."""
    names = [str(n) for n in ds["fundamental_name"].values]
    source = V.frequency_labelled if V.frequency_labelled in ds else V.frequency
    f = np.abs(ds[source].values.reshape(-1, len(names)))
    regime = ds[V.regime].values.ravel() if V.regime in ds else np.zeros(len(f), int)
    ref = 2
    x, y = f[:, 0] / f[:, ref], f[:, 1] / f[:, ref]
    fig = Figure(figsize=(6.4, 5.6), layout="constrained")
    ax = fig.add_subplot()
    keep = np.isfinite(x) & np.isfinite(y)
    regular = keep & np.isin(regime, REGULAR)
    frame = regular if regular.any() else keep
    if frame.any():
        # framed on the bulk (1-99% of the cells), so that a stray cell does not squeeze
        # the families into a corner; those outside are counted in the legend
        lo = [np.percentile(v[frame], 1) for v in (x, y)]
        hi = [np.percentile(v[frame], 99) for v in (x, y)]
        pad = 0.08 * max(hi[0] - lo[0], hi[1] - lo[1], 1e-3)
        xl, yl = (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad)
        outside = frame & ((x < xl[0]) | (x > xl[1]) | (y < yl[0]) | (y > yl[1]))
        for m1, m2, m3 in itertools.product(range(-order, order + 1), repeat=3):
            n = abs(m1) + abs(m2) + abs(m3)
            if (m1, m2) == (0, 0) or n > order or np.gcd.reduce([m1, m2, m3]) != 1:
                continue
            if m2 != 0:
                ax.plot(xl, [-(m1 * xl[0] + m3) / m2, -(m1 * xl[1] + m3) / m2],
                        color="0.55", lw=2.0 / n, zorder=0)
            else:
                ax.axvline(-m3 / m1, color="0.55", lw=2.0 / n, zorder=0)
        other = keep & ~regular
        if other.any():
            ax.scatter(x[other], y[other], s=4, color="0.75", rasterized=True,
                       label=f"not regular ({int(other.sum())}; frequencies not defined)")
        for r in REGULAR:
            cells = regular & (regime == r)
            if cells.any():
                ax.scatter(x[cells], y[cells], s=12, color=REGIME_COLOURS[r],
                           label=f"{r.name.lower()} ({int(cells.sum())})", rasterized=True)
        if outside.any():
            ax.plot([], [], " ", label=f"outside the frame: {int(outside.sum())}")
        ax.set_xlim(xl)
        ax.set_ylim(yl)
        ax.legend(fontsize="small", title="regime (cells)")
    ax.set_xlabel(rf"$\nu_1/\nu_{{{names[ref]}}}$")
    ax.set_ylabel(rf"$\nu_2/\nu_{{{names[ref]}}}$")
    ax.set_title(f"frequency map; lines: resonances m1 x + m2 y + m3 = 0, |m| <= {order}",
                 fontsize="medium")
    return place_legends(fig)


def family_diagram(ds, title: str = "") -> Figure:
    """The bifurcation diagram of a periodic family (pipeline.families.periodic_dataset):
    period against the parameter in the members' order, stable stretches blue and unstable
    red, folds and multiplier crossings marked; below, Henon's stability indices
    b = (mu + 1/mu)/2, linearly stable where every |b| <= 1 (the grey band; a complex b, a
    quartet off the circle, is drawn by its real part, dotted)."""
    name = next(iter(ds.coords))
    p, period = ds[name].values, ds["period"].values
    stable = ds["stable"].values.astype(bool)
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    for i in range(p.size - 1):     # stable stretches on top, where branches overlap
        both = bool(stable[i] and stable[i + 1])
        top.plot(p[i:i + 2], period[i:i + 2], lw=2.6 if both else 1.4, zorder=3 if both else 2,
                 color=REGIME_COLOURS[Regime.TORUS if both else Regime.CHAOTIC])
    top.plot(p, period, ".", color="#7f7f7f", ms=2)
    marks = {"fold": ("s", "k"), "through +1": ("^", "#2ca02c"),
             "period doubling (through -1)": ("v", "#9467bd"),
             "Krein collision (complex quartet)": ("D", "#ff7f0e")}
    handles = [Line2D([], [], color=REGIME_COLOURS[Regime.TORUS], lw=1.8,
                      label="linearly stable"),
               Line2D([], [], color=REGIME_COLOURS[Regime.CHAOTIC], lw=1.8, label="unstable")]
    for kind in dict.fromkeys(ds["bifurcation_kind"].values):
        where = ds["bifurcation_kind"].values == kind
        marker, colour = marks.get(kind, ("o", "k"))
        top.plot(ds["bifurcation_parameter"].values[where],
                 ds["bifurcation_period"].values[where], marker, color=colour, ms=7,
                 mfc="none", mew=1.5)
        handles.append(Line2D([], [], marker=marker, color=colour, ls="none", mfc="none",
                              mew=1.5, label=f"{kind} ({where.sum()})"))
    top.set_ylabel("period T")
    top.ticklabel_format(axis="y", useOffset=False)
    spread = float(np.ptp(period))
    if spread <= 1e-9 * abs(period.mean()):     # an isochronous family: say so, flat
        top.set_ylim(period.mean() * (1 - 1e-3), period.mean() * (1 + 1e-3))
        top.text(0.5, 0.6, f"T = {period.mean():.12g}, constant to {spread:.0e}",
                 transform=top.transAxes, ha="center", fontsize=9)
    top.legend(handles=handles, fontsize=8, loc="best")
    top.set_title("\n".join(textwrap.wrap(title or ds.attrs.get("title", ""), 80)),
                  fontsize=9)
    b_re, b_im = ds["index_real"].values, ds["index_imag"].values
    bottom.axhspan(-1.0, 1.0, color="#d9d9d9", alpha=0.6, lw=0)
    for k in range(b_re.shape[1]):
        real = np.where(np.abs(b_im[:, k]) <= 1e-9, b_re[:, k], np.nan)
        quartet = np.where(np.abs(b_im[:, k]) > 1e-9, b_re[:, k], np.nan)
        bottom.plot(p, real, lw=1.2, label=("smallest" if k == 0 else "largest" if k ==
                                            b_re.shape[1] - 1 else f"{k + 1}th") + " b")
        bottom.plot(p, quartet, ":", lw=1.2, color="k")
    low, high = np.nanmin(b_re), np.nanmax(b_re)
    bottom.set_ylim(max(low, -5.0) - 0.2, min(high, 5.0) + 0.2)
    bottom.set_ylabel("stability index b")
    bottom.set_xlabel(name if name != "energy" else "energy E")
    bottom.legend(fontsize=8, loc="best")
    return fig


EXIT_COLOURS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02")


def escape_map(ds) -> Figure:
    """The escape basins of an open system over two axes: each cell coloured by the exit its
    body escaped through (or escaped at all, without exits), the cells that stayed to their
    horizon by their regime's class; and beside it the escape time, log scale."""
    fig = Figure(figsize=(11.0, 4.8), layout="constrained")
    basin, timed = fig.subplots(1, 2, sharey=True)
    x, y, grid = _on_grid(ds)
    status, regime = ds[V.status].values, ds[V.regime].values
    escaped = status == Status.ESCAPED
    exits = (stored_table(ds, "outcomes") or {}).get("exits") or []
    where = ds[V.escape_exit].values if V.escape_exit in ds else np.where(escaped, 0, -1)
    layers = [(f"exit {k} ({exits[k]:g}°)" if exits else "escaped", escaped & (where == k),
               EXIT_COLOURS[k % len(EXIT_COLOURS)]) for k in range(max(len(exits), 1))]
    layers += [("stayed: regular", np.isin(regime, REGULAR), "#c6dbef"),
               ("stayed: chaotic or sticky", np.isin(regime, IRREGULAR), "#fcbba1"),
               ("stayed: undetermined", (regime == Regime.UNDETERMINED)
                & np.isin(status, [Status.OK, Status.EVENT]), "#dadaeb")]
    rgba = np.zeros(status.shape + (4,))
    handles = []
    for name, on, colour in layers:
        if on.any():
            rgba[on] = _rgba(colour)
            handles.append(Patch(color=colour, label=f"{name} ({int(on.sum())})"))
    basin.pcolormesh(x, y, np.moveaxis(grid(rgba), 0, 1), shading="nearest")
    handles += _mask_layer(basin, ds, x, y, grid, skip=(Status.ESCAPED,))
    handles += dissociation_lines(ds, basin, map_axes(ds))
    dissociation_lines(ds, timed, map_axes(ds))
    basin.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2,
                 fontsize="small", frameon=False)
    t = np.where(escaped, ds[V.escape_time].values, np.nan)
    from matplotlib.colors import LogNorm
    finite = t[np.isfinite(t) & (t > 0)]
    norm = LogNorm(finite.min(), max(finite.max(), 1.01 * finite.min())) if finite.size \
        else LogNorm(1.0, 10.0)
    mesh = timed.pcolormesh(x, y, grid(t).T, cmap="magma", norm=norm, shading="nearest")
    fig.colorbar(mesh, ax=timed, label=f"{label(V.escape_time)}, log scale (blank: stayed "
                                       f"to its horizon, or no start)")
    for ax in (basin, timed):
        ax.set_xlabel(label(map_axes(ds)[0]))
    basin.set_ylabel(label(map_axes(ds)[1]))
    timed.set_title("escape time", fontsize="medium")
    return fig


def approach_figure(ds) -> Figure:
    """Each decided cell's FTLE against its closest approach (the least distance of any
    pair), and for three bodies against the share of the run their triangle was thin
    (|A|/P^2 small: the areal potential's channels), coloured by regime: whether large
    FTLEs come from close encounters or from channel excursions."""
    thin = V.thin_share in ds
    fig = Figure(figsize=(10.0 if thin else 6.0, 4.5), layout="constrained")
    axs = np.atleast_1d(fig.subplots(1, 2 if thin else 1, sharey=True))
    regime = ds[V.regime].values.ravel()
    ftle = ds[V.ftle].values.ravel()
    closest = ds[V.closest_approach].min("pair").broadcast_like(ds[V.status]).values.ravel()
    near = closest[np.isfinite(closest) & (closest > 0)]
    wide = near.size > 0 and near.max() > 10.0 * near.min()     # else a log axis has no ticks
    xs = [(closest, r"closest approach $\min_{ij} r_{ij}$" + (", log scale" if wide else ""),
           wide)]
    if thin:
        xs.append((ds[V.thin_share].broadcast_like(ds[V.status]).values.ravel(),
                   label(V.thin_share) + " (share of the run in a thin triangle)", False))
    shown = np.isfinite(ftle) & (ftle > 0)
    for ax, (value, name, log) in zip(axs, xs):
        for r in Regime:
            on = shown & (regime == r) & np.isfinite(value) & ((value > 0) | (not log))
            if on.any():
                ax.scatter(value[on], ftle[on], s=8, lw=0, color=REGIME_COLOURS[r],
                           label=f"{r.name.lower()} ({int(on.sum())})", rasterized=True)
        ax.set_xscale("log" if log else "linear")
        ax.set_yscale("log")
        ax.set_xlabel(name)
    axs[0].set_ylabel(label(V.ftle))
    axs[-1].legend(fontsize="small", loc="best", title="regime (cells)")
    hidden = int(regime.size - shown.sum())
    axs[0].set_title(textwrap.fill("FTLE against how close the bodies came" + (
        f" ({hidden} cell{'s' * (hidden != 1)} without a positive FTLE not drawn: escaped, "
        "inaccessible or failed)" if hidden else ""), 70), fontsize="small")
    return fig
