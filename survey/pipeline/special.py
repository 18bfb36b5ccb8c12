"""The special solutions a survey's cells start on, for its report: relative equilibria at
its `equilibrium` cells, relative periodic orbits at its homographic ones, and the section
coordinates a section grid fixes -- computed once when the survey is written and stored in
its archive (`report_attributes`), so every reader of the archive reports the same."""
from __future__ import annotations

import json

import numpy as np

from ..analysis.refine import as_grid, cell_label
from ..numerics.integrate import integrate
from ..numerics.periodic import periodic_orbit
from ..physics.equilibria import equilibrium_positions, forces, relative_equilibrium
from ..physics.system import System
from .build import build_system


def equilibrium_cells(ds, most: int = 8) -> list[dict]:
    """The relative equilibria at an archive's `equilibrium` cells (at most `most`), each
    solved again from the cell's start at its J, with its stability and normal modes: what
    the report sets beside the family's frequencies. Cells where the solver finds none are
    left out."""
    from ..catalog.regimes import Regime
    from ..catalog.variables import V
    from .config import parse_config
    if V.regime not in ds or V.initial_state not in ds:
        return []
    cells = np.argwhere(ds[V.regime].values == Regime.EQUILIBRIUM)[:most]
    if not cells.size:
        return []
    config = parse_config(ds.attrs["config"], check_output=False)
    systems, out = _cell_systems(config, ds), []
    for idx in map(tuple, cells):
        system = systems(idx)
        start = ds[V.initial_state].values[idx]
        spin = float(ds[V.angular_momentum].values[idx]) if system.dim == 2 else 0.0
        try:
            eq = relative_equilibrium(system, system.split(start)[0], angular_momentum=spin)
        except (ValueError, np.linalg.LinAlgError):
            continue
        out.append({"kind": "equilibrium",
                    "cell": cell_label(ds, idx), "index": idx,
                    "rotation_rate": eq.rotation_rate, "stable": eq.stable,
                    "frequencies": eq.frequencies.tolist(),
                    "krein": [int(k) for k in eq.krein if k],
                    "rates": eq.rates})
    return out


def homographic_period(system: System, y, horizon: float) -> float | None:
    """The period of the size of a homographic start -- a central configuration moving
    as a similarity (v_i = a q_i + b e_z x q_i, forces -lambda m_i q_i) keeps its shape
    while it breathes and turns: a relative periodic orbit -- from the time between the
    first two minima of its moment of inertia within `horizon`; None if the start is
    not homographic (or not planar, or in an external field), is a rigid rotation (an equilibrium's business), or
    does not breathe within the horizon."""
    if system.dim != 2 or not system.translation_invariant:
        return None
    q, p = system.split(np.asarray(y, dtype=float))
    m = system.masses[:, None]
    q = q - np.sum(m * q, axis=0) / m.sum()
    v = p / m - np.sum(p, axis=0) / m.sum()
    gq = np.stack([-q[:, 1], q[:, 0]], axis=1)
    size = np.sum(m * q * q)
    a, b = np.sum(m * v * q) / size, np.sum(m * v * gq) / size
    acc = forces(system, q).reshape(q.shape) / m
    lam = -np.sum(m * acc * q) / size
    norm = lambda x: np.sqrt(np.sum(m * x * x))
    rigid = abs(a) <= 1e-9 * abs(b) and abs(lam - b * b) <= 1e-9 * lam
    if not (norm(v) > 0 and norm(v - a * q - b * gq) <= 1e-10 * norm(v) and lam > 0
            and norm(acc + lam * q) <= 1e-9 * norm(acc)) or rigid:
        return None
    times = np.linspace(0.0, horizon, 4001)
    out = integrate(system, y, horizon, t_eval=times, rtol=1e-12, atol=1e-12)
    if not out.ok:
        return None
    qs = system.split(out.samples)[0]
    inertia = np.sum(system.masses[None, :, None] * (qs - np.sum(
        system.masses[None, :, None] * qs, axis=1, keepdims=True) / m.sum()) ** 2, axis=(1, 2))
    low = np.flatnonzero((inertia[1:-1] < inertia[:-2]) & (inertia[1:-1] <= inertia[2:])) + 1
    return float(times[low[1]] - times[low[0]]) if low.size >= 2 else None


def homographic_cells(ds, most: int = 8) -> list[dict]:
    """The cells of an archive whose start is homographic (see homographic_period), each
    shot as a relative periodic orbit at its energy (`python -m survey periodic`): period,
    rotation, kind, how fast nearby orbits leave, beside the cell's own FTLE -- what the
    report sets beside a map's column of such cells. Cells where shooting fails are left
    out."""
    from ..catalog.variables import V
    from .config import parse_config
    if V.initial_state not in ds or V.status not in ds:
        return []
    config = parse_config(ds.attrs["config"], check_output=False)
    horizon = float(config.settings.integration.t_final)
    axes = list(ds[V.status].dims)
    starts = ds[V.initial_state].values.reshape(-1, ds[V.initial_state].shape[-1])
    systems, out = _cell_systems(config, ds), []
    for flat, y in enumerate(starts):
        if len(out) == most or not np.all(np.isfinite(y)):
            continue
        system = systems(np.unravel_index(flat, ds[V.status].shape))
        period = homographic_period(system, y, min(horizon, 100.0))
        if period is None:
            continue
        try:
            orbit = periodic_orbit(system, y, period, rotating=True)
        except ValueError:
            continue
        idx = np.unravel_index(flat, ds[V.status].shape) if axes else ()
        ftle = float(ds[V.ftle].values[idx]) if V.ftle in ds else float("nan")
        out.append({"kind": "periodic", "index": idx,
                    "cell": cell_label(ds, idx),
                    "period": orbit.period, "rotation": orbit.rotation,
                    "orbit_kind": orbit.kind, "stable": orbit.stable,
                    "rates": orbit.rates.tolist(), V.ftle: ftle})
    return out


def _cell_systems(config, ds):
    """idx -> the System of an archive's cell at index `idx` of its grid: the [system]
    table with the cell's values of any interaction-term axes (read from the archive's
    coordinates, each broadcast over the grid once, so a refined survey's cells are read
    too); one System for every cell where no term parameter is an axis. Built per cell,
    this was most of the time writing a large archive took."""
    from ..catalog.variables import V
    term = [a.name for a in config.axes if a.term >= 0]
    if not term:
        system = build_system(config.system_table, {})
        return lambda idx: system
    status = ds[V.status]
    grids = {a: ds[a].broadcast_like(status).transpose(*status.dims).values for a in term}
    return lambda idx: build_system(config.system_table,
                                    {a: float(g[idx]) for a, g in grids.items()})


def special_cells(ds) -> list[dict]:
    """The special solutions an archive's cells start on, for its report: relative
    equilibria at its equilibrium cells, relative periodic orbits at its homographic
    ones."""
    ds = as_grid(ds)
    return equilibrium_cells(ds) + homographic_cells(ds)


def report_attributes(ds) -> dict[str, str]:
    """What a survey's report needs that only a solver computes, as attributes of its
    archive (JSON text): the special solutions its cells start on (special_cells) and the
    section coordinates a section grid fixes (section_slice). Written with the archive
    (pipeline.archive.write), so every reader -- `python -m survey report`,
    `ds.survey.report()` -- sets the same beside the cells without solving again."""
    def plain(x):
        if isinstance(x, np.integer):
            return int(x)
        if isinstance(x, (np.floating, np.bool_)):
            return x.item()
        if isinstance(x, np.ndarray):
            return x.tolist()
        raise TypeError(f"{type(x).__name__} is not JSON")
    return {"special_cells": json.dumps(special_cells(ds), default=plain),
            "section_slice": json.dumps(section_slice(ds)),
            "dissociation_energy": json.dumps(dissociation_energy(ds))}


def dissociation_energy(ds) -> float | None:
    """Where bodies that watch for escapes can start to lose one: the least potential
    energy of the others alone, as a descent finds it -- from the first started cell's
    positions less one body, each body in turn, the others' equilibrium (0 for a pair) --
    the energy below which no body can leave (an upper bound of it where a descent misses
    the others' lowest minimum). None for an archive without escapes, or in a field."""
    from ..catalog.variables import V
    from .config import parse_config
    if V.escape_time not in ds or V.initial_state not in ds:
        return None
    config = parse_config(ds.attrs["config"], check_output=False)
    status = ds[V.status].values.ravel()
    started = np.flatnonzero(np.all(np.isfinite(ds[V.initial_state].values.reshape(
        status.size, -1)), axis=1))
    if not started.size:
        return None
    idx = np.unravel_index(started[0], ds[V.status].shape)
    system = _cell_systems(config, ds)(idx)
    if not system.translation_invariant:
        return None
    q = system.split(ds[V.initial_state].values[idx])[0]
    if system.n_bodies == 2:
        return 0.0
    least = np.inf
    # two bodies have no triangle: their triplet terms (the triple dipole) are nothing
    terms = system.terms if system.n_bodies > 3 else \
        tuple(t for t in system.terms if t.kind == "pair")
    for k in range(system.n_bodies):
        keep = np.arange(system.n_bodies) != k
        rest = System(system.masses[keep], system.dim, terms)
        try:
            at = equilibrium_positions(rest, q[keep])
        except (ValueError, np.linalg.LinAlgError):
            continue
        u = float(rest.potential_energy(np.concatenate([at.ravel(), np.zeros(at.size)])))
        least = min(least, u)
    return float(least) if np.isfinite(least) else None


def section_slice(ds) -> dict:
    """The section coordinates (sigma, p_sigma, eta, p_eta) an archive's config fixes while
    its grid varies the others: the slice of the section a `section` grid is."""
    from .config import parse_config
    fixed = parse_config(ds.attrs["config"], check_output=False).fixed
    return {q: float(fixed[q]) for q in ("sigma", "p_sigma", "eta", "p_eta")
            if q in fixed and f"crossing_{q}" in ds}

