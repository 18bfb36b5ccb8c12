"""Grid -> chunks -> dask -> checkpointed results -> archive, and `verify`.

The archive is written only when every cell is present; an interrupted survey started again
computes only the missing cells. `verify` recomputes a sample of an archive's cells from its
stored config and compares them bit for bit.
"""
from __future__ import annotations

import atexit
import contextlib
import errno
import logging
import multiprocessing
import os
import shutil
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ..catalog.errors import ArchiveError, ConfigError, SurveyError
from ..catalog.status import Status
from ..catalog.variables import BY_NAME, V
from . import archive
from ..analysis.refine import known_from, plan
from ..machine.jit import kernels_cached
from ..physics.lanes import SIMD_LANES
from .cells import (
    CellTask,
    GridStarts,
    build_starts,
    classify_rows,
    compiled_beside,
    extend_cells,
    first_runs,
    head_start,
    jobs_per_cell,
    merge_rows,
    run_cells,
    warm_beside,
    warm_up,
)
from .checkpoints import (
    CheckpointVanished,
    checkpoint_dir,
    chunk_path,
    loader,
    output_lock,
    save_chunk,
    scan_checkpoints,
    warn,
    write_error,
)
from .config import Config, load_config, parse_config
from .progress import COMPILING, FIRST_COMPILE, notice
from .resources import check_address
from .special import report_attributes


@contextlib.contextmanager
def _client(config: Config, workers, address):
    """A client of the scheduler at `address` (already reached), or of a local cluster; a
    Ctrl-C while it lives interrupts quietly (`_quiet_interrupt`)."""
    with _quiet_interrupt():
        from dask.distributed import Client, LocalCluster
        if address:
            with Client(address, timeout=f"{config.settings.dask.connect_timeout}s") as client:
                try:
                    client.wait_for_workers(1, timeout=config.settings.dask.connect_timeout)
                except TimeoutError:
                    raise SurveyError(
                        f"the dask scheduler at {address} has no workers after "
                        f"{config.settings.dask.connect_timeout:g} s: start some "
                        f"(`dask worker {address}`) or raise [dask] connect_timeout") from None
                yield client
            return
        # One numba thread per worker process, and none of the monitoring meant for interactive
        # dashboards (a stack profiler and GIL polling in every worker, a fast event-loop
        # tick): they cost the workers several percent of two cores. Set
        # in the environment before the workers start, which they inherit.
        quiet = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                 "MKL_NUM_THREADS": "1",
                 "DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED": "False",
                 "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__GIL__ENABLED": "False",
                 "DASK_DISTRIBUTED__ADMIN__TICK__INTERVAL": "500ms",
                 "DASK_DISTRIBUTED__ADMIN__SYSTEM_MONITOR__INTERVAL": "2s",
                 "DASK_DISTRIBUTED__WORKER__MEMORY__MONITOR_INTERVAL": "1s"}
        # The first workers are forked from this process, with its modules imported and its
        # kernels loaded (warm_up ran here first; on a first run they are forked before it
        # and load them from the disk cache, see _start): the cluster starts in a third of
        # the time spawned workers spend importing numpy, numba, dask and survey again.
        # Forked while this process only waits for them; a worker restarted later (one that
        # died) is spawned, as this process then runs threads whose locks a fork would copy
        # held.
        fork = "fork" in multiprocessing.get_all_start_methods()
        quiet["DASK_DISTRIBUTED__WORKER__MULTIPROCESSING_METHOD"] = "fork" if fork else "spawn"
        os.environ.update(quiet)
        import dask
        dask.config.refresh()
        # no dashboard; the scheduler's plain HTTP endpoints on a free loopback port, not 8787
        # (which warns "port 8787 is already in use" whenever another cluster runs)
        with LocalCluster(n_workers=workers or config.settings.dask.workers,
                          threads_per_worker=1, processes=True, dashboard_address=None,
                          scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                          preload=[__name__], silence_logs=logging.ERROR) as cluster:
            dask.config.set({"distributed.worker.multiprocessing-method": "spawn"})
            with Client(cluster) as client:
                # the cluster returns once its worker processes run, not once each has
                # registered with the scheduler: asked then, the scheduler knew none (a
                # refinement's chunk size divided by zero, once in `reproduce`)
                client.wait_for_workers(len(cluster.workers), timeout=120)
                yield client


@contextlib.contextmanager
def _quiet_interrupt():
    """A Ctrl-C silences dask's and tornado's logs before it interrupts. Shut down mid-task,
    they log the cancelled work as errors, and distributed's `sync` (2026.8) schedules a
    cancel on its loop thread that fails with a NameError traceback when the interrupt
    lands before its future exists -- at once, on that thread, so silencing them in an
    `except` here came too late at times (a CI run). The user asked for the stop; the
    command line says how to resume. A SIGINT ignored (a background job) stays ignored;
    off the main thread no handler can be set, and the `except` is all there is."""
    def silence():      # their loggers below the top carry levels of their own
        for name in list(logging.root.manager.loggerDict):
            if name.split(".")[0] in ("distributed", "tornado"):
                logging.getLogger(name).setLevel(logging.CRITICAL + 1)

    def interrupt(signum, frame):
        silence()
        raise KeyboardInterrupt

    own = (threading.current_thread() is threading.main_thread()
           and signal.getsignal(signal.SIGINT) is signal.default_int_handler)
    if own:
        signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    except KeyboardInterrupt:
        silence()
        raise
    finally:
        if own:
            signal.signal(signal.SIGINT, signal.default_int_handler)


def dask_setup(worker):
    """Preload of our local workers. A terminal's Ctrl-C reaches every process of its group;
    the driver stops the cluster and says how to resume, so the workers ignore it rather
    than each print a traceback -- also the one a worker's heartbeat logs when the
    scheduler (in the driver) is gone before the worker is stopped (a loaded machine, a
    test run). A worker process leaves without the interpreter's teardown of numba and
    LLVM (registered first, this runs after every other exit handler): the cluster's
    shutdown waits for it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(_scheduler_gone)
    atexit.register(os._exit, 0)


def _scheduler_gone(record: logging.LogRecord) -> bool:
    """False for a worker's heartbeat that found the scheduler gone: a local cluster's
    scheduler goes only when the driver stops it. Other worker errors pass."""
    return not record.getMessage().startswith("Failed to communicate with scheduler during "
                                              "heartbeat")


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


def _chunks(ids: np.ndarray, count: int):
    """`count` strided chunks, alike in size to a cell: chunk k holds ids k, k + count,
    k + 2 count, ... Grids are ordered by parameter and cost varies smoothly with it
    (chaotic cells cost more), so contiguous chunks would leave the expensive ones for the
    end and workers idle."""
    return [ids[k::count] for k in range(min(count, ids.size))]


def _task_count(config: Config, cells: int, counted: int) -> int:
    """Tasks for `cells`: `counted` unless [dask] chunk_size fixes the cells per task."""
    size = config.settings.dask.chunk_size
    return -(-cells // size) if size else counted


def run_survey(source, *, workers: int | None = None, scheduler: str | None = None,
               progress: bool | None = None, command: str = "survey.run_survey",
               timings: dict | None = None, imports: tuple[str, ...] = ()) -> Path:
    """Run a survey (config path or dict, or a Config) to its archive; returns the archive
    path. Resumes from checkpoints of an interrupted run of the same config. `timings`, if
    given, receives the seconds spent preparing cells, starting the cluster, computing
    (first task submitted to last result saved), stopping the cluster and writing the
    archive. `imports`: modules the caller needs after the survey (a report's), imported
    while the workers compute (`archive.prefetch`)."""
    clock = {"start": time.perf_counter(), "stream": timings is not None}
    workers, scheduler, progress = _api_arguments(workers, scheduler, progress)
    config = source if isinstance(source, Config) else load_config(source)
    address = scheduler or config.settings.dask.scheduler
    if address:       # before any work: a wrong address is an input error
        _reach(address, config.settings.dask.connect_timeout)
    if progress is None:
        progress = sys.stderr.isatty()
    key = config.result_key()
    folder = checkpoint_dir(config)
    with output_lock(config.output):
        for attempt in range(3):    # again when a checkpoint vanishes before it is read
            if config.refined:
                done, cells = _refined(config, key, folder, workers, address, clock,
                                       progress, imports)
                load = loader(config.fine(), done, cells)
            else:
                done, cells = _grid(config, key, folder, workers, address, clock,
                                    progress, imports), None
                load = loader(config, done)
            clock["archive"] = time.perf_counter()
            try:
                path = _write(config, load, command, cells, folder, progress)
                break
            except CheckpointVanished as exc:
                if attempt == 2:
                    raise SurveyError(f"checkpoints keep vanishing from {folder} before "
                                      "the archive reads them (is something deleting "
                                      "them?); run the same command again") from None
                warn(f"{exc.args[0].name} went missing from {folder} before the archive "
                     "read it; computing its cells again")
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
                       archive=now - c["archive"], total=now - c["start"],
                       tasks=c.get("tasks", []))
    return path


def _write(config, load, command, cells, folder, progress) -> Path:
    """The archive from the checkpoints `load` reads; a failed write is a SurveyError that
    says what to do."""
    try:
        def annotate(ds):
            with notice("solving the special solutions the cells start on, for the report",
                        progress):
                return report_attributes(ds)
        with notice(f"writing {config.output}", progress):
            return archive.write(config, load, command, cells, annotate=annotate)
    except OSError as exc:
        raise write_error(exc, config.output, folder) from None
    except RuntimeError as exc:     # netCDF4 reports a full disk as an HDF error
        raise write_error(OSError(errno.EIO, f"{exc}; is the disk full?"), config.output,
                          folder) from None


def _grid(config, key, folder, workers, address, clock, progress, imports) -> dict:
    """Every cell of the grid, from checkpoints where they are, computed where not:
    the checkpoint files and their cells."""
    task, starts = CellTask.of(config), GridStarts(config)
    with notice("checking the starts at the grid's corners", progress):
        starts.check_corners()
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
                client = _start(stack, config, task, starts.first(todo), starts, workers,
                                address, clock, progress, imports)
                from tqdm import tqdm
                bar = stack.enter_context(tqdm(total=config.n_cells, unit="cell",
                                               disable=not progress, desc=config.name,
                                               smoothing=0.1))
            bar.n = int(have.sum())
            bar.refresh()
            done.update(_compute(client, task, starts, todo, folder, key, config, bar,
                                 round_))
            _computed(client, clock)
    return done


def _refined(config, key, folder, workers, address, clock, progress, imports):
    """The cells of a refined survey (analysis.refine): the grid, then, as each chunk's
    results come in, the cells their disagreements call for, submitted at once (no level
    waits for the whole of the one before); from checkpoints where they are. Returns the
    checkpoint files with their cells, and the survey's cells (sorted lattice ids). The
    cells are a function of the results alone, so any worker count, chunking or
    interruption gives the same survey."""
    from dask.distributed import as_completed
    from tqdm import tqdm
    fine, lattice, rule = config.fine(), config.lattice(), config.rule()
    task, system = CellTask.of(fine), config.system()
    cache: dict[int, np.ndarray] = {}

    def starts(ids):
        missing = [int(i) for i in ids if int(i) not in cache]
        for i, row in zip(missing, build_starts(fine, missing) if missing else ()):
            cache[i] = row
        return np.array([cache[int(i)] for i in ids]).reshape(len(ids), -1)

    known: dict[int, tuple[int, float]] = {}

    def learn(ids, result):
        regime, _ = classify_rows(task, system, result)
        known.update(known_from(ids, regime, result[rule.indicator] if rule.indicator
                                else np.full(len(ids), np.nan)))

    done = scan_checkpoints(folder, fine, starts, key)
    for path, ids in done.items():
        with np.load(path) as z:
            learn(ids, {name: z[name] for name in z.files if name not in ("cell_ids",
                                                                         "result_key")})
    with contextlib.ExitStack() as stack:
        client = bar = None
        flight: dict = {}
        queue = None
        for _ in range(4):          # again only if checkpoints vanish
            while True:
                p = plan(lattice, rule, known)
                busy = {int(i) for ids in flight.values() for i in ids}
                todo = np.array([i for i in p.needed.tolist() if i not in busy], dtype=np.int64)
                if todo.size:
                    if client is None:
                        first = starts(todo)
                        pick = todo[~np.isnan(first[:, 0])][:1]
                        client = _start(stack, config, task, pick, starts, workers, address,
                                        clock, progress, imports)
                        bar = stack.enter_context(tqdm(unit="cell", disable=not progress,
                                                       desc=config.name, smoothing=0.1))
                        queue = as_completed()
                    count = _task_count(config, todo.size, refined_chunk_count(
                        todo.size, len(client.scheduler_info()["workers"]),
                        jobs_per_cell(task)))
                    for ids in _chunks(todo, count):
                        future = client.submit(run_cells, task, ids, starts(ids), pure=False,
                                               key=f"cells-{key}-{ids[0]}-{ids[-1]}-{ids.size}",
                                               retries=config.settings.dask.retries)
                        flight[future] = ids
                        queue.add(future)
                if bar is not None:     # the cells and levels decided so far
                    bar.total = len(p.cells)
                    bar.n = sum(1 for c in p.cells.tolist() if c in known)
                    bar.set_postfix_str(f"refinement level {int(lattice.level(p.cells).max(initial=0))}"
                                        f" of {config.settings.refine.max_level}",
                                        refresh=True)
                if not flight:
                    break
                future = next(queue)
                ids = flight.pop(future)
                result = future.result()
                save_chunk(folder, key, ids, result)
                done[chunk_path(folder, ids)] = ids
                future.release()
                learn(ids, result)
            if not p.done:
                raise SurveyError("refinement stopped with undecided cells (a bug: please "
                                  "report it with the config)")
            gone = [path for path in done if not path.exists()]
            if not gone:
                break
            warn(f"{len(gone)} checkpoint files went missing from {folder}; computing their "
                 "cells again")
            for path in gone:
                for i in done.pop(path).tolist():
                    known.pop(int(i), None)
        else:
            raise SurveyError(f"checkpoints keep going missing from {folder} (is something "
                              "deleting them?); run the same command again")
        if client is not None:
            _computed(client, clock)
    return done, p.cells


def _computed(client, clock):
    """The compute phase ends: its time, and (timings asked for) when each task ran on
    which worker, from the scheduler's task stream."""
    clock["computed"] = time.perf_counter()
    if clock["stream"]:
        clock["tasks"] = [(r["worker"], ss["start"], ss["stop"])
                          for r in client.get_task_stream() for ss in r["startstops"]
                          if ss["action"] == "compute"]


def _api_arguments(workers, scheduler, progress):
    """run_survey's own arguments, checked like config values (numpy integers accepted)."""
    if workers is not None:
        if isinstance(workers, (bool, np.bool_)) or not isinstance(workers, (int, np.integer)) \
                or workers < 1:
            raise ConfigError("workers", f"must be an integer >= 1, got {workers!r}")
        workers, cores = int(workers), os.cpu_count() or 1
        if workers > 4 * cores:
            raise ConfigError("workers", f"{workers} local worker processes on a machine with "
                              f"{cores} cores would only queue and use memory; use at most "
                              f"{4 * cores}, or a dask scheduler for a cluster")
    if scheduler is not None:
        if not isinstance(scheduler, str):
            raise ConfigError("scheduler", f"must be an address string, got {scheduler!r}")
        if scheduler:
            check_address(scheduler)
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise ConfigError("progress", f"must be true, false or None, got {progress!r}")
    return workers, scheduler or None, None if progress is None else bool(progress)


def _start(stack, config, task, first, starts, workers, address, clock, progress, imports):
    """Compile (or load from the disk cache) the kernels once, then start the cluster and
    let every worker load them before the first task (`first`: a cell with a start, if any;
    starts: a function giving given cells' starts); then, in a thread of this process while
    the workers compute, import what the archive and the caller (`imports`) need after
    them: before, they added to a scan whose tasks all end together (`bench --only scan`
    times the command line) and to a first run's report."""
    at = starts(first)
    cluster = f"connecting to the dask scheduler at {address}" if address else \
        f"starting {workers or config.settings.dask.workers} local dask workers"
    # A first run: the local workers start first (forked without the kernels, which they
    # then load from the disk cache), so that one compiles the integrator's stepping round
    # and everything the survey needs after the integrator (warm_beside) while this process
    # compiles the integrator -- else the second core idles for that half minute (`bench
    # --only fixed` times a first run). Otherwise they are forked after warm_up, with the
    # kernels loaded.
    beside = None
    if not address and not kernels_cached():
        with notice(cluster, progress):
            client = stack.enter_context(_client(config, workers, address))
        beside = client.submit(head_start, warm_beside, task, first, at, pure=False)
    with notice(COMPILING, progress, compiling=True):
        warm_up(task, first, at)
        if beside is not None:
            beside.result()
    clock["prepared"] = time.perf_counter()
    with notice(cluster if beside is None else "loading the kernels in the workers",
                progress):
        if beside is None:
            client = stack.enter_context(_client(config, workers, address))
        client.run(warm_up, task, first, at)
        if clock["stream"]:
            client.get_task_stream()        # records from here on
    clock["cluster"] = time.perf_counter()
    # what this thread imports while the prefetch runs, imported first (archive.prefetch):
    # the bar, and numpy's serialisation, which dask's IO thread loads at the first result
    import distributed.protocol.numpy  # noqa: F401
    import tqdm  # noqa: F401
    archive.prefetch(imports)
    return client


def chunk_count(cells: int, workers: int, per_cell: int) -> int:
    """Tasks for `cells` (strided chunks, _chunks): each of orbits for four rounds of SIMD
    lanes (4 SIMD_LANES: 64 in 256-bit vectors, 128 in 512-bit ones, where 64 cost a
    401-orbit scan 15% more), so that a lane whose orbit ends takes another, where the grid
    allows every worker a task, else what gives every worker one; on large grids about 64
    tasks per worker (a finer spread of cheap and costly cells), at most 256 cells each.
    Fewer than 8 tasks a worker come in a multiple of the workers (for every lane width:
    the count is rounded, not the size), alike in size: a last wave of fewer tasks than
    workers leaves the others idle (300 cells of one orbit in 128-orbit tasks: 3 on 2
    workers)."""
    lanes, workers = -(-4 * SIMD_LANES // per_cell), max(1, workers)  # (all may be restarting)
    size = max(1, min(256, max(lanes, -(-cells // (64 * workers))), -(-cells // workers)))
    tasks = -(-cells // size)
    if tasks < 8 * workers:
        tasks = -(-tasks // workers) * workers
        if tasks > cells:
            tasks = cells // workers * workers or cells
    return tasks


def refined_chunk_count(cells: int, workers: int, per_cell: int) -> int:
    """Tasks of a refinement's batch: about four a worker -- a cell's children are
    submitted as soon as its task returns, so smaller tasks keep the workers busy across
    levels -- but not fewer orbits a task than one round of SIMD lanes (SIMD_LANES) where
    the batch has them, and at least one task per worker."""
    lanes, workers = -(-SIMD_LANES // per_cell), max(1, workers)
    size = max(1, min(-(-cells // chunk_count(cells, workers, per_cell)),
                      max(lanes, -(-cells // (4 * workers))), -(-cells // workers)))
    # no more tasks than rounds of lanes the batch fills, but one per worker it can feed
    return max(min(workers, cells), min(-(-cells // size), cells * per_cell // SIMD_LANES))


def deal_doubts(held, group, threads, workers, chunks_out, idle, free):
    """The tasks to submit now for the cells in doubt `held` ((cost, chunk, row): the first
    run's right-hand sides), as ([(chunk, row), ...], worker or None), and the cells to hold
    back. Cells are dealt costliest first, so that a task's cells end alike, in tasks of
    about `group` cells (a round of SIMD lanes). While chunks wait (`chunks_out` > threads):
    nothing until a round of lanes' worth is held or 2 chunks a worker wait for theirs (a
    chunk is checkpointed once all its cells are final), then all, ahead of the chunks. At
    the end: one task to each free worker (`free()`), with a share kept for each worker
    still running a chunk (whose cells in doubt join the rest when it returns); once
    nothing runs (`idle`), all, a share for each thread."""
    held = sorted(held, reverse=True)
    n = -(-len(held) // group)

    def dealt(n, workers):
        shares = [[(c, k) for _, c, k in held[g::n]] for g in range(n)]
        return [(cells, w) for w, cells in zip(workers, shares) if cells]

    if idle:
        n = min(len(held), max(n, threads))
        return dealt(n, [None] * n), []
    if chunks_out > threads:
        if len(held) >= group or len({c for _, c, _ in held}) >= 2 * workers:
            return dealt(n, [None] * n), []
        return [], held
    free = free()
    n = max(n, len(free) + chunks_out)
    return dealt(n, free), [cell for g in range(len(free), n) for cell in held[g::n]]


def _compute(client, task, starts, todo, folder, key, config, bar, round_):
    """The cells `todo` in chunks, one task each (first_runs); a chunk's cells whose
    verdict is in doubt then run longer (extend_cells), several to a task, their orbits
    lanes of one batch (one cell's orbits leave most of a batch's lanes idle), as
    `deal_doubts` deals them: at the end each task to a worker with nothing to do (the
    scheduler would queue two on the worker that just finished, while another finishes
    soon after and idles). A chunk is saved when all its cells are final."""
    from dask.distributed import as_completed
    slots = {w: info["nthreads"] for w, info in client.scheduler_info()["workers"].items()}
    per_cell = jobs_per_cell(task)
    count = _task_count(config, todo.size, chunk_count(todo.size, len(slots), per_cell))
    # an extension task holds about one round of SIMD lanes
    group = max(1, -(-SIMD_LANES // per_cell))
    retries = config.settings.dask.retries
    # a chunk by its first cell: its ids, result rows, extensions pending
    chunks = {int(ids[0]): [ids, None, 0] for ids in _chunks(todo, count)}
    # a task's future: the first cell of its chunk, or the (chunk, row) of its extensions
    futures = {client.submit(first_runs, task, ids, starts, pure=False,
                             key=f"cells-{key}-{round_}-{first}",
                             retries=retries): first
               for first, (ids, _, _) in chunks.items()}
    queue = as_completed(futures)

    def extend(cells, worker=None):
        ids = np.array([chunks[first][0][k] for first, k in cells])
        rows = [(chunks[first][1], slice(k, k + 1)) for first, k in cells]
        history = np.concatenate([res[V.regime_history][k] for res, k in rows])
        begun = np.concatenate([res[V.initial_state][k] for res, k in rows])
        extension = client.submit(extend_cells, task, ids, begun, history,
                                  pure=False, priority=1, retries=retries,
                                  workers=worker, allow_other_workers=worker is not None,
                                  key=f"longer-{key}-{round_}-{int(ids[0])}")
        futures[extension] = cells
        queue.add(extension)

    def free():
        """A worker for each of its threads with nothing to do."""
        busy = client.processing()
        return [w for w in slots for _ in range(slots[w] - len(busy.get(w, ())))]

    saved, held = {}, []        # held: (the first run's right-hand sides, chunk, row)
    for future in queue:
        job = futures.pop(future)
        if isinstance(job, int):        # first_runs: (rows, rows in doubt)
            chunk = chunks[job]
            chunk[1], doubt = future.result()
            chunk[2] = doubt.size
            held += [(int(chunk[1][V.n_rhs][k]), job, int(k)) for k in doubt]
            ended = [job]
        else:
            rows = future.result()
            for i, (first, k) in enumerate(job):
                merge_rows(chunks[first][1], np.array([k]),
                           {name: values[i:i + 1] for name, values in rows.items()})
                chunks[first][2] -= 1
            ended = sorted({first for first, _ in job})
        future.release()
        for first in ended:
            if chunks[first][2] == 0:
                ids, rows, _ = chunks.pop(first)
                save_chunk(folder, key, ids, rows)
                saved[chunk_path(folder, ids)] = ids
                bar.update(len(ids))
        if held:
            chunks_out = sum(isinstance(j, int) for j in futures.values())
            tasks, held = deal_doubts(held, group, sum(slots.values()), len(slots),
                                      chunks_out, not futures, free)
            for cells, worker in tasks:
                extend(cells, worker=None if worker is None else [worker])
    return saved


def run(source, **kw):
    """Python API: run a survey and return its archive as an xarray Dataset."""
    import xarray as xr
    return xr.open_dataset(run_survey(source, **kw))


def verify(path, cells: int = 8, seed: int = 0, differences: dict | None = None):
    """Check an archive against its stored config -- the config's sha256, the grid
    coordinates, the variables, their dimensions and attributes -- then recompute a sample
    of cells and compare every variable the schema declares reproducible, bit for bit: on
    any x86-64 machine the cells compute the same bits (survey.machine.portable). Returns
    (ok, report lines), each mismatch with its largest difference relative to the value;
    `differences`, if given, receives those per variable. A file that is not a survey
    archive raises ArchiveError."""
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
        made_on = ds.attrs.get("machine", "an unrecorded machine")
        grid = config.fine() if config.refined else config
        ids = ds["cell"].values.astype(np.int64) if config.refined else np.arange(config.n_cells)
        n, ndim = ids.size, len(archive.grid_dims(config))
        others = np.random.default_rng(seed).permutation(np.arange(1, n - 1))[:max(cells - 2, 0)]
        sample = np.unique(np.concatenate([[0, n - 1], others]))   # first, last, random
        try:
            stored = {v.name: ds[v.name].values.reshape((n,) + ds[v.name].shape[ndim:])
                      for v in archive.variables(config) if v.reproducible and not v.derived}
            derived = archive.derive(ds)
            rederived = [v.name for v in archive.variables(config) if v.derived and
                         np.asarray(derived[v.name], dtype=v.dtype).tobytes()
                         != ds[v.name].values.astype(v.dtype).tobytes()]
            unrefined = _refinement_problem(ds, config, ids) if config.refined else ""
        except (OSError, RuntimeError, ValueError) as exc:
            raise ArchiveError(f"{path}: its data cannot be read ({exc}); the file "
                                       "may be truncated") from None
    timed_out = stored[V.status][sample] == Status.TIME_LIMIT
    sample = sample[~timed_out]
    with notice(f"recomputing {len(sample)} cells (compiling the kernels if this kind of "
                f"system has not run here before: {FIRST_COMPILE})", sys.stderr.isatty()):
        task, starts = CellTask.of(grid), build_starts(grid, ids[sample])
        begins = np.flatnonzero(~np.isnan(starts[:, 0]))[:1]     # a cell with a start
        with compiled_beside(warm_beside, task, ids[sample][begins], starts[begins], False):
            fresh = run_cells(task, ids[sample], starts)
    here = archive.machine()
    lines = compare({k: v[sample] for k, v in stored.items()}, fresh, differences)
    ok = not lines
    for name in rederived:
        ok = False
        lines.append(f"{name}: differs from what its evidence in the archive gives "
                     "(survey.analysis.classify)")
    if unrefined:
        ok = False
        lines.append(unrefined)
    verdict = "all reproducible variables match bit for bit" if ok else "MISMATCH"
    which = " (by their lattice index)" if config.refined else ""
    lines.insert(0, f"recomputed cells {', '.join(map(str, ids[sample]))}{which} of {n}: "
                    f"{verdict}")
    if made_on != here:
        lines.append(f"the archive was made on {made_on}; this is {here}")
    if timed_out.any():
        lines.append(f"skipped {timed_out.sum()} sampled cells that hit cell_time_limit (not "
                     "reproducible)")
    return ok, lines


def _refinement_problem(ds, config, ids) -> str:
    """Why a refined archive's cells are not the refinement its own regimes call for
    (analysis.refine.plan under its stored config), or ""."""
    rule = config.rule()
    p = plan(config.lattice(), rule, known_from(
        ids, ds[V.regime].values, ds[rule.indicator].values if rule.indicator
        else np.full(ids.size, np.nan)))
    if p.done and np.array_equal(p.cells, ids):
        return ""
    extra = np.setdiff1d(ids, p.cells).size
    missing = np.setdiff1d(p.cells, ids).size
    return (f"cell: not the refinement its regimes call for ({missing} cells missing, "
            f"{extra} not called for)")


# what a report reads beside the cells: the resolved config, special.report_attributes
REPORT_ATTRIBUTES = ("config_resolved", "special_cells", "section_slice")


def same_results(old, new) -> list[str]:
    """How archive `new` differs from archive `old` beyond provenance (when and where it was
    made, the code's commit, the run times): the config, the coordinates and every
    reproducible variable, bit for bit. Empty if they agree."""
    with archive.open_archive(old) as a, archive.open_archive(new) as b:
        if a.attrs["config"] != b.attrs["config"]:
            return ["the config differs"]
        lines = [f"the {k} attribute differs" for k in REPORT_ATTRIBUTES
                 if a.attrs.get(k) != b.attrs.get(k)]
        if set(a.variables) != set(b.variables):
            return lines + ["the variables differ: " + ", ".join(sorted(set(a.variables)
                                                                        ^ set(b.variables)))]
        names = [k for k in a.variables if k not in BY_NAME or BY_NAME[k].reproducible]
        stored = {k: a[k].values for k in names}
        fresh = {k: b[k].values for k in names}
        return lines + compare(stored, fresh)


def compare(stored: dict, fresh: dict, differences: dict | None = None) -> list[str]:
    """Compare two sets of a survey's variables over the same cells, bit for bit: a line
    naming each variable that differs, with its largest difference relative to the value
    (also into `differences`, if given)."""
    lines = []
    for name, values in stored.items():
        a, b = values, fresh[name].astype(values.dtype)
        if a.tobytes() == b.tobytes():
            continue
        worst = _relative_difference(a, b) if a.shape == b.shape else np.inf
        if differences is not None:
            differences[name] = worst
        lines.append(f"{name}: differs in {np.sum(~_equal(a, b)) if a.shape == b.shape else 'all'}"
                     f" of {len(a)} cells; largest difference {worst:.1e} of the value")
    return lines


def _relative_difference(a, b) -> float:
    """max |a - b| / max(|a|, |b|) over the elements that differ (inf where only one is
    NaN); integers by their absolute difference."""
    if a.dtype.kind in "iub":
        return float(np.max(np.abs(a.astype(np.int64) - b.astype(np.int64))))
    if a.dtype.kind != "f":
        return np.inf
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
