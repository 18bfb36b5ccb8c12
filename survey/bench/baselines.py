"""survey against its competitors, used as their docs recommend: scipy's DOP853 with a NumPy
right-hand side and heyoka's Taylor integrator on the paper's orbits (`run`), and a grid end
to end against heyoka's SIMD batch ensemble (`scan_vs_heyoka`)."""
from __future__ import annotations


import math
import time

import numpy as np

from ..catalog import defaults
from ..catalog.variables import V
from ..numerics.indicators import deviation_vectors
from ..numerics.integrate import integrate, integrate_batch
from ..physics.families import initial_state
from ..physics.system import System
from .common import CASES, best_time, checked, command_phases


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


def heyoka_integrator(system: System, y0, tangent_vector, tol, megno=False, batch=0,
                      normalised=False, t_scale=1.0):
    """heyoka's Taylor integrator of the same system (three bodies in the plane, U = c P^k / k,
    any masses), written as plainly as survey's kernels: forces U'(P) times the unit side
    vectors, and the tangent forces from the paper's one-jet (Appendix E) on the same
    subexpressions, U''(P) dP e + U'(P) (dr - (e . dr) e) / L per side -- 4.2x faster in
    heyoka than the Jacobian-vector product of symbolic derivatives (`hy.diff`) at the same
    energy error. fast_math, as heyoka's documentation offers for speed (it leaves the
    energy error unchanged here).

    megno adds the two accumulators of MEGNO as ODE components, x' = t (w . w')/|w|^2 and
    z' = x / (t + 1) (the work of survey's MEGNO: heyoka has no step-end hook to do it
    survey's way). normalised keeps the deviation vector at unit length inside the ODE,
    w' = A w - (w . A w) w, with ln|w| / t_scale as one more component: no stops to
    renormalise, so a batch runs in one propagate. heyoka's error control covers every
    component, so the accumulators are scaled to stay O(1) (t_scale = T; x' = t (w . A w) /
    T^2): unscaled, ln|w| ~ 400 in chaos loosens the control of the orbit itself (energy
    errors 70x larger at the same tol). batch > 0 builds the SIMD batch integrator of that
    width, every lane starting from the same state."""
    import heyoka as hy
    c, k = system.potential.params
    m = np.repeat(system.masses, 2)
    q = hy.make_vars(*[f"q{i}" for i in range(6)])
    p = hy.make_vars(*[f"p{i}" for i in range(6)])
    dq = hy.make_vars(*[f"dq{i}" for i in range(6)])
    dp = hy.make_vars(*[f"dp{i}" for i in range(6)])
    pairs = ((0, 1), (1, 2), (2, 0))
    sides = []
    for i, j in pairs:
        rx, ry = q[2 * j] - q[2 * i], q[2 * j + 1] - q[2 * i + 1]
        length = hy.sqrt(rx * rx + ry * ry)
        sides.append((rx / length, ry / length, length, dq[2 * j] - dq[2 * i],
                      dq[2 * j + 1] - dq[2 * i + 1]))
    P = sum(side[2] for side in sides)
    U1 = c * P if k == 2 else c * P ** (k - 1)
    U2 = c * (k - 1) * P ** (k - 2) if k != 2 else c
    force, tangent_force = [0.0] * 6, [0.0] * 6
    dP = sum(ex * rx + ey * ry for ex, ey, _, rx, ry in sides)
    for (i, j), (ex, ey, length, rx, ry) in zip(pairs, sides):
        along = ex * rx + ey * ry
        g = (U2 * dP * ex + U1 / length * (rx - along * ex),
             U2 * dP * ey + U1 / length * (ry - along * ey))
        for axis, (e, gc) in enumerate(((ex, g[0]), (ey, g[1]))):
            force[2 * i + axis] += U1 * e
            force[2 * j + axis] -= U1 * e
            tangent_force[2 * i + axis] += gc
            tangent_force[2 * j + axis] -= gc
    sys = [(q[i], p[i] / m[i]) for i in range(6)] + [(p[i], force[i]) for i in range(6)]
    state = list(y0)
    if tangent_vector is not None:
        w = list(dq) + list(dp)
        Aw = [dp[i] / m[i] for i in range(6)] + tangent_force
        if normalised:
            rate = sum(wi * ai for wi, ai in zip(w, Aw))     # w . A w = d ln|w|/dt, |w| = 1
            L = hy.make_vars("L")
            sys += [(wi, ai - rate * wi) for wi, ai in zip(w, Aw)] + [(L, rate / t_scale)]
            state += list(tangent_vector / np.linalg.norm(tangent_vector)) + [0.0]
        else:
            rate = sum(wi * ai for wi, ai in zip(w, Aw)) / sum(wi * wi for wi in w)
            sys += list(zip(w, Aw))
            state += list(tangent_vector)
        if megno:
            x, z = hy.make_vars("x", "z")
            sys += [(x, hy.time * rate / t_scale ** 2), (z, x / (hy.time + 1.0))]
            state += [0.0, 0.0]
    if batch:
        return hy.taylor_adaptive_batch(sys, np.repeat(np.array(state)[:, None], batch, 1),
                                        tol=tol, fast_math=True)
    return hy.taylor_adaptive(sys, state, tol=tol, fast_math=True)


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
            wall, res = best_time(lambda: integrate(system, y0, t_final, rtol=tol, atol=tol,
                                                     **kw), repeats)
            row = dict(case=label, kind=kind, survey_s=wall, steps=res.n_steps,
                       rhs=res.n_rhs, dE=abs(system.energy(res.y) / E0 - 1))
            # scipy on a shorter span, extrapolated by survey's own work ratio (same method,
            # same steps): t_scipy(T) ~ t_scipy(t_short) * rhs(T) / rhs(t_short)
            from scipy.integrate import solve_ivp
            state0 = np.concatenate([y0, w0]) if with_tangent else y0
            short = integrate(system, y0, t_scipy, rtol=tol, atol=tol, **kw)
            f = numpy_rhs(system, with_tangent)
            sp_wall, sp = best_time(lambda: solve_ivp(f, (0, t_scipy), state0, method="DOP853",
                                                       rtol=tol, atol=tol), 1)
            row["scipy_s"] = sp_wall * res.n_rhs / short.n_rhs
            row["scipy_check"] = float(np.abs(sp.y[:system.n, -1] - short.y).max())
            row.update(_heyoka(system, y0, w0 if with_tangent else None, t_final, E0, row["dE"],
                               heyoka_tols, repeats))
            rows.append(row)
    _print_table(rows, t_scipy, t_final, out)
    return rows


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
        wall, r = best_time(go, repeats)
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


def scan_vs_heyoka(cells=101, t_final=2000.0, tol=1e-12, repeats=2, folder="results/bench",
                   heyoka_tols=(1e-10, 1e-11, 1e-12, 1e-13, 1e-14, 1e-15), out=print):
    """The issue's grid: `cells` orbits of the equilateral family, delta in [0, 10], one
    tangent vector + MEGNO, no section, through survey on 2 local workers, against heyoka at
    its strongest: the SIMD batch integrator (in the width heyoka recommends or this
    machine's vector width, whichever runs faster: `_heyoka_scan`) over the same starts and
    deviation vectors, one `propagate_until` per batch in `ensemble_propagate_until_batch`
    on 2 threads, the tangent kept at unit length inside the ODE (no stops), the one-jet
    written plainly (heyoka_integrator), at the loosest tolerance whose largest energy error
    is not above survey's (its JIT compilation not counted). survey runs twice: the same
    work as heyoka (`[tori] extend = 0`: every orbit to t_final once), which the ratios
    compare, and its default, where the cells whose verdict is in doubt run again to 4
    t_final. Reported: survey's compute phase, the in-process run by phase, and the command
    line (`python -m survey run`, interpreter start to archive) without and with the default
    torus analysis; best of `repeats` interleaved runs. Targets: compute <= 0.4x heyoka,
    command line <= 1.0x without the torus analysis, <= 1.2x with it."""
    import sys
    from pathlib import Path

    import xarray as xr

    from ..pipeline.config import _to_toml
    from ..pipeline.sweep import run_survey
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cfgs, files = {}, {}
    for extend in (0, None):            # the same work as heyoka; survey's default
        name = "same" if extend == 0 else "default"
        tori = {} if extend is None else {"extend": extend}
        cfgs[name] = {"survey": {"name": "bench-scan",
                                 "output": str(folder / f"bench-scan-{name}.nc")},
                      "initial": {"family": "equilateral",
                                  "delta": {"start": 0.0, "stop": 10.0, "num": cells}},
                      "integration": {"t_final": t_final, "rtol": tol, "atol": tol},
                      "indicators": {"deviations": 1, "perturbations": 0,
                                     "which": [V.ftle, V.megno, V.fli]},
                      "tori": {**tori, "analyse": False},
                      "dask": {"workers": 2}}
        for analyse in (False, True):
            c = {**cfgs[name], "tori": {**tori, "analyse": analyse},
                 "survey": {"name": "bench-scan",
                            "output": str(folder / f"scan-{name}-{analyse}.nc")}}
            files[name, analyse] = folder / f"scan-{name}-{analyse}.toml"
            files[name, analyse].write_text(_to_toml(c))
    for cfg in cfgs.values():
        run_survey(cfg, progress=False)     # numba's disk cache is warm from here on
    with xr.open_dataset(cfgs["same"]["survey"]["output"]) as ds:
        survey_dE = float(np.nanmax(ds[V.energy_error].values))
        ftle = ds[V.ftle].values
    hy = _heyoka_scan(cells, t_final, heyoka_tols, survey_dE)
    tori = {**cfgs["same"], "tori": {"extend": 0},
            "survey": {**cfgs["same"]["survey"], "output": str(folder / "scan-same-tori.nc")}}
    best = {k: math.inf for k in ("heyoka", "tori", *files, *((n, "compute") for n in cfgs))}
    phases, command = {}, None
    for _ in range(repeats):
        for name, cfg in cfgs.items():
            timings = {}
            run_survey(cfg, progress=False, timings=timings)
            if timings["compute"] < best[name, "compute"]:
                best[name, "compute"] = timings["compute"]
                phases[name] = timings
        timings = {}
        run_survey(tori, progress=False, timings=timings)
        best["tori"] = min(best["tori"], timings["compute"])
        for key, toml in files.items():
            t = time.perf_counter()
            checked([sys.executable, "-m", "survey", "run", str(toml), "--no-report",
                     "--no-progress"])
            best[key] = min(best[key], time.perf_counter() - t)
        by_phase = command_phases(["run", str(files["same", False]), "--no-report",
                                   "--no-progress"])
        if command is None or sum(by_phase.values()) < sum(command.values()):
            command = by_phase
        if hy:
            wall, heyoka_ftle = hy["run"]()
            best["heyoka"] = min(best["heyoka"], wall)
    out("")
    out(f"Scan of {cells} orbits (equilateral, delta in [0, 10], t = {t_final:g}, one tangent "
        f"vector + MEGNO, 2 workers / threads; best of {repeats} interleaved runs): seconds")
    out(f"survey (rtol = atol = {tol:g}; largest energy error {survey_dE:.1e} at the same "
        "work as heyoka):")
    out(f"  {'':24s}{'same work as heyoka':>20s}{'default':>10s}")
    for label, key in (("compute phase", "compute"),
                       ("python -m survey run", False), ("the same with [tori]", True)):
        out(f"  {label:24s}{best['same', key]:20.2f}{best['default', key]:10.2f}")
    out("  (same work as heyoka: every orbit to t_final once, [tori] extend = 0; default: "
        "the cells whose verdict is in doubt run again to 4 t_final; command line: "
        "interpreter start to archive, Python writing bytecode as it does by default)")
    for name in cfgs:
        out(f"  in process, by phase ({name}): " + ", ".join(
            f"{k} {v:.2f}" for k, v in phases[name].items() if k != "tasks"))
    out("  python -m survey run, by phase (same work, torus analysis off; prepare loads the "
        "kernels, rest is the regime summary): " + ", ".join(
            f"{k} {v:.2f}" for k, v in command.items()))
    share = best["tori"] / best["same", "compute"] - 1.0
    out(f"  the torus analysis (same work, in process): compute {best['same', 'compute']:.2f}"
        f" -> {best['tori']:.2f} s, {100 * share:+.0f}% (the orbits sampled every "
        f"{defaults.SAMPLE_INTERVAL:g} and analysed; target <= +15%)")
    parts = _torus_parts(cfgs["same"], repeats)
    out(f"  of it, on one worker's task ({parts['cells']} cells; best of {repeats}): "
        f"{parts['off']:.2f} s without the analysis, {parts['on']:.2f} s with it: the "
        f"analysis of the samples {parts['analysis']:.2f} s, the sampling (dense output at "
        f"the sample times, the samples' memory) {parts['on'] - parts['off'] - parts['analysis']:.2f} s")
    if not hy:
        out("heyoka is not installed (pip install 'survey[bench]'): no baseline.")
        return dict(compute=best["same", "compute"], phases=phases, command=command,
                    tori=best["tori"])
    width_note = "" if len(hy["trials"]) < 2 else ", the faster of " + " and ".join(
        f"{w} ({min(t):.2f}-{max(t):.2f} s)" for w, t in hy["trials"].items()) + \
        f" in two trials each, heyoka recommending {hy['recommended']}"
    out(f"heyoka batch           {best['heyoka']:7.2f}  (tol {hy['tol']:g}, the loosest of "
        f"{', '.join(f'{t:g}' for t in heyoka_tols)} whose largest energy error, "
        f"{hy['dE']:.1e}, is not above survey's; SIMD width {hy['width']}"
        f"{width_note}, {hy['batches']} batches, one propagate_until each over 2 "
        f"threads, unit tangent in the ODE, one-jet tangent forces, fast_math; JIT "
        f"{hy['compile']:.2f} s not counted)")
    agree = np.mean((ftle > 0.02) == (heyoka_ftle > 0.02))
    regular = (ftle < 0.02) & (heyoka_ftle < 0.02)
    out(f"same physics: FTLE > 0.02 in both or neither in {100 * agree:.0f}% of the cells; "
        f"largest FTLE difference where both are below 0.02: "
        f"{np.max(np.abs(ftle - heyoka_ftle)[regular], initial=0.0):.1e}")
    ratios = {k: best["same", k] / best["heyoka"] for k in ("compute", False, True)}
    default = {k: best["default", k] / best["heyoka"] for k in ("compute", False, True)}
    out(f"survey / heyoka: compute {ratios['compute']:.2f}x (target <= 0.4x), command line "
        f"{ratios[False]:.2f}x (<= 1.0x), with the torus analysis {ratios[True]:.2f}x "
        f"(<= 1.2x); survey's default: {default['compute']:.2f}x, {default[False]:.2f}x, "
        f"{default[True]:.2f}x")
    return dict(compute=best["same", "compute"], heyoka=best["heyoka"], ratios=ratios,
                default=default, phases=phases, command=command, tori=best["tori"])


def _torus_parts(cfg, repeats) -> dict:
    """Where the torus analysis's share of a scan goes, on the task of one worker (every
    second cell), in this process: the task with the analysis off and on (`first_runs`, a
    worker's code path), and the analysis alone on the same orbits' samples -- the rest is
    the sampling. Best of `repeats` interleaved runs each."""
    from ..pipeline.cells import CellTask, build_starts, first_runs, torus_evidence
    from ..pipeline.config import load_config
    runs = {}
    for analyse in (False, True):
        config = load_config({**cfg, "tori": {"extend": 0, "analyse": analyse}})
        ids = np.arange(0, config.n_cells, 2)
        task, starts = CellTask.of(config), build_starts(config, ids)
        first_runs(task.short(), ids[:1], starts[:1])
        runs[analyse] = (task, ids, starts)
    task, _, starts = runs[True]
    system = config.system()
    T, dt = config.settings.integration.t_final, task.tori.sample_interval
    outs = integrate_batch(system, starts, T, t_fine=(np.arange(int(T / dt)) + 0.5) * dt)
    errors = [abs(system.energy(o.y) / system.energy(y0) - 1.0) for o, y0 in zip(outs, starts)]

    def analysis():
        for o, e in zip(outs, errors):
            torus_evidence(task, system, o.fine, e)
    best = {"off": math.inf, "on": math.inf, "analysis": math.inf}
    for _ in range(repeats):
        for key, analyse in (("off", False), ("on", True)):
            best[key] = min(best[key], best_time(lambda: first_runs(*runs[analyse]), 1)[0])
        best["analysis"] = min(best["analysis"], best_time(analysis, 1)[0])
    return {**best, "cells": len(starts)}


def vector_doubles() -> int:
    """Doubles in one of this machine's SIMD vectors, from the features LLVM finds (a virtual
    machine may hide some of its CPU's: heyoka then recommends a width for the CPU's name that
    the vectors it may use do not hold)."""
    import llvmlite.binding as llvm
    features = llvm.get_host_cpu_features()
    return 8 if features.get("avx512f") else 4 if features.get("avx") else 2


def _heyoka_scan(cells, t_final, tols, dE_max):
    """heyoka_batches over the scan's starts: the equilateral family, delta in [0, 10], each
    with survey's first deviation vector."""
    from ..catalog.indicators import IndicatorOptions
    system = System.create()
    seed = IndicatorOptions().seed
    starts = [initial_state(system, "equilateral", delta=float(delta))
              for delta in np.linspace(0.0, 10.0, cells)]
    return heyoka_batches(system, starts, [deviation_vectors(system, y0, 1, seed)[0]
                                           for y0 in starts], t_final, tols, dE_max)


def heyoka_batches(system, starts, deviations, t_final, tols, dE_max):
    """heyoka's batch ensemble over orbits (starts, each with its deviation vector and
    MEGNO) at the loosest of `tols` whose largest relative energy error at t_final is not
    above dE_max, in batches of the SIMD width heyoka recommends or of the width of this
    machine's vectors, where they differ, whichever runs faster (on a virtual AMD EPYC that
    hides AVX-512 heyoka recommends 8 and runs the scan ~10% faster in 4): a runner giving
    (wall time, ln|w(t_final)| / t_final per orbit), or {} without heyoka."""
    try:
        import heyoka as hy
    except ImportError:
        return {}
    n = system.n
    orbits = len(starts)
    E0 = [system.energy(y0) for y0 in starts]
    starts = [np.concatenate([y0, w0 / np.linalg.norm(w0), [0.0, 0.0, 0.0]])
              for y0, w0 in zip(starts, deviations)]
    recommended = hy.recommended_simd_size()

    def runner(tol, width):
        batches = -(-orbits // width)
        padded = np.array(starts + [starts[-1]] * (batches * width - orbits))
        first = padded.reshape(batches, width, -1).transpose(0, 2, 1)
        t = time.perf_counter()
        ta = heyoka_integrator(system, starts[0][:n], starts[0][n:2 * n], tol, megno=True,
                               batch=width, normalised=True, t_scale=t_final)
        compile_s = time.perf_counter() - t

        def run():
            def gen(ta_copy, i):
                ta_copy.set_time(0.0)
                ta_copy.state[:] = first[i]
                return ta_copy
            clock = time.perf_counter()
            done = hy.ensemble_propagate_until_batch(ta, t_final, batches, gen, max_workers=2)
            wall = time.perf_counter() - clock
            final = np.concatenate([np.array(r[0].state).T for r in done])[:orbits]
            return wall, final
        return run, compile_s

    chosen = None
    for tol in sorted(tols, reverse=True):          # loosest first
        run, compile_s = runner(tol, recommended)
        _, final = run()
        dE = float(np.max(np.abs(system.energy(final[:, :n]) / np.array(E0) - 1)))
        if dE <= dE_max:
            chosen = dict(tol=tol, dE=dE, compile=compile_s)
            break
    if chosen is None:
        raise RuntimeError(f"no heyoka tolerance of {tols} reached survey's energy error "
                           f"{dE_max:.1e}")
    runs = {recommended: run}
    for width in {vector_doubles()} - {recommended}:
        runs[width] = runner(chosen["tol"], width)[0]
        runs[width]()                                   # its first run, untimed as above
    # the faster width from two interleaved runs of each, then best of `repeats` of it alone,
    # as for survey (a best over both widths' runs would be a best of more runs)
    trials = {w: [] for w in runs}
    for _ in range(2 if len(runs) > 1 else 0):
        for width, run in runs.items():
            trials[width].append(run()[0])
    width = min(runs, key=lambda w: min(trials[w], default=0.0))
    run = runs[width]

    def timed():
        wall, final = run()
        return wall, final[:, 2 * n]                     # ln|w| / T
    return {**chosen, "run": timed, "width": width, "recommended": recommended,
            "trials": trials, "batches": -(-orbits // width)}
