"""`python -m survey bench`: survey's DOP853 against scipy's DOP853 (NumPy right-hand side)
and heyoka's Taylor integrator, all measured in the same run on the paper's two orbits.

Speed claims are ratios against baselines timed here, never absolute numbers: machines
differ, ratios on one machine in one run do not. Compilation (numba's cached load, heyoka's
LLVM JIT) is timed separately from integration.
"""
from __future__ import annotations

import math
import time

import numpy as np

from .dynamics import System
from .families import initial_state
from .indicators import deviation_vectors
from .integrator import integrate

CASES = [("chaotic 'sides'", "sides", {}),
         ("regular equilateral d=3", "equilateral", {"delta": 3.0})]


def _best_time(fn, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def numpy_rhs(system: System, tangent: bool):
    """A plain vectorised NumPy right-hand side for scipy (three bodies, U = c P^k / k), with
    the tangent dynamics from the paper's one-jet (Appendix E)."""
    m = np.repeat(system.masses, system.dim)
    c, k = system.potential.params
    N, d, n = system.n_bodies, system.dim, system.n
    nq = n // 2
    pairs = np.array([[0, 1], [1, 2], [2, 0]])

    def f(_, y):
        q = y[:nq].reshape(N, d)
        r = q[pairs[:, 1]] - q[pairs[:, 0]]
        L = np.linalg.norm(r, axis=1)
        e = r / L[:, None]
        P = L.sum()
        U1, U2 = c * P ** (k - 1), c * (k - 1) * P ** (k - 2)
        F = np.zeros((N, d))
        np.add.at(F, pairs[:, 0], U1 * e)
        np.add.at(F, pairs[:, 1], -U1 * e)
        out = [y[nq:n] / m, F.ravel()]
        if tangent:
            dq = y[n:n + nq].reshape(N, d)
            dr = dq[pairs[:, 1]] - dq[pairs[:, 0]]
            edr = np.sum(e * dr, axis=1)
            g = U2 * edr.sum() * e + U1 * (dr - e * edr[:, None]) / L[:, None]
            dF = np.zeros((N, d))
            np.add.at(dF, pairs[:, 0], g)
            np.add.at(dF, pairs[:, 1], -g)
            out += [y[n + nq:] / m, dF.ravel()]
        return np.concatenate(out)
    return f


def heyoka_integrator(system: System, y0, tangent_vector, tol):
    """heyoka Taylor integrator of the same system (U = c P^k / k); the tangent dynamics are
    the symbolic derivative of the forces applied to one deviation vector."""
    import heyoka as hy
    N, d = system.n_bodies, system.dim
    c, k = system.potential.params
    q = hy.make_vars(*[f"q{i}" for i in range(N * d)])
    p = hy.make_vars(*[f"p{i}" for i in range(N * d)])
    pos = [q[i * d:(i + 1) * d] for i in range(N)]
    P = sum(hy.sqrt(sum((pos[j][a] - pos[i][a]) ** 2 for a in range(d)))
            for i, j in ((0, 1), (1, 2), (2, 0)))
    U = c * P ** k / k
    force = [-hy.diff(U, qi) for qi in q]
    m = np.repeat(system.masses, d)
    sys = [(q[i], p[i] / m[i]) for i in range(N * d)] + [(p[i], force[i]) for i in range(N * d)]
    state = list(y0)
    if tangent_vector is not None:
        dq = hy.make_vars(*[f"dq{i}" for i in range(N * d)])
        dp = hy.make_vars(*[f"dp{i}" for i in range(N * d)])
        sys += [(dq[i], dp[i] / m[i]) for i in range(N * d)]
        sys += [(dp[i], sum(hy.diff(force[i], q[j]) * dq[j] for j in range(N * d)))
                for i in range(N * d)]
        state += list(tangent_vector)
    return hy.taylor_adaptive(sys, state, tol=tol)


def run(t_final=2000.0, t_scipy=50.0, repeats=2, heyoka_tols=(1e-12, 1e-11, 1e-10, 1e-9),
        out=print):
    """Measure and print the comparison table; returns the rows as dicts."""
    system = System.create()
    tol = 1e-12
    rows = []
    t = time.perf_counter()
    y_warm = initial_state(system, "sides")
    integrate(system, y_warm, 1.0, tangents=deviation_vectors(system, y_warm, 1, seed=0))
    out(f"numba kernels loaded/compiled in {time.perf_counter() - t:.2f} s (cached on disk)")
    out(f"t = {t_final:g}, rtol = atol = {tol:g}, U = P^2/2, unit masses; wall times best of "
        f"{repeats}; dE = |E(t)/E(0) - 1| at the end")
    for label, family, params in CASES:
        y0 = initial_state(system, family, **params)
        E0 = system.energy(y0)
        w0 = deviation_vectors(system, y0, 1, seed=0)[0]
        for with_tangent in (False, True):
            kind = "orbit+tangent" if with_tangent else "orbit"
            kw = dict(tangents=w0) if with_tangent else {}
            wall, res = _best_time(lambda: integrate(system, y0, t_final, rtol=tol, atol=tol,
                                                     **kw), repeats)
            row = dict(case=label, kind=kind, survey_s=wall, steps=res.n_steps,
                       rhs=res.n_rhs, dE=abs(system.energy(res.y) / E0 - 1))
            # scipy on a shorter span, extrapolated by survey's own work ratio (same method,
            # same steps): t_scipy(T) ~ t_scipy(t_short) * rhs(T) / rhs(t_short)
            from scipy.integrate import solve_ivp
            state0 = np.concatenate([y0, w0]) if with_tangent else y0
            short = integrate(system, y0, t_scipy, rtol=tol, atol=tol, **kw)
            f = numpy_rhs(system, with_tangent)
            sp_wall, sp = _best_time(lambda: solve_ivp(f, (0, t_scipy), state0, method="DOP853",
                                                       rtol=tol, atol=tol), 1)
            row["scipy_s"] = sp_wall * res.n_rhs / short.n_rhs
            row["scipy_check"] = float(np.abs(sp.y[:system.n, -1] - short.y).max())
            row.update(_heyoka(system, y0, w0 if with_tangent else None, t_final, E0, row["dE"],
                               heyoka_tols, repeats))
            rows.append(row)
    _print_table(rows, t_scipy, t_final, out)
    return rows


def indicator_overhead(t_final=2000.0, repeats=7, deviations=2, out=print):
    """Cost of MEGNO + the phi = pi/2 section + 64-point indicator histories over the bare
    orbit + tangent-vector integration (same vectors, same steps), per paper orbit. The
    variants are timed interleaved and each keeps its best time, which cancels most of the
    machine's drift."""
    from .coordinates import section_event
    system = System.create()
    history = np.linspace(t_final / 64, t_final, 64)
    rows = []
    for label, family, params in CASES:
        y0 = initial_state(system, family, **params)
        w = deviation_vectors(system, y0, deviations, seed=0)
        ev = [section_event(system)]
        variants = {
            "bare": dict(tangents=w),
            "+MEGNO": dict(tangents=w, megno=True),
            "+section": dict(tangents=w, events=ev),
            "+all": dict(tangents=w, megno=True, events=ev, t_eval=history,
                         sample_tangents=True),
        }
        best = {k: math.inf for k in variants}
        res = {}
        for _ in range(repeats):
            for k, kw in variants.items():
                t = time.perf_counter()
                res[k] = integrate(system, y0, t_final, **kw)
                best[k] = min(best[k], time.perf_counter() - t)
        rows.append(dict(case=label, best=best, crossings=res["+all"].n_crossings,
                         steps=res["bare"].n_steps,
                         rhs={k: r.n_rhs for k, r in res.items()}))
    out("")
    out(f"Indicators and sections over the bare orbit + {deviations} tangent vectors "
        f"(t = {t_final:g}, best of {repeats} interleaved runs; target: +all < +20%)")
    out(f"{'case':26s} {'bare s':>8s} {'+MEGNO':>8s} {'+section':>9s} {'+all':>8s} "
        f"{'crossings':>9s} {'steps':>8s}")
    for r in rows:
        b = r["best"]
        pct = lambda k: f"{100 * (b[k] / b['bare'] - 1):+.0f}%"
        out(f"{r['case']:26s} {b['bare']:8.3f} {pct('+MEGNO'):>8s} {pct('+section'):>9s} "
            f"{pct('+all'):>8s} {r['crossings']:9d} {r['steps']:8d}")
    return rows


def torus_overhead(t_final=2000.0, repeats=6, out=print):
    """The torus analysis (Birkhoff digits, frequencies, resonance) per default survey cell
    -- 2 deviation vectors, 2 perturbed orbits, the phi section, histories -- against the
    same cell without it, through the worker's own code path (run_cells), best of
    `repeats` interleaved runs; and the classification of a 10^4-cell grid (target: the
    analysis adds < 15% per cell)."""
    import xarray as xr
    from .config import load_config
    from .sweep import CellTask, build_starts, run_cells
    from .tori import classify
    rows = []
    for label, fam, params in CASES:
        best = {}
        for analyse in (False, True):
            config = load_config({"survey": {"output": "results/bench/tori.nc"},
                                  "initial": {"family": fam, **params},
                                  "integration": {"t_final": t_final},
                                  "section": {"coordinate": "phi"},
                                  "tori": {"analyse": analyse}})
            task, starts = CellTask.of(config), build_starts(config)
            run_cells(task.short(), [0], starts)
            best[analyse] = (task, starts, math.inf)
        for _ in range(repeats):
            for analyse, (task, starts, b) in best.items():
                t = time.perf_counter()
                run_cells(task, [0], starts)
                best[analyse] = (task, starts, min(b, time.perf_counter() - t))
        rows.append((label, best[False][2], best[True][2]))
    n = 10_000
    rng = np.random.default_rng(0)
    grid = xr.Dataset({"status": ("cell", np.zeros(n, np.int8)),
                       **{k: ("cell", rng.uniform(0, 10, n)) for k in
                          ("birkhoff_digits", "birkhoff_digits_half", "megno", "sali",
                           "frequency_diffusion")},
                       "ftle": ("cell", rng.uniform(0, 0.2, n)),
                       "t_end": ("cell", np.full(n, t_final))})
    t = time.perf_counter()
    classify(grid)
    classified = time.perf_counter() - t
    out("")
    out(f"Torus analysis per default cell (t = {t_final:g}, best of {repeats} interleaved "
        "runs; target: < +15%)")
    out(f"{'case':26s} {'without s':>10s} {'with s':>8s} {'extra':>7s}")
    for label, without, with_ in rows:
        out(f"{label:26s} {without:10.3f} {with_:8.3f} {100 * (with_ / without - 1):+6.1f}%")
    out(f"classifying {n} cells: {classified * 1e3:.0f} ms")
    return rows


def survey_scaling(cells=200, t_final=2000.0, repeats=2, folder="results/bench", out=print):
    """End-to-end survey of `cells` cells of the equilateral family on 1 and 2 local
    workers, interleaved `repeats` times (this kind of machine drifts by 20% from run to
    run; each worker count keeps its best run). Reports the phases, the 2-vs-1 speed-up,
    and the per-task overhead: the share of the workers' compute phase not spent inside
    cells (targets: speed-up >= 1.85, overhead < 5%)."""
    import xarray as xr
    from .sweep import run_survey
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
    out(f"{'workers':>8s} {'prepare':>8s} {'cluster':>8s} {'compute':>8s} {'archive':>8s} "
        f"{'total':>8s} {'in cells':>9s} {'overhead':>9s}")
    for w, t in rows.items():
        out(f"{w:8d} {t['prepare']:8.2f} {t['cluster']:8.2f} {t['compute']:8.2f} "
            f"{t['archive']:8.2f} {t['total']:8.2f} {t['in_cells']:9.2f} "
            f"{100 * t['overhead']:8.1f}%")
    out(f"speed-up 2 vs 1 workers: {rows[1]['total'] / rows[2]['total']:.2f}x end to end, "
        f"{rows[1]['compute'] / rows[2]['compute']:.2f}x in the compute phase "
        "(targets: >= 1.85x; overhead < 5%)")
    return rows


def survey_memory(sizes=(10_000, 100_000), folder="results/bench", out=print):
    """Peak resident memory of the process driving a survey of many tiny cells (the
    workers are separate processes): finished results stream to checkpoint files, and the
    archive is written one variable at a time."""
    import subprocess
    import sys
    out("")
    out("Peak memory of the process driving a survey (cells of t = 0.01, orbit + indicators, "
        "no section; the workers are separate processes)")
    for n in sizes:
        code = f"from survey.bench import _memory_run; print(*_memory_run({n}, {folder!r}))"
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True)
        peak, seconds = map(float, res.stdout.split()[-2:])
        out(f"{n:>8d} cells: peak RSS {peak / 1024:7.1f} MiB, {seconds:6.1f} s")


def _memory_run(n, folder):
    import resource
    from .sweep import run_survey
    cfg = {"survey": {"name": f"mem-{n}", "output": f"{folder}/mem-{n}.nc"},
           "initial": {"family": "equilateral",
                       "delta": {"start": 0.0, "stop": 10.0, "num": n}},
           "integration": {"t_final": 0.01},
           "indicators": {"perturbations": 0, "history_points": 2,
                          "renorm_interval": 0.005},
           "dask": {"chunk_size": 500}}
    t = time.perf_counter()
    run_survey(cfg, progress=False)
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, time.perf_counter() - t


def _heyoka(system, y0, w0, t_final, E0, dE_survey, tols, repeats):
    """heyoka at tol 1e-12 and at the loosest tolerance in `tols` whose energy error is not
    above survey's ("similar energy error")."""
    try:
        import heyoka  # noqa: F401
    except ImportError:
        return {}
    res = {}
    matched = None
    for tol in tols:
        t = time.perf_counter()
        ta = heyoka_integrator(system, y0, w0, tol)
        compile_s = time.perf_counter() - t
        start = np.array(ta.state)

        def go():
            ta.time = 0.0
            ta.state[:] = start
            return ta.propagate_until(t_final)
        wall, r = _best_time(go, repeats)
        dE = abs(system.energy(np.array(ta.state[:system.n])) / E0 - 1)
        if tol == 1e-12:
            res.update(hy12_s=wall, hy12_steps=r[3], hy12_dE=dE, hy_compile_s=compile_s)
        if dE <= max(dE_survey, 1e-15):
            matched = dict(hym_s=wall, hym_tol=tol, hym_steps=r[3], hym_dE=dE)
    res.update(matched or {})
    return res


def _print_table(rows, t_scipy, t_final, out):
    out("")
    out(f"{'case':26s} {'kind':14s} {'survey s':>9s} {'steps':>8s} {'rhs':>9s} {'dE':>8s} | "
        f"{'scipy s*':>9s} {'x':>6s} | {'heyoka 1e-12':>12s} {'dE':>8s} {'x':>5s} | "
        f"{'heyoka tol':>10s} {'s':>7s} {'dE':>8s} {'x':>5s}")
    for r in rows:
        line = (f"{r['case']:26s} {r['kind']:14s} {r['survey_s']:9.3f} {r['steps']:8d} "
                f"{r['rhs']:9d} {r['dE']:8.1e} | {r['scipy_s']:9.1f} "
                f"{r['scipy_s'] / r['survey_s']:6.0f} |")
        if "hy12_s" in r:
            line += (f" {r['hy12_s']:12.3f} {r['hy12_dE']:8.1e} {r['hy12_s'] / r['survey_s']:5.2f} |")
        if "hym_s" in r:
            line += (f" {r['hym_tol']:10.0e} {r['hym_s']:7.3f} {r['hym_dE']:8.1e} "
                     f"{r['hym_s'] / r['survey_s']:5.2f}")
        out(line)
    out("")
    out(f"* scipy solve_ivp(DOP853) with a NumPy right-hand side, run to t = {t_scipy:g} and "
        f"extrapolated to t = {t_final:g} by survey's own RHS-evaluation ratio (same method and "
        "steps; its end state agrees with survey's to "
        f"{max(r['scipy_check'] for r in rows):.0e}).")
    out("x = baseline time / survey time (> 1: survey is faster). Targets: scipy x >= 100; "
        "orbit+tangent heyoka x >= 1.")
    if not any("hy12_s" in r for r in rows):
        out("heyoka is not installed (pip install 'survey[bench]'): its columns are empty.")
