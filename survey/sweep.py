"""Grid -> cells -> chunks -> dask -> checkpointed results -> archive.

A cell's result depends only on the config and its own index (deviation vectors are seeded
by (seed, cell index)), never on the chunk it travels in or the worker that runs it, so an
archive is the same bit for bit whatever the chunk size or worker count.

Finished chunks are written to checkpoint files as they arrive (atomically), under a key
that hashes everything that determines a cell's result (config tables, grid, code). Every
checkpoint is checked before it is used -- readable, written under this key, its cells in
the grid and its starts equal to this grid's -- and one that is not is recomputed. The
archive is written only when every cell is present. One survey at a time writes an output
(a lock beside it).
"""
from __future__ import annotations

import atexit
import contextlib
import errno
import fcntl
import logging
import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import archive, tori
from .archive import CellResult
from .config import (Config, ConfigError, build_system, indicator_options, load_config,
                     section_event_for, check_address)
from .coordinates import reduced
from .families import Inaccessible, initial_state
from .indicators import chaos_indicators, conservation_errors, history_times
from .integrator import integrate
from .status import Status


class SurveyError(RuntimeError):
    """A survey that cannot go on for a reason outside its config (a full disk, a busy
    output, cells that could not be computed): one line saying what and what to do."""


def build_starts(config: Config) -> np.ndarray:
    """Initial states of every cell (n_cells, n), NaN rows where inaccessible. A value that
    makes no start at all (a degenerate triangle) is a ConfigError naming the cell."""
    system = config.system()
    varies = any(a.term >= 0 for a in config.axes)
    family = config.tables["initial"]["family"]
    starts = np.full((config.n_cells, system.n), np.nan)
    for index in range(config.n_cells):
        params = config.cell_parameters(index)
        if varies:
            system = config.system(index)
        try:
            starts[index] = initial_state(system, family, **params)
        except Inaccessible:
            continue
        except ValueError as exc:
            values = {**params, **config.axis_values(index, terms=True)}
            at = ", ".join(f"{a.name} = {values[a.name]:g}" for a in config.axes)
            raise ConfigError("[initial]" + (f" at {at}" if at else ""), str(exc)) from None
    return starts


# ---------------------------------------------------------------- the task

@dataclass(frozen=True)
class CellTask:
    """What a worker needs to integrate cells -- the result-determining tables and the
    archive's layout -- and nothing of the grid or the config text, which can be large."""

    system: dict
    integration: dict
    indicators: dict
    section: dict | None
    tori: dict
    slots: tuple
    term_axes: tuple = ()   # (name, values, stride in flat cell index) of the terms' axes

    @classmethod
    def of(cls, config: Config) -> "CellTask":
        t = config.tables
        strides = np.cumprod((config.shape + (1,))[:0:-1])[::-1]
        terms = tuple((a.name, tuple(a.values.tolist()), int(stride))
                      for a, stride in zip(config.axes, strides) if a.term >= 0)
        return cls(t["system"], t["integration"], t["indicators"],
                   t["section"] if t["section_enabled"] else None, t["tori"],
                   archive.layout(config), terms)

    def term_values(self, cell: int) -> tuple:
        """(axis name, value) of the interaction-term axes at a cell: what its System
        depends on beyond the [system] table."""
        return tuple((name, values[(cell // stride) % len(values)])
                     for name, values, stride in self.term_axes)

    def short(self) -> "CellTask":
        """The same task with a tiny t_final: compiles (or loads) every kernel a cell uses."""
        ind = self.indicators
        return replace(self, integration={**self.integration, "t_final": 1e-3},
                       indicators={**ind, "renorm_interval": 1e-3,
                                   "perturbations": min(1, ind["perturbations"])})


def run_cells(task: CellTask, cell_ids, starts) -> dict[str, np.ndarray]:
    """Integrate a chunk of cells (the unit of work a dask task does): one result row per
    cell in every array of the task's layout."""
    res = archive.empty_results(task.slots, len(cell_ids))
    systems = {}
    for k, (cell, y0) in enumerate(zip(cell_ids, starts)):
        at = task.term_values(int(cell))
        if at not in systems:
            system = build_system(task.system, dict(at))
            systems[at] = system, ([section_event_for({"section": task.section}, system)]
                                   if task.section else [])
        archive.fill_row(res, k, compute_cell(task, *systems[at], int(cell), y0))
    return res


def compute_cell(task: CellTask, system, events, cell: int, y0) -> CellResult:
    """Everything one cell's variables are filled from."""
    clock = time.perf_counter()
    if np.isnan(y0[0]):
        return CellResult(Status.INACCESSIBLE, time.perf_counter() - clock)
    integ, ind, tor = task.integration, task.indicators, task.tori
    kw = dict(rtol=integ["rtol"], atol=integ["atol"], max_steps=integ["max_steps"],
              time_limit=integ["cell_time_limit"])
    dt = tor["sample_interval"]
    if tor["analyse"]:    # midpoints of equal intervals: the Birkhoff sums' quadrature
        kw["t_fine"] = (np.arange(int(integ["t_final"] / dt)) + 0.5) * dt
    if task.section:
        kw["max_events"] = task.section["max_crossings"]
    indicators = None
    if ind["which"]:
        indicators = chaos_indicators(system, y0, integ["t_final"], indicator_options(ind),
                                      cell=cell, events=events,
                                      control_tangents=integ["control_tangents"], **kw)
        out, status = indicators.outcome, indicators.status
        errors = indicators.energy_error, indicators.angular_momentum_error
    else:
        history = history_times(integ["t_final"], ind["history_points"])
        out = integrate(system, y0, integ["t_final"], events=events, t_eval=history, **kw)
        status = out.status
        done = ~np.isnan(out.samples[:, 0])
        errors = conservation_errors(system, y0, np.concatenate([out.samples[done], [out.y]]))
    planar3 = system.n_bodies == 3 and system.dim == 2
    evidence = None
    if tor["analyse"] and status.finished:
        evidence = tori.analyse(system, out.fine, dt, errors[0], tor["observables"],
                                tor["lines"], tor["resonance_order"])
    return CellResult(
        status=status, wall_time=time.perf_counter() - clock, n_steps=out.n_steps,
        n_rhs=out.n_rhs, start=y0, t_end=out.t, energy=system.energy(y0),
        angular_momentum=system.angular_momentum(y0), energy_error=errors[0],
        angular_momentum_error=errors[1], indicators=indicators, tori=evidence,
        n_crossings=out.n_crossings,
        crossing_time=out.crossings.t, crossing_state=out.crossings.y,
        reduced=reduced(system, out.crossings.y) if planar3 else None)


# ---------------------------------------------------------------- checkpoints

def checkpoint_dir(config: Config) -> Path:
    out = config.output
    return out.with_name(out.name + ".checkpoints") / config.result_key()


def save_chunk(folder: Path, key: str, cell_ids, result: dict):
    """Write one finished chunk atomically (temporary file, fsync, rename), with the key it
    was computed under, at chunk_path. The folder is made again if it was deleted
    meanwhile."""
    name = chunk_path(folder, cell_ids)
    tmp = folder / f".{name.name}.{os.getpid()}.tmp"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            np.savez(fh, cell_ids=np.asarray(cell_ids, dtype=np.int64), result_key=key,
                     **result)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, name)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise _write_error(exc, name, folder) from None


def chunk_path(folder: Path, cell_ids) -> Path:
    return folder / f"chunk-{int(cell_ids[0]):012d}-{int(cell_ids[-1]):012d}-{len(cell_ids)}.npz"


def _write_error(exc: OSError, path: Path, folder: Path) -> SurveyError:
    kept = f"finished cells are kept in {folder}" if folder.exists() else ""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        try:
            free = shutil.disk_usage(path.parent if path.parent.exists() else folder).free
            room = f" ({free / 2**20:.1f} MiB free)"
        except OSError:
            room = ""
        return SurveyError(f"no space left on the device writing {path}{room}; free some "
                           f"space and run the same command again" + (f": {kept}" if kept else ""))
    return SurveyError(f"cannot write {path} ({exc.strerror or exc}); fix the folder and run "
                       "the same command again" + (f": {kept}" if kept else ""))


def scan_checkpoints(folder: Path, config: Config, starts, key: str) -> dict[Path, np.ndarray]:
    """The usable checkpoint files and their cells. A file that cannot be read, was written
    under another key, holds cells outside the grid or already held, lacks a variable or has
    one of the wrong shape, or whose starts differ from this grid's, is reported and
    deleted: its cells are computed again."""
    slots = archive.layout(config)
    usable, seen = {}, np.zeros(config.n_cells, dtype=bool)
    for path in sorted(folder.glob("chunk-*.npz")):
        try:
            with np.load(path) as z:
                ids = z["cell_ids"]
                problem = _chunk_problem(z, ids, slots, seen, starts, key)
        except Exception as exc:   # zipfile, pickle and numpy raise many kinds
            problem = f"unreadable ({type(exc).__name__}: {str(exc)[:80]})"
        if problem:
            warn(f"checkpoint {path} {problem}; its cells will be computed again")
            with contextlib.suppress(OSError):
                path.unlink()
            continue
        seen[ids] = True
        usable[path] = ids
    return usable


def _chunk_problem(z, ids, slots, seen, starts, key) -> str:
    if str(z["result_key"]) != key:
        return "was written for another config or code version"
    if ids.dtype.kind != "i" or ids.ndim != 1 or not ids.size:
        return "has no valid cell list"
    if ids.min() < 0 or ids.max() >= len(starts) or np.unique(ids).size != ids.size:
        return "names cells outside this grid"
    if seen[ids].any():
        return "repeats cells another checkpoint holds"
    for s in slots:
        if s.name not in z.files:
            return f"lacks variable {s.name}"
        if z[s.name].shape != (ids.size,) + s.shape or z[s.name].dtype != np.dtype(s.dtype):
            return f"has variable {s.name} of the wrong shape or type"
    stored = z["initial_state"]
    if stored.tobytes() != starts[ids].tobytes():
        return "holds starts that differ from this grid's (another grid's results)"
    return ""


def warn(message: str):
    print(f"survey: {message}", file=sys.stderr)


@contextlib.contextmanager
def output_lock(output: Path):
    """Hold the output for this process alone: a second survey writing the same output
    refuses at once. The lock (an flock on .NAME.lock) dies with its process, so a killed
    survey never leaves a stale one; the file is removed on the way out."""
    path = output.with_name(f".{output.name}.lock")
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise SurveyError(f"another survey (process {holder}) is writing {output}; wait "
                              "for it to finish, or choose another [survey].output") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:      # not a file its previous holder unlinked while we waited to open it
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        _remove_stale_temporaries(output)
        yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()
        os.close(fd)


def _remove_stale_temporaries(output: Path):
    """Temporary files of runs that were killed while writing (we hold the lock, so no
    living survey owns them)."""
    stale = list(output.parent.glob(f".{output.name}.partial-*"))
    stale += list(output.with_name(output.name + ".checkpoints").glob("*/.chunk-*.tmp"))
    for f in stale:
        with contextlib.suppress(OSError):
            f.unlink()


# ---------------------------------------------------------------- the cluster

@contextlib.contextmanager
def _client(config: Config, workers, address):
    """A client of the scheduler at `address` (already reached), or of a local cluster."""
    from dask.distributed import Client, LocalCluster
    if address:
        with Client(address, timeout=f"{config.tables['dask']['connect_timeout']}s") as client:
            yield client
        return
    # One numba thread per worker process, and none of the monitoring meant for interactive
    # dashboards (a 10 ms stack profiler and 1 ms GIL polling in every worker, a 20 ms
    # event-loop tick): measured, they cost the workers several percent of two cores. Set
    # in the environment before the workers start, which they inherit.
    quiet = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
             "MKL_NUM_THREADS": "1",
             "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
             "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__GIL__ENABLED": "False",
             "DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL": "500ms",
             "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL": "2s",
             "DASK_DISTRIBUTED__WORKER__MEMORY__MONITOR_INTERVAL": "1s"}
    os.environ.update(quiet)
    import dask
    dask.config.refresh()
    # no dashboard; the scheduler's plain HTTP endpoints on a free loopback port, not 8787
    # (which warns "port 8787 is already in use" whenever another cluster runs)
    with LocalCluster(n_workers=workers or config.tables["dask"]["workers"],
                      threads_per_worker=1, processes=True, dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                      preload=[__name__], silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def dask_setup(worker):
    """Preload of our local workers. A terminal's Ctrl-C reaches every process of its group;
    the driver stops the cluster and says how to resume, so the workers ignore it rather
    than each print a traceback. A worker process leaves without the interpreter's teardown
    of numba and LLVM (registered first, this runs after every other exit handler): the
    cluster's shutdown waits for it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    atexit.register(os._exit, 0)


def _reach(address: str, timeout: float):
    """Ask the address who it is, within `timeout` seconds in all: a port that accepts TCP
    but never speaks dask's protocol (e.g. the dashboard's 8787) would otherwise hang the
    client forever."""
    import asyncio

    from distributed.core import rpc

    async def identity():
        r = rpc(address, timeout=timeout)
        try:
            return await r.identity()
        finally:
            await r.close_rpc()

    fix = ("start one with `dask scheduler` or give its address, e.g. tcp://host:8786 "
           "(8787 is the dashboard, not the scheduler)")
    try:
        info = asyncio.run(asyncio.wait_for(identity(), timeout))
    except (asyncio.TimeoutError, TimeoutError):
        raise ConfigError("[dask].scheduler", f"nothing at {address} answered as a dask "
                                              f"scheduler within {timeout:g} s; {fix}") from None
    except Exception as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError("[dask].scheduler", f"cannot reach a dask scheduler at {address} "
                                              f"({reason}); {fix}") from None
    if not isinstance(info, dict) or info.get("type") != "Scheduler":
        kind = info.get("type") if isinstance(info, dict) else "something else"
        raise ConfigError("[dask].scheduler", f"{address} is a dask {kind}, not a scheduler; "
                                              f"{fix}")


def _chunks(ids: np.ndarray, size: int):
    """Strided chunks of about `size` cells: chunk k holds ids k, k + K, k + 2K, ... Grids
    are ordered by parameter and cost varies smoothly with it (chaotic cells cost more), so
    contiguous chunks would leave the expensive ones for the end and workers idle."""
    count = -(-ids.size // size)
    return [ids[k::count] for k in range(count)]


# ---------------------------------------------------------------- running

def run_survey(source, *, workers: int | None = None, scheduler: str | None = None,
               progress: bool | None = None, command: str = "survey.run_survey",
               timings: dict | None = None) -> Path:
    """Run a survey (config path or dict, or a Config) to its archive; returns the archive
    path. Resumes from checkpoints of an interrupted run of the same config. `timings`, if
    given, receives the seconds spent preparing cells, starting the cluster, computing
    (first task submitted to last result saved), stopping the cluster and writing the
    archive."""
    clock = {"start": time.perf_counter()}
    config = source if isinstance(source, Config) else load_config(source)
    workers, scheduler, progress = _api_arguments(workers, scheduler, progress)
    address = scheduler or config.tables["dask"]["scheduler"]
    if address:       # before any work: a wrong address is an input error
        _reach(address, config.tables["dask"]["connect_timeout"])
    if progress is None:
        progress = sys.stderr.isatty()
    key = config.result_key()
    folder = checkpoint_dir(config)
    task = CellTask.of(config)
    with output_lock(config.output):
        starts = build_starts(config)
        with contextlib.ExitStack() as stack:
            client = bar = done = None
            for round_ in range(4):     # rounds after the first only if checkpoints vanish
                if done is None:
                    done = scan_checkpoints(folder, config, starts, key)
                else:       # checked when found or written here: are they still there?
                    done = {path: ids for path, ids in done.items() if path.exists()}
                have = np.zeros(config.n_cells, dtype=bool)
                for ids in done.values():
                    have[ids] = True
                todo = np.flatnonzero(~have)
                if not todo.size:
                    break
                if round_ == 3:
                    raise SurveyError(f"{todo.size} cells are still missing from {folder} "
                                      "after computing them again (is something deleting "
                                      "checkpoints?); the checkpoints are kept: run the same "
                                      "command again")
                if round_:
                    warn(f"{todo.size} finished cells went missing from {folder}; computing "
                         "them again")
                if client is None:
                    client = _start(stack, config, task, starts, todo, workers, address,
                                    clock)
                    from tqdm import tqdm
                    bar = stack.enter_context(tqdm(total=config.n_cells, unit="cell",
                                                   disable=not progress, desc=config.name,
                                                   smoothing=0.1))
                bar.n = int(have.sum())
                bar.refresh()
                done.update(_compute(client, task, starts, todo, folder, key, config, bar,
                                     round_))
                clock["computed"] = time.perf_counter()
        clock["archive"] = time.perf_counter()
        try:
            path = archive.write(config, _loader(config, done), command)
        except OSError as exc:
            raise _write_error(exc, config.output, folder) from None
        shutil.rmtree(folder, ignore_errors=True)
        with contextlib.suppress(OSError):
            folder.parent.rmdir()
    if timings is not None:
        now = time.perf_counter()
        c = clock
        timings.update(prepare=c.get("prepared", c["archive"]) - c["start"],
                       cluster=c.get("cluster", c["archive"]) - c.get("prepared", c["archive"]),
                       compute=c.get("computed", c["archive"]) - c.get("cluster", c["archive"]),
                       shutdown=c["archive"] - c.get("computed", c["archive"]),
                       archive=now - c["archive"], total=now - c["start"])
    return path


def _api_arguments(workers, scheduler, progress):
    """run_survey's own arguments, checked like config values (numpy integers accepted)."""
    if workers is not None:
        if isinstance(workers, (bool, np.bool_)) or not isinstance(workers, (int, np.integer)) \
                or workers < 1:
            raise ConfigError("workers", f"must be an integer >= 1, got {workers!r}")
        workers = int(workers)
    if scheduler is not None:
        if not isinstance(scheduler, str):
            raise ConfigError("scheduler", f"must be an address string, got {scheduler!r}")
        if scheduler:
            check_address(scheduler)
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ConfigError("progress", f"must be true, false or None, got {progress!r}")
    return workers, scheduler or None, None if progress is None else bool(progress)


def _start(stack, config, task, starts, todo, workers, address, clock):
    """Compile (or load from the disk cache) the kernels once, then start the cluster and
    let every worker load them before the first task."""
    first = todo[~np.isnan(starts[todo, 0])][:1]
    warm_up(task, first, starts[first])
    clock["prepared"] = time.perf_counter()
    client = stack.enter_context(_client(config, workers, address))
    client.run(warm_up, task, first, starts[first])
    clock["cluster"] = time.perf_counter()
    return client


def warm_up(task: CellTask, first, starts):
    """Load every compiled kernel a cell uses from numba's disk cache."""
    if first.size:
        run_cells(task.short(), first, starts)


def _compute(client, task, starts, todo, folder, key, config, bar, round_):
    from dask.distributed import as_completed
    size = config.tables["dask"]["chunk_size"] or min(
        256, max(1, -(-todo.size // (64 * len(client.scheduler_info()["workers"])))))
    futures = {client.submit(run_cells, task, ids, starts[ids], pure=False,
                             key=f"cells-{key}-{round_}-{int(ids[0])}",
                             retries=config.tables["dask"]["retries"]): ids
               for ids in _chunks(todo, size)}
    saved = {}
    for future in as_completed(futures):
        ids = futures.pop(future)
        save_chunk(folder, key, ids, future.result())
        saved[chunk_path(folder, ids)] = ids
        future.release()
        bar.update(len(ids))
    return saved


def _loader(config: Config, files: dict[Path, np.ndarray]):
    """Reads variables over all cells from the checked checkpoint files, opening each file
    once per call."""
    specs = {v.name: v for v in archive.variables(config)}

    def load(names):
        out = {name: np.full((config.n_cells,) + archive.cell_shape(config, specs[name]),
                             specs[name].fill, specs[name].dtype) for name in names}
        for path, ids in files.items():
            with np.load(path) as z:
                for name in names:
                    out[name][ids] = z[name]
        return out
    return load


def run(source, **kw):
    """Python API: run a survey and return its archive as an xarray Dataset."""
    import xarray as xr
    return xr.open_dataset(run_survey(source, **kw))


# ---------------------------------------------------------------- verification

def verify(path, cells: int = 8, seed: int = 0, differences: dict | None = None):
    """Check an archive against its stored config -- the config's sha256, the grid
    coordinates, the variables, their dimensions and attributes -- then recompute a sample
    of cells and compare every variable the schema declares reproducible, bit for bit.
    Returns (ok, report lines), each mismatch with its largest difference relative to the
    value (rounding on another machine shows as ~1e-16, a real change as much more);
    `differences`, if given, receives those per variable. A file that is not a survey
    archive raises ArchiveError."""
    from .config import parse_config
    with archive.open_archive(path) as ds:
        try:
            config = parse_config(ds.attrs["config"], f"{path} (stored config)",
                                  check_output=False)
        except ConfigError as exc:
            return False, [f"the stored config is not valid: {exc}"]
        found = archive.problems(ds, config)
        if found:
            return False, ["the archive does not match its stored config:"] + \
                [f"  {p}" for p in found]
        n = config.n_cells
        others = np.random.default_rng(seed).permutation(np.arange(1, n - 1))[:max(cells - 2, 0)]
        sample = np.unique(np.concatenate([[0, n - 1], others]))   # first, last, random
        try:
            stored = {v.name: ds[v.name].values.reshape((n,) + ds[v.name].shape[len(config.shape):])
                      for v in archive.variables(config) if v.reproducible and not v.derived}
            derived = archive.derive(ds)
            rederived = [v.name for v in archive.variables(config) if v.derived and
                         np.asarray(derived[v.name], dtype=v.dtype).tobytes()
                         != ds[v.name].values.astype(v.dtype).tobytes()]
        except (OSError, RuntimeError, ValueError) as exc:
            raise archive.ArchiveError(f"{path}: its data cannot be read ({exc}); the file "
                                       "may be truncated") from None
    timed_out = stored["status"][sample] == Status.TIME_LIMIT
    sample = sample[~timed_out]
    fresh = run_cells(CellTask.of(config), sample, build_starts(config)[sample])
    lines, ok = [], True
    for name, values in stored.items():
        a, b = values[sample], fresh[name].astype(values.dtype)
        if a.tobytes() != b.tobytes():
            ok = False
            worst = _relative_difference(a, b)
            if differences is not None:
                differences[name] = worst
            lines.append(f"{name}: differs in {np.sum(~_equal(a, b))} of {len(sample)} cells; "
                         f"largest difference {worst:.1e} of the value")
    for name in rederived:
        ok = False
        lines.append(f"{name}: differs from what its evidence in the archive gives "
                     "(tori.classify)")
    lines.insert(0, f"recomputed cells {', '.join(map(str, sample))} of {n}: "
                    + ("all reproducible variables match bit for bit" if ok else "MISMATCH"))
    if timed_out.any():
        lines.append(f"skipped {timed_out.sum()} sampled cells that hit cell_time_limit (not "
                     "reproducible)")
    return ok, lines


def _relative_difference(a, b) -> float:
    """max |a - b| / max(|a|, |b|) over the elements that differ (inf where only one is
    NaN); integers by their absolute difference."""
    if a.dtype.kind != "f":
        return float(np.max(np.abs(a.astype(np.int64) - b.astype(np.int64))))
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    if np.any(nan_a != nan_b):
        return np.inf
    both = ~nan_a & (a != b)
    if not both.any():
        return 0.0
    return float(np.max(np.abs(a[both] - b[both]) / np.maximum(np.abs(a[both]),
                                                                np.abs(b[both]))))


def _equal(a, b):
    eq = (a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b
    return eq.reshape(len(a), -1).all(axis=1)
