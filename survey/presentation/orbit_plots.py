"""The paper's single-orbit figures: paths with the Hill-type disk, the orbit in inequity
space, P and A against time, side lengths with near collisions; several orbits in inequity
space on one figure."""
from __future__ import annotations

import textwrap

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure

from ..physics.geometry import area, inequities, sides

DENSE = 4000        # samples beyond which a path fades and a time series becomes a band


def orbit_figures(system, t, states, title="", p_max=None, collision_fraction=0.05):
    """The paper's single-orbit figures from an orbit sampled at times t (states (k, n)):
    paths in the plane with the Hill-type disk |x - R| <= P_max/3, the orbit in inequity
    space, P and A against time, side lengths against time with near collisions marked."""
    q, _ = system.split(states)
    u, v, w = q[:, 0], q[:, 1], q[:, 2]
    s = sides(u, v, w)
    out = {}
    fig = Figure(figsize=(5.6, 5.4), layout="constrained")
    ax = fig.add_subplot()
    centre = system.centre_of_mass(states[0])
    for body, colour in zip(range(3), ("tab:red", "tab:green", "tab:blue")):
        _path(ax, q[:, body, 0], q[:, body, 1], colour, "uvw"[body])
        ax.plot(q[0, body, 0], q[0, body, 1], "o", color=colour, ms=6)
    if p_max is not None:
        from matplotlib.patches import Circle
        ax.add_patch(Circle(centre[:2], p_max / 3, fill=False, ls="--", color="0.4",
                            label=rf"$|x-R| \leq P_{{max}}/3$ = {p_max / 3:.4g}"))
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.legend(fontsize="small")
    ax.set_title(f"{title}: positions up to t = {t[-1]:g}"
                 + (" (fading: older is paler)" if t.size > DENSE else ""), fontsize="medium")
    out["paths"] = fig

    fig = Figure(figsize=(5.6, 5.4), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    ia = inequities(u, v, w)
    dense = t.size > DENSE
    ax.plot(ia[:, 0], ia[:, 1], ia[:, 2], lw=0.3 if dense else 0.6, color="k",
            alpha=max(0.15, DENSE / t.size) if dense else 1.0)
    _inequity_axes(ax)
    ax.set_title(f"{title}: inequities", fontsize="medium")
    out["inequities"] = fig

    fig = Figure(figsize=(8.0, 5.0), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    _series(ax1, t, s.sum(axis=1), "k")
    ax1.set_ylabel("$P$")
    _series(ax2, t, area(u, v, w) if system.dim == 2 else
            np.linalg.norm(area(u, v, w), axis=1), "k")
    ax2.set_ylabel("$A$")
    ax2.set_xlabel("t")
    ax1.set_title(f"{title}: perimeter and area" + (
        f" (band: range over each {(t[-1] - t[0]) / BINS:.3g} time units)"
        if t.size > DENSE else ""), fontsize="medium")
    out["perimeter_area"] = fig

    fig = Figure(figsize=(8.0, 3.6), layout="constrained")
    ax = fig.add_subplot()
    for k, (name, colour) in enumerate(zip("abc", ("tab:red", "tab:green", "tab:blue"))):
        _series(ax, t, s[:, k], colour, name)
    close = near_collisions(t, s, collision_fraction)
    for tc, side, value in close:
        ax.plot(tc, value, "kv", ms=5)
    ax.plot([], [], "kv", ms=5, label=f"near collisions ({len(close)})")
    ax.set_xlabel("t")
    ax.set_ylabel("side length")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.0, 1.0))
    ax.set_title(f"{title}: side lengths", fontsize="medium")
    out["sides"] = fig
    return out


BINS = 250          # bands of a dense time series


def _series(ax, t, x, colour, label=None):
    """A time series; a dense one (more than DENSE samples) as the band of its minimum and
    maximum over BINS equal time bins, which stays readable at any length."""
    if t.size <= DENSE:
        ax.plot(t, x, lw=0.7, color=colour, label=label)
        return
    edges = np.linspace(0, t.size, BINS + 1).astype(int)
    lo = np.minimum.reduceat(x, edges[:-1])
    hi = np.maximum.reduceat(x, edges[:-1])
    mid = t[(edges[:-1] + edges[1:] - 1) // 2]
    ax.fill_between(mid, lo, hi, color=colour, alpha=0.3, lw=0.3, label=label)


def _path(ax, x, y, colour, label):
    """A body's path; a dense one fades from pale (early) to solid (late), so the last
    stretch stays visible over the earlier ones."""
    if x.size <= DENSE:
        ax.plot(x, y, color=colour, lw=0.8, label=label)
        return
    points = np.stack([x, y], axis=1)
    segments = np.stack([points[:-1], points[1:]], axis=1)
    alpha = np.linspace(0.05, 1.0, len(segments)) ** 2
    rgba = np.zeros((len(segments), 4))
    rgba[:, :3] = to_rgb(colour)
    rgba[:, 3] = alpha
    ax.add_collection(LineCollection(segments, colors=rgba, linewidths=0.5))
    ax.plot([], [], color=colour, lw=0.8, label=label)
    ax.autoscale_view()


def _inequity_axes(ax):
    ax.set_xlabel("$i_a$")
    ax.set_ylabel("$i_b$")
    ax.set_zlabel("$i_c$")
    ax.set_box_aspect(None, zoom=0.85)      # room for the labels


def near_collisions(t, s, fraction=0.05):
    """Local minima of each side below `fraction` of the mean side length: (t, side, value)."""
    scale = fraction * np.mean(s)
    out = []
    for k in range(3):
        x = s[:, k]
        mins = np.flatnonzero((x[1:-1] < x[:-2]) & (x[1:-1] <= x[2:]) & (x[1:-1] < scale)) + 1
        out += [(t[i], "abc"[k], x[i]) for i in mins]
    return sorted(out)


def inequity_set(system, orbits: dict) -> Figure:
    """Several orbits in inequity space on one figure (the paper's EquilateralSet)."""
    fig = Figure(figsize=(6.0, 5.6), layout="constrained")
    ax = fig.add_subplot(projection="3d")
    colours = ["k", "tab:red", "tab:blue", "tab:orange", "tab:green", "tab:purple"]
    curves = []
    for (name, states), colour in zip(orbits.items(), colours):
        q, _ = system.split(states)
        curves.append((name, colour, inequities(q[:, 0], q[:, 1], q[:, 2])))
    # the widest first, so that the orbits nested inside it are drawn over it
    for name, colour, ia in sorted(curves, key=lambda c: -np.ptp(c[2], axis=0).sum()):
        ax.plot(ia[:, 0], ia[:, 1], ia[:, 2], lw=0.9, color=colour, label=name, alpha=0.85)
    _inequity_axes(ax)
    handles, labels = ax.get_legend_handles_labels()
    order = [labels.index(name) for name in orbits]        # the legend in the given order
    ax.legend([handles[k] for k in order], [labels[k] for k in order], fontsize="small")
    return fig


def spec_figures(name: str, zoom_until: float, runs) -> dict:
    """The figures of an orbit spec's runs (pipeline.orbits.OrbitRun): the four single-orbit
    figures (paths and side lengths up to `zoom_until` if it is > 0), or for a set of
    orbits their common inequity-space figure."""
    if len(runs) > 1:
        system = runs[0].system
        orbits = {r.label: r.outcome.samples[~np.isnan(r.outcome.samples[:, 0]), :system.n]
                  for r in runs}
        return {"inequities": inequity_set(system, orbits)}
    run = runs[0]
    system, out = run.system, run.outcome
    t = out.t_eval
    done = ~np.isnan(out.samples[:, 0])
    figs = orbit_figures(system, t[done], out.samples[done, :system.n], title=name,
                         p_max=run.p_max)
    if zoom_until:
        upto = done & (t <= zoom_until)
        zoomed = orbit_figures(system, t[upto], out.samples[upto, :system.n], title=name,
                               p_max=run.p_max)
        figs["paths"], figs["sides"] = zoomed["paths"], zoomed["sides"]
    return figs


MARKS = {"elliptic": "o", "hyperbolic": "X", "inverse hyperbolic": "P"}


def plane_figure(name: str, spec, run) -> Figure:
    """A section of the isosceles plane (pipeline.orbits.PlaneSpec and its PlaneRun): each
    orbit's crossings in its own colour -- an invariant curve, an island chain or a
    scattered sea -- inside the energy shell's edge on the section."""
    fig = Figure(figsize=(7.5, 6.4), layout="constrained")
    ax = fig.add_subplot()
    b, edge = run.edge
    ax.plot(b, edge, color="0.6", lw=0.8)
    ax.plot(b, -edge, color="0.6", lw=0.8, label="edge of the energy shell")
    colours = [f"C{k % 10}" for k in range(len(run.sections))]
    for (b0, p0), sec, colour in zip(spec.starts, run.sections, colours):
        ax.plot(sec.b, sec.p_b, ".", ms=1.8, color=colour, rasterized=True)
        ax.plot([b0], [p0], "x", ms=4, color=colour)
    grown = [f for f in run.manifolds if hasattr(f, "branches")]
    for kind, colour in (("unstable", "#d62728"), ("stable", "#1f3fb4")):
        for k, branch in enumerate(b for f in grown for b in f.branches if b.kind == kind):
            ax.plot(branch.points[:, 0], branch.points[:, 1], "-", color=colour, lw=0.9,
                    label=None if k else f"{kind} manifold")
    crossings = np.array([h.point for f in grown for h in f.homoclinic]).reshape(-1, 2)
    if crossings.size:
        ax.plot(crossings[:, 0], crossings[:, 1], "o", ms=5, mfc="gold", mec="k", mew=0.8,
                ls="none", label="first homoclinic crossings")
    marked, shown = [], run.periodic + [f.orbit for f in grown]
    for orbit in shown:
        if not orbit.converged or any(o.same_as(orbit) for o in marked):
            continue
        elliptic = orbit.kind == "elliptic"
        ax.plot(orbit.b, orbit.p_b, MARKS[orbit.kind], ms=7 if elliptic else 6,
                mfc="none" if elliptic else "k", mec="k", mew=1.4, ls="none",
                label=None if any(o.kind == orbit.kind for o in marked) else
                f"{orbit.kind} periodic orbit" + (" (its k points)" if
                                                  max(o.crossings for o in shown
                                                      if o.converged) > 1 else ""))
        marked.append(orbit)
    inside = np.isfinite(edge)
    sides = {np.sign(b0) for b0, _ in spec.starts}
    if not any(s.passages for s in run.sections) and len(sides) == 1:
        inside &= np.sign(b) == sides.pop()     # the orbits stay on their side of b = 0
    if inside.any():
        lo, hi = b[inside].min(), b[inside].max()
        ax.set_xlim(lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo))
    ax.set_xlabel("base $b$ (signed: $u$ and $w$ change places at $b = 0$)")
    ax.set_ylabel("$p_b = \\dot b / 2$")
    worst = max(s.energy_error for s in run.sections)
    passages = sum(s.passages for s in run.sections)
    points = sum(s.b.size for s in run.sections)
    early = sum(s.status.name != "OK" for s in run.sections)
    ax.set_title(textwrap.fill(
        f"{name}: the isosceles plane under {run.system.describe()}; E = {spec.energy:g}, "
        f"section h = {spec.height:g} crossed upwards; {len(run.sections)} orbits (x: their "
        f"starts), {points} crossings, {passages} passages through b = 0, |E/E0 - 1| <= "
        f"{worst:.0e}" + (f"; {early} orbits ended early (step limit)" if early else "")
        + (f"; {len(marked)} periodic orbits marked (Newton on the section map, stability "
           f"from its Jacobian's trace)" if marked else "")
        + (f"; the manifolds of {len(grown)} hyperbolic orbit{'s' if len(grown) > 1 else ''}"
           f" to arclength {spec.manifold_length:g}, grown from its eigenvectors"
           if grown else ""),
        110), fontsize="small")
    ax.legend(loc="upper right", fontsize="small", framealpha=0.9)
    return fig
