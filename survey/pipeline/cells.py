"""A survey's cells: their starts, the task a worker runs on a chunk of them, and everything
one cell computes.

A cell's result depends only on the config and its start (deviation vectors and perturbed
starts are seeded by (seed, start)), never on its place in the grid, the chunk it travels
in or the worker that runs it: an archive is the same bit for bit whatever the chunk size
or worker count, and the same start gives the same numbers in any grid.
"""
from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, replace

import numpy as np

from ..analysis.classify import Table, classify, verdict_class
from ..catalog.errors import ConfigError, Inaccessible
from ..catalog.regimes import Thresholds
from ..catalog.status import Status
from ..catalog.variables import (
    CellResult,
    V,
    fundamental_names,
    history_grid,
    history_times,
    horizon_factors,
)
from ..numerics import torus
from ..numerics.indicators import batch_options, combine, conservation_errors, ensemble
from ..numerics.driver import compile_round
from ..numerics.events import escape_events
from ..numerics.integrate import integrate_batch
from ..machine import linalg, portable
from ..physics.equilibria import forces
from ..physics.families import initial_state
from ..physics.jacobi import reduced
from . import archive
from .build import build_system, escape_for, indicator_options, section_event_for
from .config import Config
from .records import (IndicatorsTable, IntegrationTable, OutcomesTable, SectionTable,
                      ToriTable)


THIN_EQUILATERAL = 3 ** 0.5 / 36     # |A| / P^2 of the equilateral triangle


def build_starts(config: Config, ids=None) -> np.ndarray:
    """Initial states of the cells `ids` (default every cell; (len, n)), NaN rows where
    inaccessible. A value that makes no start at all (a degenerate triangle) is a
    ConfigError naming the cell."""
    system = config.system()
    varies = any(a.term >= 0 for a in config.axes)
    family = config.settings.initial.family
    ids = range(config.n_cells) if ids is None else [int(i) for i in ids]
    starts = np.full((len(ids), system.n), np.nan)
    for row, index in enumerate(ids):
        params = config.cell_parameters(index)
        if varies:
            system = config.system(index)
        try:
            starts[row] = initial_state(system, family, **params)
        except Inaccessible:
            continue
        except ValueError as exc:
            values = {**params, **config.axis_values(index, terms=True)}
            at = ", ".join(f"{a.name} = {values[a.name]:g}" for a in config.axes)
            raise ConfigError("[initial]" + (f" at {at}" if at else ""), str(exc)) from None
    return starts


@dataclass(frozen=True)
class GridStarts:
    """A grid's starts, built where its cells are integrated: a task carries this (the
    config's axes, not 8 bytes a component of every start) and its worker builds its chunk's
    starts, so that a grid of millions of cells starts computing at once and the driver
    never holds them all. Called with cell ids: their starts (build_starts)."""

    config: Config

    def __call__(self, ids) -> np.ndarray:
        return build_starts(self.config, ids)

    def first(self, ids) -> np.ndarray:
        """The first of `ids` with a start (none: empty), built in batches of 1, 2, 4, ...
        (a grid's first cell has a start, unless its corner is out of reach)."""
        at, batch = 0, 1
        while at < len(ids):
            some = np.asarray(ids[at:at + batch])
            found = some[~np.isnan(self(some)[:, 0])]
            if found.size:
                return found[:1]
            at, batch = at + batch, min(2 * batch, 4096)
        return np.zeros(0, dtype=np.int64)

    def check_corners(self):
        """The starts of the grid's corners (every axis at its first or last value), built
        before any work: a value that makes no start (a ConfigError) lies there in the
        common case -- the end of a range -- and any other stops the survey when the worker
        holding it builds it, its finished chunks kept."""
        shape = self.config.shape
        corners = {int(np.ravel_multi_index(at, shape)) for at in
                   np.ndindex(*(2,) * len(shape))
                   for at in [tuple((n - 1) * b for n, b in zip(shape, at))]}
        self(sorted(corners))


def resolved(starts, cell_ids) -> np.ndarray:
    """A task's starts: given (the rows of its cells), or built here (GridStarts)."""
    return starts(cell_ids) if callable(starts) else np.asarray(starts)


@dataclass(frozen=True)
class CellTask:
    """What a worker needs to integrate cells -- the result-determining tables and the
    archive's layout -- and nothing of the grid or the config text, which can be large."""

    system: dict                # the [system] table as build_system takes it
    integration: IntegrationTable
    indicators: IndicatorsTable
    section: SectionTable | None
    tori: ToriTable
    outcomes: OutcomesTable
    slots: tuple
    term_axes: tuple = ()   # (name, values, stride in flat cell index) of the terms' axes

    @classmethod
    def of(cls, config: Config) -> "CellTask":
        t = config.settings
        strides = np.cumprod((config.shape + (1,))[:0:-1])[::-1]
        terms = tuple((a.name, tuple(a.values.tolist()), int(stride))
                      for a, stride in zip(config.axes, strides) if a.term >= 0)
        return cls(config.system_table, t.integration, t.indicators,
                   t.section if t.section_enabled else None, t.tori, t.outcomes,
                   archive.layout(config), terms)

    def term_values(self, cell: int) -> tuple:
        """(axis name, value) of the interaction-term axes at a cell: what its System
        depends on beyond the [system] table."""
        return tuple((name, values[(cell // stride) % len(values)])
                     for name, values, stride in self.term_axes)

    def short(self) -> "CellTask":
        """The same task with a tiny t_final: compiles (or loads) every kernel a cell uses."""
        ind = self.indicators
        return replace(self, integration=replace(self.integration, t_final=1e-3),
                       indicators=replace(ind, renorm_interval=1e-3,
                                          perturbations=min(1, ind.perturbations)))


def run_cells(task: CellTask, cell_ids, starts) -> dict[str, np.ndarray]:
    """Integrate a chunk of cells (the unit of work a dask task does) and decide their
    verdicts, those in doubt on longer runs too (first_runs, then extend_cells, here); one
    result row per cell in every array of the task's layout (starts: the cells' rows, or
    a GridStarts that builds them here)."""
    starts = resolved(starts, cell_ids)
    res, doubt = first_runs(task, cell_ids, starts)
    if doubt.size:
        rows = extend_cells(task, np.asarray(cell_ids)[doubt], np.asarray(starts)[doubt],
                            res[V.regime_history][doubt])
        merge_rows(res, doubt, rows)
    return res


def first_runs(task: CellTask, cell_ids, starts) -> tuple[dict, np.ndarray]:
    """The cells' runs to t_final: the orbits of all of them -- nominal orbits, their
    deviation vectors, perturbed starts -- as SIMD lanes of one batch per System (cells
    differ in System only along interaction-term axes), each cell's verdicts at T/2 and T.
    Returns the result rows and the rows whose verdict is in doubt (for extend_cells;
    their rows are as of this run until then)."""
    clock = time.perf_counter()
    starts = resolved(starts, cell_ids)
    results = [CellResult(Status.INACCESSIBLE, 0.0)] * len(cell_ids)
    doubt = []
    decide = bool(task.indicators.which or task.tori.analyse)
    longer = len(horizon_factors(task.tori.extend, task.tori.extend_rounds)) > 2
    for system, events, rows in _systems(task, cell_ids, starts):
        ran = _run(task, system, events, [starts[k] for k in rows], 1)
        if decide:
            verdicts, in_doubt = _first_verdicts(task, system, ran)
            ran = [r._replace(verdicts=v) for r, v in zip(ran, verdicts)]
            doubt += [k for k, d in zip(rows, in_doubt) if d and longer]
        for k, result in zip(rows, ran):
            results[k] = result
    return _rows(task, results, clock), np.array(sorted(doubt), dtype=np.int64)


def extend_cells(task: CellTask, cell_ids, starts, history) -> dict[str, np.ndarray]:
    """Cells whose verdict first_runs left in doubt, run again from their start to
    extend x T and decided there -- and again, up to extend_rounds times, while still in
    doubt (history: their regime_history rows so far). A cell's result depends on itself
    alone, so these may run in any task, with any others, and verify reproduces them."""
    clock = time.perf_counter()
    starts = resolved(starts, cell_ids)
    results = [None] * len(cell_ids)
    for system, events, rows in _systems(task, cell_ids, starts):
        verdicts = np.array(history)[rows]
        for k, result in zip(rows, _extend(task, system, events, [starts[k] for k in rows],
                                           verdicts)):
            results[k] = result
    return _rows(task, results, clock)


def merge_rows(res: dict, at: np.ndarray, rows: dict):
    """The rows `at` of first_runs' arrays replaced by extend_cells' rows of those cells (the
    wall time the sum of both)."""
    for name, values in rows.items():
        res[name][at] = values + res[name][at] if name == V.wall_time else values


def _systems(task: CellTask, cell_ids, starts):
    """(System, its events -- the surface of section's, then the escapes' -- the rows of
    the cells with a start on it) of a chunk's cells."""
    groups: dict = {}
    for k, cell in enumerate(cell_ids):
        groups.setdefault(task.term_values(int(cell)), []).append(k)
    for at, rows in groups.items():
        system = build_system(task.system, dict(at))
        events = [section_event_for(task.section, system)] if task.section \
            else []
        escape = escape_for(task.outcomes, system)
        if escape is not None:
            events += escape_events(system, *escape)
        rows = [k for k in rows if not np.isnan(starts[k][0])]
        if rows:
            yield system, events, rows


def _rows(task: CellTask, results, clock) -> dict[str, np.ndarray]:
    """The result arrays of a task's cells, each with its share of the task's wall time."""
    res = archive.empty_results(task.slots, len(results))
    wall = (time.perf_counter() - clock) / max(len(results), 1)
    for k, result in enumerate(results):
        archive.fill_row(res, k, result._replace(wall_time=wall))
    return res


def jobs_per_cell(task: CellTask) -> int:
    """The orbits a cell integrates (lanes of its chunk's batch)."""
    ind = task.indicators
    if not ind.which:
        return 1
    nominal = 1 if task.integration.control_tangents else ind.deviations
    return nominal + ind.perturbations


def _first_verdicts(task: CellTask, system, results):
    """Each cell's verdicts from its first run, at T/2 and T (-1 at the longer horizons),
    and whether it is in doubt: its verdict changed class between them, or its evidence did
    not all vote for it (a line between its thresholds, or against it)."""
    factors = horizon_factors(task.tori.extend, task.tori.extend_rounds)
    half, _ = _verdicts(task, system, results, half=True)
    end, confidence = _verdicts(task, system, results)
    verdicts = np.full((len(results), len(factors)), -1, dtype=np.int8)
    verdicts[:, 0], verdicts[:, 1] = half, end
    return verdicts, [_in_doubt(r, h, e, c) for r, h, e, c in zip(results, half, end,
                                                                    confidence)]


def _extend(task: CellTask, system, events, starts, verdicts) -> list[CellResult]:
    """Verdicts against a longer horizon: cells in doubt at T run again from their start to
    extend x T, are decided there, and run again while still in doubt, up to extend_rounds
    times. Every cell carries its verdicts (regime_history) and the horizon of the run its
    evidence comes from."""
    factors = horizon_factors(task.tori.extend, task.tori.extend_rounds)
    results = [None] * len(starts)
    todo = list(range(len(starts)))
    for level in range(2, len(factors)):
        if not todo:
            break
        longer = _run(task, system, events, [starts[k] for k in todo], int(factors[level]))
        new, confidence = _verdicts(task, system, longer)
        for k, r, v in zip(todo, longer, new):
            results[k] = r
            verdicts[k, level] = v
        todo = [k for k, r, v, c in zip(todo, longer, new, confidence)
                if _in_doubt(r, verdicts[k, level - 1], v, c)]
    return [r._replace(verdicts=v) for r, v in zip(results, verdicts)]


def _in_doubt(result: CellResult, before, now, confidence) -> bool:
    """A finished run whose verdict changed class since the horizon before, or that not
    every line of evidence supports."""
    return result.status.finished and (verdict_class(before) != verdict_class(now)
                                       or confidence < 1.0)


def _verdicts(task: CellTask, system, results, half: bool = False):
    """(regime, confidence) of each result, as the archive will derive them, at its
    horizon or at half of it."""
    slots = [slot for slot in task.slots if slot.name != V.regime_history]
    arrays = archive.empty_results(slots, len(results))
    for k, result in enumerate(results):
        archive.fill_row(arrays, k, result)
    return classify_rows(task, system, arrays, half)


def classify_rows(task: CellTask, system, arrays: dict, half: bool = False):
    """(regime, confidence) of cells from their result arrays (a task's, or a
    checkpoint's), as the archive derives them."""
    tor, ind = task.tori, task.indicators
    table = Table(arrays, history_time=history_grid(
        task.integration.t_final, ind.history_points, tor.extend,
        tor.extend_rounds), fundamental_name=np.array(fundamental_names(
            system.n_bodies, system.dim, not system.translation_invariant)))
    return classify(table, Thresholds.from_table(vars(tor)), half=half)


def _run(task: CellTask, system, events, starts, factor: int) -> list[CellResult]:
    """Integrate cells to factor x t_final, their orbits as lanes of one batch, and compute
    everything a cell stores from those runs."""
    integ, ind, tor = task.integration, task.indicators, task.tori
    t_final = factor * integ.t_final
    points = factor * ind.history_points
    run = dict(rtol=integ.rtol, atol=integ.atol, max_steps=integ.max_steps,
               time_limit=integ.cell_time_limit, events=events, approach=True,
               thin=task.outcomes.thin * THIN_EQUILATERAL)
    dt = tor.sample_interval
    if tor.analyse:    # midpoints of equal intervals: the Birkhoff sums' quadrature;
        # each batch's samples are analysed before this thread's next batch reuses them
        run.update(t_fine=(np.arange(int(t_final / dt)) + 0.5) * dt, reuse_samples=True)
    if task.section:
        run["max_events"] = task.section.max_crossings
    if ind.which:
        options = replace(indicator_options(ind), history_points=points)
        jobs = [ensemble(system, y0, options, integ.control_tangents) for y0 in starts]
        outcomes = integrate_batch(
            system, np.concatenate([j.starts for j in jobs]), t_final,
            tangents=np.concatenate([j.tangents for j in jobs]),
            record=np.concatenate([j.record for j in jobs]),
            **batch_options(t_final, options, control_tangents=integ.control_tangents,
                            **run))
        first = np.cumsum([0] + [len(j.starts) for j in jobs])
        indicators = [combine(system, y0, t_final, options, j, outcomes[a:b])
                      for y0, j, a, b in zip(starts, jobs, first[:-1], first[1:])]
        ends = [(i.outcome, i.status, (i.energy_error, i.angular_momentum_error))
                for i in indicators]
    else:
        history = history_times(t_final, points)
        outcomes = integrate_batch(system, np.array(starts), t_final, t_eval=history, **run)
        indicators = [None] * len(starts)
        ends = []
        for y0, out in zip(starts, outcomes):
            done = ~np.isnan(out.samples[:, 0])
            ends.append((out, out.status, conservation_errors(
                system, y0, np.concatenate([out.samples[done], [out.y]]))))
    planar3 = system.n_bodies == 3 and system.dim == 2
    watched = len(events) > (1 if task.section else 0)     # escape events after the section's
    results = []
    for y0, ind_k, (out, status, errors) in zip(starts, indicators, ends):
        escape, crossings, n_crossings = None, out.crossings, out.n_crossings
        if watched and status == Status.EVENT:
            status, n_crossings = Status.ESCAPED, n_crossings - 1
            escape = escaped(system, out.y, out.t, task.outcomes.exits)
        if watched and task.section:
            on = crossings.index == 0
            crossings = crossings._replace(index=crossings.index[on], t=crossings.t[on],
                                           y=crossings.y[on])
        evidence = None
        if tor.analyse and status.finished:
            evidence = torus_evidence(task, system, out.fine, errors[0])
        results.append(CellResult(
            status=status, wall_time=0.0, n_steps=out.n_steps,
            n_rhs=out.n_rhs, start=y0, t_end=out.t, energy=system.energy(y0),
            angular_momentum=system.angular_momentum(y0),
            scale_free_energy=system.scale_free_energy(y0),
            start_potential=float(system.potential_energy(y0)), energy_error=errors[0],
            angular_momentum_error=errors[1], indicators=ind_k, tori=evidence,
            n_crossings=n_crossings,
            crossing_time=crossings.t, crossing_state=crossings.y,
            reduced=reduced(system, crossings.y) if planar3 else None,
            centre=None if system.translation_invariant else (
                system.centre_of_mass(crossings.y), system.momentum(crossings.y)),
            horizon=t_final, near=out.near, escape=escape))
    return results


def escaped(system, y, t: float, exits) -> tuple[float, int, int]:
    """(time, body, exit) of an escape that ended an orbit at state y, time t: the body
    farthest from the others' centre of mass (the one whose escape event fired; one body
    in a field), and in a field the index of the exit direction (degrees) nearest the
    body's (-1 if no exits are given)."""
    q = system.split(y)[0]
    m = system.masses
    if system.translation_invariant:
        rest = (m.sum() - m)[:, None]
        away = q - ((m[:, None] * q).sum(0) - m[:, None] * q) / rest
        body = int(np.argmax(np.einsum("ij,ij->i", away, away)))
    else:
        body = 0
    exit_ = -1
    if exits:
        angle = np.degrees(np.arctan2(q[body, 1], q[body, 0]))
        gap = np.abs((angle - np.asarray(exits, dtype=float) + 180.0) % 360.0 - 180.0)
        exit_ = int(np.argmin(gap))
    return float(t), body, exit_


def torus_evidence(task: CellTask, system, fine, energy_error) -> torus.TorusEvidence:
    """The torus analysis of one orbit's samples, as the task's [tori] table asks."""
    tor = task.tori
    return torus.analyse(system, fine, tor.sample_interval, energy_error,
                         tor.observables, tor.lines, tor.resonance_order)


def warm_up(task: CellTask, first, starts):
    """Load every compiled kernel a cell uses from numba's disk cache."""
    if first.size:
        run_cells(task.short(), first, starts)


def warm_beside(task: CellTask, first, starts, report: bool = True):
    """On a first run, in a worker while the driver compiles the integrator (warm_up, one
    core for twenty seconds): compile the integrator's stepping round (`compile_round`,
    which the driver then loads from the disk cache) and the kernels the survey needs
    after it -- the energies a cell's results take (which warm_up compiled after the
    integrator), the torus analysis (which a cell's first real run compiled in every
    worker) and, with `report`, the forces and linear algebra of the report's special
    solutions (which the driver compiled after the survey) -- on stand-in data of the
    types they are given: a smooth quasi-periodic motion near the first start, small
    matrices (the wrappers of machine.linalg make their kernels' arguments contiguous
    float64)."""
    if not first.size:
        return
    compile_round(lambda: run_cells(task.short(), first, starts), False)
    system = next(_systems(task, first, starts))[0]
    y0 = np.asarray(starts[0], dtype=np.float64)
    rng = np.random.default_rng(0)
    dt = task.tori.sample_interval
    # samples enough for every path: NAFF updates its spectrum in place on halves of over
    # 4 x SPECTRUM_BINS samples (a long run, or a cell in doubt extended)
    t = (np.arange(16 * torus.SPECTRUM_BINS) + 0.5) * dt
    modes = rng.standard_normal((3, y0.size))
    modes *= 1e-2 * max(float(np.max(np.abs(y0))), 1.0) / np.linalg.norm(modes, axis=1,
                                                                         keepdims=True)
    waves = np.stack([np.sin(t), np.cos(np.sqrt(2.0) * t), np.sin(np.sqrt(5.0) * t)], 1)
    states = np.ascontiguousarray(y0 + waves @ modes)

    def results():
        """What every cell's result takes after its orbits (else compiled by warm_up's
        driver after the integrator): energies, the scale-free energy, log norms."""
        conservation_errors(system, y0, states)
        system.scale_free_energy(y0)
        portable.vlog(portable.vnorm(states))

    def analysis():
        torus.analyse(system, states, dt, 1e-12, task.tori.observables, task.tori.lines,
                      task.tori.resonance_order)

    def second_half():
        compile_round(lambda: run_cells(task.short(), first, starts), True)

    # the round's second half evaluates the right-hand side, which the driver compiles
    # (and caches) meanwhile: it comes after a few seconds' other work; with the report,
    # its special solutions' forces and Hessians, and their linear algebra
    report_forces = [lambda: solver_forces(system, y0)] if report else []
    report_algebra = [solver_algebra] if report else []
    if task.tori.analyse:
        steps = [analysis, second_half, results, *report_forces, *report_algebra]
    else:
        steps = [results, *report_forces, second_half, *report_algebra]
    with np.errstate(all="ignore"):
        for step in steps:
            step()


def head_start(warm, *args):
    """warm(*args) in another process (a worker, where an exception would be logged as a
    failed task, or `compiled_beside`'s helper): a head start that fails leaves its
    kernels to compile where first used, as without it."""
    try:
        warm(*args)
    except Exception:
        pass


def solver_forces(system, y0):
    """Compile (or load) what the special solutions' solvers evaluate of `system` at y0's
    kind of state: its forces with their Hessian (physics.system.rhs among them)."""
    forces(system, system.split(y0)[0], hessian=True)


def solver_algebra():
    """Compile (or load) the solvers' linear algebra, on a small square matrix."""
    a = np.random.default_rng(0).standard_normal((6, 6))
    linalg.eig(a)
    linalg.svd(a)
    linalg.lstsq(a, a[0], 1e-14)
    linalg.chain(a, a, a)
    linalg.symmetric_eigen(linalg.dot(a, a.T))     # a Morse index


def warm_solvers(system, y0, integrates: bool = True):
    """In `compiled_beside`'s helper of `periodic` and `equilibria`, whose solvers compile
    the system's forces (physics.system.rhs) first: for a solver that `integrates` (then
    compiles the integrator), the stepping round's half that evaluates the right-hand side
    (the full states' integrator reaches it 8 s into its compiling, after a job's start),
    then the other half; the solvers' linear algebra and the system's energy."""
    def call():
        integrate_batch(system, y0[None], 1e-3, lanes=1)

    with np.errstate(all="ignore"):
        if integrates:
            compile_round(call, True, False)
        solver_algebra()
        system.energy(y0)


@contextlib.contextmanager
def compiled_beside(warm, *args):
    """A first run in one process (`verify`, `orbit`, `periodic`, `equilibria`): while
    this process compiles the integrator (or a solver's kernels) for the block, a process
    forked from it runs warm(*args) -- the stepping round's leaves (`compile_round`) and
    what else the block needs after the integrator -- and this one loads those kernels
    from the disk cache, else the second core idles for that half minute. With the
    kernels cached the helper only loads some of them, on that second core. It is stopped
    when the block ends: what it has not compiled by then is no longer ahead (numba writes
    a cache file under another name and renames it, so a stop leaves no torn kernel). A
    helper that fails leaves its kernels to compile here, as without it. Forked before
    this process compiles anything of the block, so no compiler lock is copied held;
    nothing where processes cannot be forked."""
    import multiprocessing
    if "fork" not in multiprocessing.get_all_start_methods():
        yield
        return
    helper = multiprocessing.get_context("fork").Process(target=head_start,
                                                         args=(warm, *args), daemon=True)
    helper.start()
    try:
        yield
    finally:
        helper.terminate()
        helper.join()
