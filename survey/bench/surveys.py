"""Whole surveys: scaling over workers, how busy a refined map keeps them, the driver's memory."""
from __future__ import annotations


import time

import numpy as np

from ..catalog.variables import V


def survey_scaling(cells=200, t_final=2000.0, repeats=2, folder="results/bench", out=print):
    """End-to-end survey of `cells` cells of the equilateral family on 1 and 2 local
    workers, interleaved `repeats` times (this kind of machine drifts by 20% from run to
    run; each worker count keeps its best run). Reports the phases, the 2-vs-1 speed-up,
    and the per-task overhead: the share of the workers' compute phase not spent inside
    cells (targets: speed-up >= 1.85, overhead < 5%)."""
    import xarray as xr

    from ..pipeline.sweep import run_survey
    rows = {}
    for _ in range(repeats):
        for workers in (1, 2):
            cfg = {"survey": {"name": f"bench-{workers}w",
                              "output": f"{folder}/bench-{workers}w.nc"},
                   "initial": {"family": "equilateral",
                               "delta": {"start": 0.0, "stop": 10.0, "num": cells}},
                   "integration": {"t_final": t_final},
                   "indicators": {"perturbations": 1},
                   "section": {"coordinate": "phi"},
                   "dask": {"workers": workers}}
            timings = {}
            path = run_survey(cfg, progress=False, timings=timings)
            with xr.open_dataset(path) as ds:
                timings["in_cells"] = float(ds.wall_time.sum())
            timings["overhead"] = 1.0 - timings["in_cells"] / (workers * timings["compute"])
            if workers not in rows or timings["total"] < rows[workers]["total"]:
                rows[workers] = timings
    out("")
    out(f"Survey of {cells} cells (equilateral family, t = {t_final:g}, default chunks; best "
        f"of {repeats} interleaved runs): seconds")
    out(f"{'workers':>8s} {'prepare':>8s} {'cluster':>8s} {'compute':>8s} {'shutdown':>8s} "
        f"{'archive':>8s} {'total':>8s} {'in cells':>9s} {'overhead':>9s}")
    for w, t in rows.items():
        out(f"{w:8d} {t['prepare']:8.2f} {t['cluster']:8.2f} {t['compute']:8.2f} "
            f"{t['shutdown']:8.2f} {t['archive']:8.2f} {t['total']:8.2f} {t['in_cells']:9.2f} "
            f"{100 * t['overhead']:8.1f}%")
    out(f"speed-up 2 vs 1 workers: {rows[1]['total'] / rows[2]['total']:.2f}x end to end, "
        f"{rows[1]['compute'] / rows[2]['compute']:.2f}x in the compute phase "
        "(targets: >= 1.85x; overhead < 5%)")
    return rows


def refined_map(t_final=300.0, levels=3, folder="results/bench", out=print):
    """A refined map (equilateral family over (delta, E), 9 x 7 cells refined `levels`
    times where neighbours disagree) on 2 local workers: how busy the workers were while
    it ran -- from the scheduler's task stream, each worker's share of the compute phase
    (first task started to last task ended) spent outside tasks, and its longest idle gap
    -- and the cells against the finest uniform grid (target: no worker idle more than
    10% of the time)."""
    import xarray as xr

    from ..pipeline.sweep import run_survey
    cfg = {"survey": {"name": "bench-refined", "output": f"{folder}/bench-refined.nc"},
           "initial": {"family": "equilateral", "delta": {"start": 0.0, "stop": 8.0, "num": 9},
                       V.energy: {"start": 60.0, "stop": 120.0, "num": 7}},
           "integration": {"t_final": t_final},
           "indicators": {"perturbations": 0},
           "refine": {"max_level": levels},
           "dask": {"workers": 2}}
    timings = {}
    path = run_survey(cfg, progress=False, timings=timings)
    with xr.open_dataset(path) as ds:
        cells, level = ds.sizes["cell"], ds["level"].values
    tasks = timings["tasks"]
    begin, end = min(t[1] for t in tasks), max(t[2] for t in tasks)
    out("")
    out(f"Refined map (equilateral, (delta, E) from 9 x 7 cells, {levels} levels, t = "
        f"{t_final:g}, 2 workers): {cells} cells ({', '.join(f'level {k}: {n}' for k, n in enumerate(np.bincount(level)))}); "
        f"the finest uniform grid has {(8 * 2 ** levels + 1) * (6 * 2 ** levels + 1)}")
    out(f"compute phase {timings['compute']:.2f} s, {len(tasks)} tasks; from the first task's "
        f"start to the last one's end {end - begin:.2f} s")
    out(f"{'worker':>28s} {'tasks':>6s} {'busy s':>7s} {'idle':>6s} {'longest gap s':>14s}")
    idle = {}
    for worker in sorted({t[0] for t in tasks}):
        spans = sorted((a, b) for w, a, b in tasks if w == worker)
        busy = sum(b - a for a, b in spans)
        gaps = [spans[0][0] - begin] + [c - b for (_, b), (c, _) in zip(spans, spans[1:])] + \
            [end - spans[-1][1]]
        idle[worker] = 1.0 - busy / (end - begin)
        out(f"{worker:>28s} {len(spans):6d} {busy:7.2f} {idle[worker]:6.1%} {max(gaps):14.2f}")
    out(f"largest idle share {max(idle.values()):.1%} (target <= 10%)")
    return dict(cells=cells, idle=idle, compute=timings["compute"])


def survey_memory(sizes=(10_000, 100_000), folder="results/bench", out=print):
    """Peak resident memory of the process driving a survey of many tiny cells (the
    workers are separate processes): finished results stream to checkpoint files, and the
    archive is written one variable at a time."""
    import sys

    from .common import checked
    out("")
    out("Peak memory of the process driving a survey (cells of t = 0.01, orbit + indicators, "
        "no section; the workers are separate processes)")
    for n in sizes:
        code = (f"from survey.bench.surveys import _memory_run; "
                f"print(*_memory_run({n}, {folder!r}))")
        peak, seconds, archive = map(float, checked([sys.executable, "-c", code]).split()[-3:])
        out(f"{n:>8d} cells: peak RSS {peak / 1024:7.1f} MiB, {seconds:6.1f} s, of which "
            f"writing the archive {archive:5.1f} s")


def _memory_run(n, folder):
    import resource

    from ..pipeline.sweep import run_survey
    cfg = {"survey": {"name": f"mem-{n}", "output": f"{folder}/mem-{n}.nc"},
           "initial": {"family": "equilateral",
                       "delta": {"start": 0.0, "stop": 10.0, "num": n}},
           "integration": {"t_final": 0.01},
           "indicators": {"perturbations": 0, "history_points": 2,
                          "renorm_interval": 0.005},
           "dask": {"chunk_size": 500}}
    t, timings = time.perf_counter(), {}
    run_survey(cfg, progress=False, timings=timings)
    return (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, time.perf_counter() - t,
            timings["archive"])


def _map(n: int, t_final: float, folder) -> dict:
    """A (delta, energy) map of about n cells (the same ranges at any n, so the same mix
    of tori and chaos), default verdict machinery."""
    rows = max(1, round((n / 2.5) ** 0.5))
    return {"survey": {"name": f"scale-{n}", "output": f"{folder}/scale-{n}.nc"},
            "initial": {"family": "equilateral",
                        "delta": {"start": 0.0, "stop": 8.0, "num": -(-n // rows)},
                        "energy": {"start": 60.0, "stop": 120.0, "num": rows}},
            "integration": {"t_final": t_final}}


def _map_against_heyoka(n, t_final, folder, out, repeats=2,
                        tols=(1e-10, 1e-11, 1e-12, 1e-13, 1e-14, 1e-15)):
    """The n-cell map's orbits -- every cell's ensemble, one deviation vector each, with
    MEGNO -- in heyoka's batch mode (baselines.heyoka_batches: the loosest of `tols` whose
    largest energy error is not above survey's) against survey's compute phase on the same
    work (every orbit once to t_final, no torus analysis) and with its default verdict
    machinery; best of `repeats` interleaved runs."""
    import xarray as xr

    from ..numerics.indicators import ensemble
    from ..pipeline.build import build_system, indicator_options
    from ..pipeline.cells import CellTask, GridStarts
    from ..pipeline.config import load_config
    from ..pipeline.sweep import run_survey
    from .baselines import heyoka_batches
    default = _map(n, t_final, folder)
    same = {**default, "survey": {**default["survey"], "output": f"{folder}/scale-{n}-same.nc"},
            "tori": {"extend": 0, "analyse": False}}
    run_survey(same, progress=False)
    config = load_config(same)
    task = CellTask.of(config)
    system = build_system(task.system)
    options = indicator_options(task.indicators)
    jobs = [ensemble(system, y0, options) for y0 in GridStarts(config)(np.arange(config.n_cells))
            if not np.isnan(y0[0])]
    starts = [y0 for j in jobs for y0 in j.starts]
    deviations = [w[0] for j in jobs for w in j.tangents]
    with xr.open_dataset(same["survey"]["output"]) as ds:
        dE = float(np.nanmax(ds[V.energy_error].values))
    hy = heyoka_batches(system, starts, deviations, t_final, tols, dE)
    if not hy:
        out("heyoka is not installed (pip install 'survey[bench]'): no baseline for the map.")
        return None
    best = {"heyoka": np.inf, "same": np.inf, "default": np.inf}
    for _ in range(repeats):
        for name, cfg in (("same", same), ("default", default)):
            timings = {}
            run_survey(cfg, progress=False, timings=timings)
            best[name] = min(best[name], timings["compute"])
        best["heyoka"] = min(best["heyoka"], hy["run"]()[0])
    out(f"the {config.n_cells:,}-cell map's {len(starts):,} orbits (every cell's ensemble, one "
        f"deviation vector each, MEGNO; best of {repeats}): heyoka's batch mode "
        f"{best['heyoka']:.2f} s (tol {hy['tol']:g}, the loosest of "
        f"{', '.join(f'{t:g}' for t in tols)} whose largest energy error, {hy['dE']:.1e}, is "
        f"not above survey's {dE:.1e}; SIMD width {hy['width']}, 2 threads, JIT not counted); "
        f"survey's compute phase on the same work (every orbit once to t_final, no torus "
        f"analysis) {best['same']:.2f} s, {best['same'] / best['heyoka']:.2f}x; with its "
        f"default verdict machinery {best['default']:.2f} s, "
        f"{best['default'] / best['heyoka']:.2f}x")
    return best


def survey_scale(sizes=(1_000, 10_000, 100_000), t_final=5.0, first=1_000_000,
                 folder="results/bench", out=print):
    """Cost per cell of a (delta, energy) map of 10^3..10^5 cells with the default verdict
    machinery on 2 local workers (target: flat within 10%); the smallest map's compute
    against heyoka's batch mode on its orbits (`_map_against_heyoka`); and a grid of `first` cells
    run as a user runs it, until its first chunk is saved: the seconds to that and the
    driver's peak memory (its starts are built by the workers, chunk by chunk)."""
    import os
    import shutil
    import signal
    import subprocess
    import sys
    from pathlib import Path

    import psutil

    from ..pipeline.checkpoints import checkpoint_dir
    from ..pipeline.config import load_config
    from ..pipeline.sweep import run_survey
    from .common import user_env
    out("")
    out(f"Maps of (delta, energy) cells, default verdict machinery, t = {t_final:g}, 2 local "
        "workers: seconds per cell (compute phase: first task submitted to last result "
        "saved; whole command: its total)")
    out(f"{'cells':>8s} {'compute':>9s} {'per cell ms':>12s} {'total':>8s} {'per cell ms':>12s}")
    run_survey(_map(4, t_final, folder), progress=False)     # kernels loaded or compiled
    rows = []
    for n in sizes:
        cfg = _map(n, t_final, folder)
        timings = {}
        run_survey(cfg, progress=False, timings=timings)
        cells = load_config(cfg).n_cells
        rows.append((cells, timings["compute"], timings["total"]))
        out(f"{cells:8d} {timings['compute']:9.1f} {1e3 * timings['compute'] / cells:12.2f} "
            f"{timings['total']:8.1f} {1e3 * timings['total'] / cells:12.2f}")
    per = [c / n for n, c, _ in rows]
    out(f"compute per cell, largest against smallest map: {per[-1] / per[0]:.2f}x "
        "(target: within 10%)")
    _map_against_heyoka(sizes[0], t_final, folder, out)
    cfg = _map(first, t_final, folder)
    config = load_config(cfg)
    toml = Path(folder) / f"scale-{first}.toml"
    toml.write_text(config.resolved_text)
    chunks = checkpoint_dir(load_config(toml))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "survey", "run", str(toml), "--no-report",
                             "--no-progress"], env=user_env(), start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    peak, saved = 0, None
    try:
        driver = psutil.Process(proc.pid)
        while saved is None and proc.poll() is None and time.perf_counter() - t0 < 600:
            peak = max(peak, driver.memory_info().rss)
            if any(chunks.glob("chunk-*.npz")):
                saved = time.perf_counter() - t0
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    shutil.rmtree(chunks, ignore_errors=True)
    out(f"a grid of {config.n_cells:,} cells (python -m survey run, warm kernel cache): its "
        f"first chunk saved {saved:.1f} s after the command, the driver's peak memory "
        f"{peak / 2**20:.0f} MiB by then (target: first task within 10 s)" if saved else
        f"a grid of {config.n_cells:,} cells saved no chunk within 600 s")
    return rows, saved, peak
