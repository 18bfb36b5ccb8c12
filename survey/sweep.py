"""Grid -> cells -> chunks -> dask -> checkpointed results -> archive.

A cell's result depends only on the config and its own index (deviation vectors are seeded
by (seed, cell index)), never on the chunk it travels in or the worker that runs it, so an
archive is the same bit for bit whatever the chunk size or worker count. Finished chunks are
written to checkpoint files as they arrive (atomically); a survey started again with the
same config computes only the missing cells. Checkpoints live under a key that hashes the
result-determining config and survey's own code, so a changed config never reuses them.
"""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from . import archive
from .config import Config, ConfigError, load_config, section_event_for
from .coordinates import reduced
from .families import Inaccessible, initial_state
from .indicators import chaos_indicators, conservation_errors
from .integrator import Status, integrate


def build_starts(config: Config) -> np.ndarray:
    """Initial states of every cell (n_cells, n), NaN rows where inaccessible. A value that
    makes no start at all (a degenerate triangle) is a ConfigError naming the cell."""
    system = config.system()
    family = config.tables["initial"]["family"]
    starts = np.full((config.n_cells, system.n), np.nan)
    for index in range(config.n_cells):
        params = config.cell_parameters(index)
        try:
            starts[index] = initial_state(system, family, **params)
        except Inaccessible:
            continue
        except ValueError as exc:
            at = ", ".join(f"{a.name} = {params[a.name]:g}" for a in config.axes)
            raise ConfigError("[initial]" + (f" at {at}" if at else ""), str(exc)) from None
    return starts


# ---------------------------------------------------------------- the task

def run_cells(config: Config, cell_ids, starts) -> dict[str, np.ndarray]:
    """Integrate a chunk of cells (the unit of work a dask task does)."""
    system = config.system()
    integ = config.tables["integration"]
    sec = config.tables["section"]
    events = [section_event_for(config.tables, system)] if config.tables["section_enabled"] \
        else []
    which = set(config.tables["indicators"]["which"])
    options = config.indicator_options()
    res = archive.empty_results(config, len(cell_ids))
    kw = dict(rtol=integ["rtol"], atol=integ["atol"], max_steps=integ["max_steps"],
              max_events=sec["max_crossings"], time_limit=integ["cell_time_limit"],
              control_tangents=integ["control_tangents"])
    planar3 = system.n_bodies == 3 and system.dim == 2
    for k, (cell, y0) in enumerate(zip(cell_ids, starts)):
        clock = time.perf_counter()
        if np.isnan(y0[0]):
            res["status"][k] = Status.INACCESSIBLE
            res["n_steps"][k] = res["n_rhs"][k] = 0
            res["wall_time"][k] = time.perf_counter() - clock
            continue
        res["initial_state"][k] = y0
        for name, value in (("energy", system.energy), ("angular_momentum",
                                                         system.angular_momentum)):
            if name in res:
                res[name][k] = value(y0)
        if which:
            ci = chaos_indicators(system, y0, integ["t_final"], options, cell=int(cell),
                                  events=events, **kw)
            out = ci.outcome
            for name in ("ftle", "ftle_spread", "megno", "megno_spread", "megno_slope", "fli",
                         "sali", "gali2", "ftle_history", "megno_history", "fli_history",
                         "sali_history"):
                if name in res:
                    res[name][k] = getattr(ci, name)
            res["energy_error"][k] = ci.energy_error
            res["angular_momentum_error"][k] = ci.angular_momentum_error
        else:
            history = archive.coordinates(config)["history_time"][1]
            kw_orbit = {key: v for key, v in kw.items() if key != "control_tangents"}
            out = integrate(system, y0, integ["t_final"], events=events, t_eval=history,
                            **kw_orbit)
            done = ~np.isnan(out.samples[:, 0])
            res["energy_error"][k], res["angular_momentum_error"][k] = conservation_errors(
                system, y0, np.concatenate([out.samples[done], [out.y]]))
        res["status"][k] = out.status
        res["t_end"][k] = out.t
        res["n_steps"][k], res["n_rhs"][k] = out.n_steps, out.n_rhs
        if events:
            kept = out.crossings.t.size
            res["n_crossings"][k] = out.n_crossings
            res["crossing_time"][k, :kept] = out.crossings.t
            if planar3 and kept:
                r = reduced(system, out.crossings.y)
                for q in ("sigma", "p_sigma", "eta", "p_eta", "phi", "p_phi"):
                    res[f"crossing_{q}"][k, :kept] = getattr(r, q)
            if "crossing_state" in res:
                res["crossing_state"][k, :kept] = out.crossings.y
        res["wall_time"][k] = time.perf_counter() - clock
    return res


# ---------------------------------------------------------------- checkpoints

def checkpoint_dir(config: Config) -> Path:
    out = config.output
    return out.with_name(out.name + ".checkpoints") / config.result_key()


def save_chunk(folder: Path, cell_ids, result: dict):
    """Write one finished chunk atomically (temporary file, fsync, rename)."""
    name = folder / f"chunk-{int(cell_ids[0]):012d}-{int(cell_ids[-1]):012d}-{len(cell_ids)}.npz"
    tmp = folder / f".{name.name}.{os.getpid()}.tmp"
    with open(tmp, "wb") as fh:
        np.savez(fh, cell_ids=np.asarray(cell_ids, dtype=np.int64), **result)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, name)


def finished_cells(folder: Path) -> np.ndarray:
    files = sorted(folder.glob("chunk-*.npz"))
    ids = [np.load(f)["cell_ids"] for f in files]
    return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)


def _loader(config: Config, folder: Path):
    files = sorted(folder.glob("chunk-*.npz"))
    specs = {v.name: v for v in archive.variables(config)}

    def load(name):
        v = specs[name]
        k = archive.extra_size(config, v.extra)
        arr = np.full((config.n_cells,) + (() if v.extra is None else (k,)), v.fill, v.dtype)
        for f in files:
            with np.load(f) as z:
                arr[z["cell_ids"]] = z[name]
        return arr
    return load


# ---------------------------------------------------------------- running

@contextlib.contextmanager
def _client(config: Config, workers, scheduler):
    from dask.distributed import Client, LocalCluster
    address = scheduler or config.tables["dask"]["scheduler"]
    if address:
        with Client(address, timeout="30s") as client:
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
    with LocalCluster(n_workers=workers or config.tables["dask"]["workers"],
                      threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


def _chunks(ids: np.ndarray, size: int):
    """Strided chunks of about `size` cells: chunk k holds ids k, k + K, k + 2K, ... Grids
    are ordered by parameter and cost varies smoothly with it (chaotic cells cost more), so
    contiguous chunks would leave the expensive ones for the end and workers idle."""
    count = -(-ids.size // size)
    return [ids[k::count] for k in range(count)]


def run_survey(source, *, workers: int | None = None, scheduler: str | None = None,
               progress: bool | None = None, command: str = "survey.run_survey",
               timings: dict | None = None) -> Path:
    """Run a survey (config path or dict, or a Config) to its archive; returns the archive
    path. Resumes from checkpoints of an interrupted run of the same config. `timings`, if
    given, receives the seconds spent preparing cells, starting the cluster, computing
    (first task submitted to last result saved) and writing the archive."""
    clock = {"start": time.perf_counter()}
    config = source if isinstance(source, Config) else load_config(source)
    starts = build_starts(config)
    folder = checkpoint_dir(config)
    folder.mkdir(parents=True, exist_ok=True)
    done = finished_cells(folder)
    todo = np.setdiff1d(np.arange(config.n_cells), done)
    if progress is None:
        progress = sys.stderr.isatty()
    if todo.size:
        from tqdm import tqdm
        first = todo[~np.isnan(starts[todo, 0])][:1]
        if first.size:   # compile (or load from the disk cache) once, before the workers
            run_cells(_short(config), first, starts[first])
        warm = (lambda: run_cells(_short(config), first, starts[first])) if first.size else None
        clock["prepared"] = time.perf_counter()
        with _client(config, workers, scheduler) as client, \
                tqdm(total=config.n_cells, initial=done.size, unit="cell", disable=not progress,
                     desc=config.name, smoothing=0.1) as bar:
            from dask.distributed import as_completed
            if warm is not None:      # every worker loads the kernels from the disk cache
                client.run(warm)
            clock["cluster"] = time.perf_counter()
            size = config.tables["dask"]["chunk_size"] or min(
                256, max(1, -(-todo.size // (64 * len(client.scheduler_info()["workers"])))))
            chunks = _chunks(todo, size)
            key = config.result_key()
            futures = {client.submit(run_cells, config, ids, starts[ids], pure=False,
                                     key=f"cells-{key}-{int(ids[0])}",
                                     retries=config.tables["dask"]["retries"]): ids
                       for ids in chunks}
            for future in as_completed(futures):
                ids = futures.pop(future)
                save_chunk(folder, ids, future.result())
                future.release()
                bar.update(len(ids))
            clock["computed"] = time.perf_counter()
    clock["archive"] = time.perf_counter()
    path = archive.write(config, _loader(config, folder), command)
    shutil.rmtree(folder)
    with contextlib.suppress(OSError):
        folder.parent.rmdir()
    if timings is not None:
        now = time.perf_counter()
        c = clock
        timings.update(prepare=c.get("prepared", c["archive"]) - c["start"],
                       cluster=c.get("cluster", c["archive"]) - c.get("prepared", c["archive"]),
                       compute=c.get("computed", c["archive"]) - c.get("cluster", c["archive"]),
                       archive=now - c["archive"], total=now - c["start"])
    return path


def _short(config: Config) -> Config:
    """The same config with a tiny t_final: compiles every kernel a cell uses."""
    tables = {k: (dict(v) if isinstance(v, dict) else v) for k, v in config.tables.items()}
    tables["integration"]["t_final"] = 1e-3
    tables["indicators"]["renorm_interval"] = 1e-3
    tables["indicators"]["perturbations"] = min(1, tables["indicators"]["perturbations"])
    return Config(tables, config.axes, config.fixed, config.text, config.source)


def run(source, **kw):
    """Python API: run a survey and return its archive as an xarray Dataset."""
    import xarray as xr
    return xr.open_dataset(run_survey(source, **kw))


# ---------------------------------------------------------------- verification

def verify(path, cells: int = 8, seed: int = 0):
    """Recompute a sample of cells from the config stored in an archive and compare every
    reproducible variable bit for bit. Returns (ok, report lines)."""
    import xarray as xr
    from .config import parse_config
    with xr.open_dataset(path) as ds:
        config = parse_config(ds.attrs["config"], f"{path} (stored config)", check_output=False)
        n = config.n_cells
        rng = np.random.default_rng(seed)
        sample = np.unique(np.concatenate([[0, n - 1], rng.choice(n, min(cells, n),
                                                                   replace=False)]))[:max(cells, 2)]
        starts = build_starts(config)
        fresh = run_cells(config, sample, starts[sample])
        lines, ok = [], True
        for name in archive.reproducible_variables(ds):
            stored = ds[name].values.reshape((n,) + ds[name].shape[len(config.shape):])
            a, b = stored[sample], fresh[name].astype(stored.dtype)
            same = a.tobytes() == b.tobytes()
            ok &= same
            if not same:
                lines.append(f"{name}: differs in {np.sum(~_equal(a, b))} of {len(sample)} "
                             "cells")
        lines.insert(0, f"recomputed cells {', '.join(map(str, sample))} of {n}: "
                        + ("all reproducible variables match bit for bit" if ok else "MISMATCH"))
    return ok, lines


def _equal(a, b):
    eq = (a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else a == b
    return eq.reshape(len(a), -1).all(axis=1)
