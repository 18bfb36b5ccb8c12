"""Poincare sections of a survey: each shell's crossings in its own panel (`section`), and
the 4-D section of three bodies in the plane sliced in 3-D (`section_slice`)."""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from ..analysis.classify import stored_table
from ..catalog.regimes import REGULAR, Regime
from ..catalog.variables import V, label
from .style import REGIME_COLOURS, grid_axes, map_axes, per_cell


MAX_SHELLS = 9      # a section figure draws up to this many shells, one panel each


def in_field(ds) -> bool:
    """Whether an archive's system has an external term (its stored [system] table)."""
    return any(t.get("kind") == "external"
               for t in (stored_table(ds, "system") or {}).get("interactions") or [])


def shells(ds) -> list[np.ndarray]:
    """The cells of an archive grouped by the Hamiltonian and energy shell they start on:
    equal E and J (to 1e-9; E alone in an external field) and equal values of every grid axis that is a parameter of the
    system (its terms' axes). Each group is a flat array of cell indices; cells without a
    start are left out. A Poincare section is of one shell."""
    axes = [a for a in map_axes(ds)        # a term's parameter: another Hamiltonian
            if str(ds[a].attrs.get("long_name", "")).startswith("parameter ")]
    flat = {a: per_cell(ds, a) for a in axes}
    groups: dict[tuple, list[int]] = {}
    energy, spin = per_cell(ds, V.energy), per_cell(ds, V.angular_momentum)
    if in_field(ds):        # a field conserves no angular momentum
        spin = np.zeros_like(energy)
    for i, (e, j) in enumerate(zip(energy, spin)):
        if np.isfinite(e):
            key = (float(f"{e:.9e}"), float(f"{j:.9e}")) + tuple(float(flat[a][i])
                                                                for a in axes)
            groups.setdefault(key, []).append(i)
    return [np.array(cells) for cells in groups.values()]


def section_axes(ds) -> tuple[str, str] | None:
    """The two coordinates a section figure draws its crossings in: (sigma, p_sigma) of the
    reduced flow of three bodies in the plane; in an external field, the centre of mass's
    coordinate after the surface's and its momentum ((y, p_y) on x = 0: Henon-Heiles'
    plane); None if the archive stores neither."""
    if V.crossing_sigma in ds:
        return "sigma", "p_sigma"
    coordinate = crossing_surface(ds)[0]
    other = {"x": "y", "y": "x", "z": "x"}.get(coordinate, "x")
    return (other, f"p_{other}") if f"crossing_{other}" in ds else None


def section(ds, colour_by=V.regime) -> Figure:
    """Section crossings in the archive's `section_axes`, one panel per energy shell (and
    Hamiltonian: see `shells`) -- a section never overlays different shells -- coloured by
    the cell's regime (or an indicator), rasterised; a panel of the reduced flow says it is
    a projection of the 4-D section of a 3-degree-of-freedom flow (a two-degree-of-freedom
    system's section is the plane itself)."""
    x, y = section_axes(ds)
    groups = shells(ds)[:MAX_SHELLS]
    cols = min(3, len(groups))
    rows = -(-len(groups) // cols)
    fig = Figure(figsize=(4.6 * cols + 0.6, 4.0 * rows + 0.8), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    xs = ds[f"crossing_{x}"].values.reshape(-1, ds.sizes["crossing"])
    ys = ds[f"crossing_{y}"].values.reshape(-1, ds.sizes["crossing"])
    energy, spin = per_cell(ds, V.energy), per_cell(ds, V.angular_momentum)
    regime = ds[V.regime].values.ravel() if V.regime in ds else None
    for ax, cells in zip(axes, groups):
        size = 1.0 if np.isfinite(xs[cells]).sum() > 5000 else 5.0    # few points: seen
        if colour_by == V.regime and regime is not None:
            for r in Regime:
                mine = cells[regime[cells] == r]
                if mine.size and np.isfinite(xs[mine]).any():
                    ax.scatter(xs[mine].ravel(), ys[mine].ravel(), s=size, lw=0,
                               color=REGIME_COLOURS[r], rasterized=True,
                               label=f"{r.name.lower()} ({mine.size})")
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize="x-small", markerscale=6 if size < 2 else 2)
        else:
            value = np.repeat(ds[colour_by].values.ravel()[cells], xs.shape[1])
            pts = ax.scatter(xs[cells].ravel(), ys[cells].ravel(), c=value, s=size, lw=0,
                             cmap="viridis", rasterized=True)
            fig.colorbar(pts, ax=ax, label=label(colour_by))
        ax.set_title(f"E = {energy[cells[0]]:.6g}"
                     + (f", J = {spin[cells[0]]:.6g}" if x == "sigma" else "") + " "
                     f"({cells.size} cell{'s' if cells.size > 1 else ''})", fontsize="small")
        ax.set_xlabel(label(x))
        ax.set_ylabel(label(y))
        _one_point(ax, xs[cells], ys[cells])
    for ax in axes[len(groups):]:
        ax.set_visible(False)
    surface = "surface of section {} = {:.6g}, one panel per energy shell: ".format(
        *crossing_surface(ds))
    fig.supxlabel(textwrap.fill(
        surface + (f"every crossing projected onto ({x}, {y}); the section of the reduced "
                   "3-degree-of-freedom flow is 4-D, so a torus need not draw a curve"
                   if x == "sigma" else f"every crossing in ({x}, {y}): a torus draws a "
                   "curve, a chaotic orbit fills an area"), int(13 * fig.get_figwidth())),
        fontsize="small")
    return place_legends(fig)


def place_legends(fig: Figure) -> Figure:
    """Fix each axes' legend at the place, of matplotlib's in its order of preference, that
    covers the fewest data (scatter points, marked line vertices, texts, bars), and of those
    the fewest vertices and crossings of unmarked lines. matplotlib's loc="best" counts them
    all alike -- a frequency map's resonance lines, the background, pushed its legend over
    cells -- and gathers a scatter's points into a Python list counted again for each place:
    2.2 s of a section figure's 2.9 s at 1.5e5 crossings, 0.5 s of a frequency map. The
    layout is run first, as saving will, so that the legend's size is its final one."""
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None or not ax.get_visible():
            continue
        marked = [ln for ln in ax.lines if ln.get_marker() not in (None, "None", "", " ")]
        points = [c.get_offset_transform().transform(np.asarray(c.get_offsets(), float))
                  for c in ax.collections
                  if len(c.get_offsets()) and not isinstance(c, PolyCollection)]
        points += [ln.get_transform().transform(ln.get_xydata()) for ln in marked
                   if len(ln.get_xydata())]
        points = np.concatenate(points) if points else np.zeros((0, 2))
        boxes = [a.get_bbox().transformed(a.get_data_transform()) for a in ax.patches
                 if isinstance(a, Rectangle)] + [t.get_window_extent() for t in ax.texts]
        paths = [a.get_transform().transform_path(a.get_path()) for a in
                 [ln for ln in ax.lines if ln not in marked] + list(ax.patches)
                 if not isinstance(a, Rectangle)]
        paths += [c.get_transform().transform_path(q) for c in ax.collections
                  if isinstance(c, PolyCollection) for q in c.get_paths()]
        best = None
        for code in range(1, len(legend.codes)):        # 0 is "best" itself
            legend.set_loc(code)
            box = legend.get_window_extent()
            badness = (box.count_contains(points) + (box.count_overlaps(boxes) if boxes else 0),
                       sum(box.count_contains(q.vertices) + q.intersects_bbox(box, filled=False)
                           for q in paths))
            if best is None or badness < best[0]:
                best = (badness, code)
            if badness == (0, 0):
                break
        legend.set_loc(best[1])
    return fig


def _one_point(ax, xs, ys):
    """A panel whose crossings all lie within roundoff of one point (an equilibrium's or a
    periodic orbit's) is drawn as that point in a window of unit size, and says so:
    autoscaled, the roundoff would look like a cloud."""
    spread = max(np.nanmax(v) - np.nanmin(v) for v in (xs, ys)) if np.isfinite(xs).any() \
        else np.inf
    scale = max(np.nanmax(np.abs(xs)), np.nanmax(np.abs(ys)), 1.0) if np.isfinite(spread) \
        else 1.0
    if spread <= 1e-9 * scale:
        cx, cy = np.nanmean(xs), np.nanmean(ys)
        ax.set_xlim(cx - 0.5, cx + 0.5)
        ax.set_ylim(cy - 0.5, cy + 0.5)
        ax.text(0.5, 0.08, f"every crossing within {spread:.1g} of one point",
                transform=ax.transAxes, ha="center", fontsize="x-small", color="0.3")


def crossing_surface(ds) -> tuple[str, float]:
    """The archive's surface of section (coordinate, value) as its config gives it."""
    section = stored_table(ds, "section") or {}
    coordinate = section.get("coordinate", "phi")
    return coordinate, section.get("value", np.pi / 2 if coordinate == "phi" else 0.0)


SLICE_VIEWS = ((22, -58), (12, 32), (88, -90))     # (elevation, azimuth) of the 3-D views


def section_slice(ds, fourth="p_eta", at=0.0) -> Figure:
    """A one-shell section of three bodies in the plane (4-D: sigma, p_sigma, eta, p_eta)
    drawn as researchers read one (Richter et al. 2014; Katsanikas and Patsis): the 3-D
    slice |fourth - at| <= SLAB (its range) seen from three sides, where a torus (a 2-D
    surface in the 4-D section) leaves closed curves and chaos a cloud -- regular cells
    coloured by their first shape frequency, so each torus keeps one colour, the others by
    regime -- and the projection onto (sigma, p_sigma) coloured by the fourth coordinate."""
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3-D projection)
    n = ds.sizes["crossing"]
    names = [q for q in ("sigma", "p_sigma", "eta", "p_eta") if q != fourth]
    pts = {q: ds[f"crossing_{q}"].values.reshape(-1, n) for q in names + [fourth]}
    width = SLAB * float(np.nanmax(pts[fourth]) - np.nanmin(pts[fourth]))
    inside = np.abs(pts[fourth] - at) <= width
    regime = ds[V.regime].values.ravel()
    nu = ds[V.frequency].isel(fundamental=0).values.ravel() if V.frequency in ds \
        else np.full(regime.shape, np.nan)
    regular = np.isin(regime, REGULAR) & np.isfinite(nu)
    from matplotlib.colors import Normalize
    norm = Normalize(*(np.nanpercentile(nu[regular], [2, 98]) if regular.any() else (0, 1)))
    fig = Figure(figsize=(11.5, 10.0), layout="constrained")
    grid = fig.add_gridspec(2, 2)
    for k, (elev, azim) in enumerate(SLICE_VIEWS):
        ax = fig.add_subplot(grid[k // 2, k % 2], projection="3d")
        ax.view_init(elev=elev, azim=azim)
        for r in Regime:
            mine = (regime == r) & ~regular
            keep = inside & mine[:, None]
            if keep.any():
                ax.scatter(*(pts[q][keep] for q in names), s=1.5, lw=0, alpha=0.5,
                           color=REGIME_COLOURS[r], rasterized=True,
                           label=f"{r.name.lower()} ({int(mine.sum())} starts)")
        keep = inside & regular[:, None]
        if keep.any():
            colours = np.broadcast_to(nu[:, None], inside.shape)[keep]
            mesh = ax.scatter(*(pts[q][keep] for q in names), c=colours, cmap="viridis",
                              norm=norm, s=2.0, lw=0, rasterized=True)
        ax.set_xlabel(label(names[0]))
        ax.set_ylabel(label(names[1]))
        if elev < 80:
            ax.set_zlabel(label(names[2]))
        else:               # seen from above: the third axis is the depth
            ax.set_zticks([])
            ax.set_title(f"from above ({label(names[2])} hidden)", fontsize="small")
        if k == 0 and ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize="x-small", markerscale=5, loc="upper left")
    if regular.any():
        fig.colorbar(mesh, ax=fig.axes[1], location="right", shrink=0.7, pad=0.08,
                     label=f"{int(regular.sum())} regular starts:\nfirst shape frequency")
    ax = fig.add_subplot(grid[1, 1])
    good = np.isfinite(pts[fourth])
    proj = ax.scatter(pts[names[0]][good], pts[names[1]][good], c=pts[fourth][good],
                      cmap="coolwarm", s=0.6, lw=0, rasterized=True)
    fig.colorbar(proj, ax=ax, label=label(fourth))
    ax.set_xlabel(label(names[0]))
    ax.set_ylabel(label(names[1]))
    ax.set_title(f"every crossing, projected, coloured by {label(fourth)}", fontsize="small")
    energy, spin = per_cell(ds, V.energy), per_cell(ds, V.angular_momentum)
    fig.supxlabel(textwrap.fill(
        f"one energy shell E = {np.nanmean(energy):.7g}, J = {np.nanmean(spin):.7g}, surface of "
        f"section phi = {crossing_surface(ds)[1]:.6g}; 3-D views: the slice |{fourth} - {at:g}| <= "
        f"{width:.3g} of the 4-D section ({int(inside.sum())} of {int(good.sum())} "
        "crossings), in which a torus draws "
        "closed curves and chaos fills a volume", 150), fontsize="small")
    return fig


SLAB = 0.025     # half-width of a slice's slab, as a share of each coordinate's range


def slice_slab(ds, slice_at: dict):
    """A grid over two coordinates of a section fixes the others (slice_at: name -> value):
    the grid is a 2-D slice of the section, and only crossings within the slab |q - q0| <=
    SLAB (range of q's crossings) of each fixed q belong on it. Returns (mask over the
    flattened crossings, the slab's description with counts)."""
    a = grid_axes(ds)[0]
    keep = np.isfinite(ds[f"crossing_{a}"].values.ravel())
    total = int(keep.sum())
    parts = []
    for q, q0 in slice_at.items():
        values = ds[f"crossing_{q}"].values.ravel()
        width = SLAB * float(np.nanmax(values) - np.nanmin(values))
        keep &= np.abs(values - q0) <= width
        parts.append(f"|{q} - {q0:g}| <= {width:.2g}")
    return keep, "(" + ", ".join(parts) + f"; {int(keep.sum())} of {total})"
