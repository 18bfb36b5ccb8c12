"""`python -m survey bench`: survey against its baselines, measured in the same run -- a
101-orbit grid end to end against heyoka's SIMD batch ensemble (`scan_vs_heyoka`), a
default cell against its bare orbit (`default_cell`), what a survey costs beside its cells
(`fixed_costs`), how busy a refined map keeps the workers (`refined_map`), where a step
goes and one orbit's step against the same step in plain scalar code (`step_costs`),
survey's DOP853 against scipy's DOP853 (NumPy right-hand side) and heyoka's
Taylor integrator on the paper's two orbits (`run`), the cost of indicators, sections and
the torus analysis, the scaling on 1 vs 2 workers, the driver's memory, and what the paper's
one-term systems would pay on the general path of sums of terms (`interaction_terms`).

Speed claims are ratios against baselines timed here, never absolute numbers: machines
differ, ratios on one machine in one run do not. Compilation (numba's cached load, heyoka's
LLVM JIT) is timed separately from integration.
"""
from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass

import numpy as np

from .catalog import defaults
from .catalog.variables import V
from .numerics.dop853 import (A2, A3, A4, A5, A6, A7, A8, A9, A10, A11, A12, B, BETA_ROOTS,
                              BHH1, BHH2, BHH3, ER, ERR_FLOOR_ROOT, _dot, error_norms, stages)
from .numerics.indicators import deviation_vectors
from .numerics.integrate import Frame, integrate, integrate_batch
from .physics.families import initial_state
from .machine import portable
from .machine.jit import helper, kernel, leaf
from .machine.portable import fma
from .physics.lanes import SIMD_LANES, rhs_lanes, state_size, workspace_size
from .physics.system import System
from .physics.terms import make_potential

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
    from .numerics.sections import section_event
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


@dataclass(frozen=True, eq=False)
class GeneralPath(System):
    """The same system on the general path of sums of terms (a 2-D `par`): all 12
    components integrated, never reduced."""

    @property
    def kernel_args(self):
        m, d, measure, prof, par = super().kernel_args
        return m, d, measure, prof, np.concatenate([par, [0.0] * 3]).reshape(1, 5)


def interaction_terms(t_final=2000.0, repeats=5, out=print):
    """The paper's one-term systems have a compiled path of their own (a 1-D `par`, in which
    further terms do not exist; the relative motion alone integrated); sums of terms take
    the general one (a 2-D `par`, all 12 components). Here the same paper orbit runs three
    ways, interleaved, best of `repeats`: the own path as a survey runs it, the own path on
    all 12 components (the reduction switched off: what the specialised right-hand side
    alone buys, which the target is about) and the general path; the orbits compared over
    t = 10. Then other systems in SIMD lanes (`_others_in_lanes`)."""
    from unittest import mock
    own = System.create()
    general = GeneralPath(own.masses, own.dim, own.terms)
    y0 = initial_state(own, "sides")
    w = deviation_vectors(own, y0, 1, seed=0)
    rows = []
    ways = (("own", own, False), ("own12", own, True), ("general", general, False))
    for label, kw in (("orbit", {}), ("orbit + tangent + MEGNO", dict(tangents=w, megno=True))):
        best = {}
        for _ in range(repeats):
            for name, system, full in ways:
                with mock.patch.object(Frame, "of", lambda *a: None) if full else \
                        contextlib.nullcontext():
                    t = time.perf_counter()
                    integrate(system, y0, t_final, **kw)
                    best[name] = min(best.get(name, math.inf), time.perf_counter() - t)
        # the own path integrates the relative motion (8 components, integrate.Frame), the
        # general one all 12: the same orbit to the tolerance, not the same bits; compared
        # over t = 10 (the 'sides' orbit is chaotic)
        short = [integrate(s, y0, min(t_final, 10.0), **kw).y for s in (own, general)]
        same = np.allclose(short[0], short[1], rtol=1e-8, atol=1e-10)
        rows.append(dict(case=label, **best, same=same))
    out("")
    out(f"The paper's system on its own compiled path vs the general path of sums of terms "
        f"('sides' orbit, t = {t_final:g}, best of {repeats} interleaved runs; own: the "
        f"relative motion, as a survey runs it; own 12: all 12 components, as the general "
        f"path; target: general <= 2x own 12)")
    out(f"{'case':26s} {'own s':>8s} {'own 12 s':>9s} {'general s':>10s} "
        f"{'general/own 12':>15s} {'general/own':>12s} agree")
    for r in rows:
        out(f"{r['case']:26s} {r['own']:8.3f} {r['own12']:9.3f} {r['general']:10.3f} "
            f"{r['general'] / r['own12']:14.2f}x {r['general'] / r['own']:11.2f}x "
            f"{'yes' if r['same'] else 'NO'}")
    lanes = _others_in_lanes(repeats)
    out(f"Other systems in lanes ({lanes['orbits']} orbits, t = {lanes['t']:g}, one tangent + "
        f"MEGNO; ns per attempted orbit-step, alone and in {SIMD_LANES} lanes):")
    for name, label in (("ljat", "the LJAT trimer (Lennard-Jones pairs + Axilrod-Teller)"),
                        ("mixed", "the paper's P^2/2 + Lennard-Jones pairs"),
                        ("3-D", "P^2/2 of three bodies in 3-D"),
                        ("four", "P^2/2 of four bodies in the plane (4 triangles)")):
        alone, many = lanes[name]
        out(f"  {label:55s} {alone:6.0f} {many:6.0f}  ({alone / many:.1f}x)")
    out(f"  the paper's 'sides' orbit in {SIMD_LANES} lanes: {lanes['paper']:.0f} ns")
    return rows


def _others_in_lanes(repeats, orbits=64, t_final=100.0) -> dict:
    """ns per attempted orbit-step, alone and in SIMD_LANES lanes, of systems other than the
    paper's -- the LJAT trimer and the paper's P^2/2 beside Lennard-Jones pairs (orbits
    near the equilateral triangle), P^2/2 of three bodies in 3-D (the triangle tilted out
    of the plane) and of four in the plane (near a square), seeded momenta -- and of the
    paper's 'sides' orbit in as many lanes, best of `repeats`."""
    rng = np.random.default_rng(3)
    triangle = np.array([[0.0, 0.0, 0.0], [1.12, 0.0, 0.0], [0.56, 0.97, 0.0]])
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    P2 = make_potential("perimetric_power")
    systems = {"ljat": (System(np.ones(3), 2, (
        make_potential("lennard_jones", {}, "pair"),
        make_potential("axilrod_teller", {"strength": 0.3}))), triangle[:, :2]),
        "mixed": (System(np.ones(3), 2, (P2, make_potential("lennard_jones", {}, "pair"))),
                  triangle[:, :2]),
        "3-D": (System(np.ones(3), 3, (P2,)), triangle),
        "four": (System(np.ones(4), 2, (P2,)), square)}
    paper = System.create()
    sides = np.repeat(initial_state(paper, "sides")[None], orbits, 0)

    def per_step(system, y0s, lanes, t):
        w = np.array([deviation_vectors(system, y, 1, seed=0) for y in y0s])
        integrate_batch(system, y0s, 1.0, tangents=w, megno=True, lanes=lanes)
        best = math.inf
        for _ in range(repeats):
            start = time.perf_counter()
            done = integrate_batch(system, y0s, t, tangents=w, megno=True, lanes=lanes)
            best = min(best, time.perf_counter() - start)
        return 1e9 * best / sum(o.n_steps + o.n_rejected for o in done)
    out = dict(orbits=orbits, t=t_final, paper=per_step(paper, sides, SIMD_LANES, t_final))
    for name, (system, at) in systems.items():
        q = at + 0.02 * rng.normal(size=(orbits,) + at.shape)
        p = 0.3 * rng.normal(size=(orbits,) + at.shape)
        p -= p.mean(1, keepdims=True)
        y0s = np.array([system.state(*qp) for qp in zip(q, p)])
        out[name] = (per_step(system, y0s[:4], 1, t_final),
                     per_step(system, y0s, SIMD_LANES, t_final))
    return out


def torus_overhead(t_final=2000.0, repeats=6, out=print):
    """The torus analysis (Birkhoff digits, frequencies, resonance) per default survey cell
    -- 2 deviation vectors, 16 perturbed orbits, the phi section, histories -- against the
    same cell without it, through the worker's own code path (run_cells), best of
    `repeats` interleaved runs; and the classification of a 10^4-cell grid (target: the
    analysis adds < 15% per cell)."""
    import xarray as xr

    from .analysis.classify import classify
    from .pipeline.cells import CellTask, build_starts, run_cells
    from .pipeline.config import load_config
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
    grid = xr.Dataset({V.status: ("cell", np.zeros(n, np.int8)),
                       **{k: ("cell", rng.uniform(0, 10, n)) for k in
                          (V.birkhoff_digits, V.birkhoff_digits_half, V.megno, V.sali,
                           V.frequency_diffusion)},
                       V.ftle: ("cell", rng.uniform(0, 0.2, n)),
                       V.t_end: ("cell", np.full(n, t_final))})
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

    from .pipeline.sweep import run_survey
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

    from .pipeline.sweep import run_survey
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
    import subprocess
    import sys
    out("")
    out("Peak memory of the process driving a survey (cells of t = 0.01, orbit + indicators, "
        "no section; the workers are separate processes)")
    for n in sizes:
        code = f"from survey.bench import _memory_run; print(*_memory_run({n}, {folder!r}))"
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True)
        peak, seconds, archive = map(float, res.stdout.split()[-3:])
        out(f"{n:>8d} cells: peak RSS {peak / 1024:7.1f} MiB, {seconds:6.1f} s, of which "
            f"writing the archive {archive:5.1f} s")


def _memory_run(n, folder):
    import resource

    from .pipeline.sweep import run_survey
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


# The command line run as `python -m survey` runs it, its phases recorded: wall-clock times
# (comparable across processes) at its first line, after its imports, and at its end, with
# run_survey's own timings; printed as JSON on the last line.
_CLI_PHASES = """
import json, sys, time
start = time.time()
from survey import cli
from survey.pipeline import sweep
imported = time.time()
timings, run = {}, sweep.run_survey
sweep.run_survey = lambda *a, **kw: run(*a, timings=timings, **kw)
code = cli.main(sys.argv[1:])
timings.pop("tasks", None)
print(json.dumps(dict(start=start, imported=imported, end=time.time(), code=code, **timings)))
"""


def user_env(**extra) -> dict:
    """The environment of a timed command: this one, but Python writing bytecode as it does
    by default (a development environment may set PYTHONDONTWRITEBYTECODE; survey's own
    modules, compiled from source on every start, then cost a command 0.05-0.1 s)."""
    import os
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, **extra}


def command_phases(argv) -> dict:
    """Seconds of a `python -m survey` command by phase: the interpreter's start, survey's
    imports, run_survey's phases (prepare -- the kernels loaded --, cluster, compute,
    shutdown, archive), and the rest (the regime summary; the exit without teardown is not
    run here)."""
    import json
    import subprocess
    import sys
    launched = time.time()
    done = subprocess.run([sys.executable, "-c", _CLI_PHASES, *argv], check=True,
                          capture_output=True, text=True, env=user_env())
    r = json.loads(done.stdout.strip().splitlines()[-1])
    phases = {"interpreter": r["start"] - launched, "imports": r["imported"] - r["start"]}
    phases.update({k: r[k] for k in ("prepare", "cluster", "compute", "shutdown", "archive")})
    phases["rest"] = r["end"] - r["imported"] - r["total"]
    return phases


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
    torus analysis; best of `repeats` interleaved runs. Targets: compute <= 0.5x heyoka,
    command line <= 1.0x without the torus analysis, <= 1.2x with it."""
    import subprocess
    import sys
    from pathlib import Path

    import xarray as xr

    from .pipeline.config import _to_toml
    from .pipeline.sweep import run_survey
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
            subprocess.run([sys.executable, "-m", "survey", "run", str(toml), "--no-report",
                            "--no-progress"], check=True, capture_output=True, env=user_env())
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
    out(f"survey / heyoka: compute {ratios['compute']:.2f}x (target <= 0.5x), command line "
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
    from .pipeline.cells import CellTask, build_starts, first_runs, torus_evidence
    from .pipeline.config import load_config
    runs = {}
    for analyse in (False, True):
        config = load_config({**cfg, "tori": {"extend": 0, "analyse": analyse}})
        ids = np.arange(0, config.n_cells, 2)
        task, starts = CellTask.of(config), build_starts(config, ids)
        first_runs(task.short(), ids[:1], starts[:1])
        runs[analyse] = (task, ids, starts)
    task, _, starts = runs[True]
    system = config.system()
    T, dt = config.tables["integration"]["t_final"], task.tori["sample_interval"]
    outs = integrate_batch(system, starts, T, t_fine=(np.arange(int(T / dt)) + 0.5) * dt)
    errors = [abs(system.energy(o.y) / system.energy(y0) - 1.0) for o, y0 in zip(outs, starts)]

    def analysis():
        for o, e in zip(outs, errors):
            torus_evidence(task, system, o.fine, e)
    best = {"off": math.inf, "on": math.inf, "analysis": math.inf}
    for _ in range(repeats):
        for key, analyse in (("off", False), ("on", True)):
            best[key] = min(best[key], _best_time(lambda: first_runs(*runs[analyse]), 1)[0])
        best["analysis"] = min(best["analysis"], _best_time(analysis, 1)[0])
    return {**best, "cells": len(starts)}


def _vector_doubles() -> int:
    """Doubles in one of this machine's SIMD vectors, from the features LLVM finds (a virtual
    machine may hide some of its CPU's: heyoka then recommends a width for the CPU's name that
    the vectors it may use do not hold)."""
    import llvmlite.binding as llvm
    features = llvm.get_host_cpu_features()
    return 8 if features.get("avx512f") else 4 if features.get("avx") else 2


def _heyoka_scan(cells, t_final, tols, dE_max):
    """heyoka's batch ensemble over the scan's starts at the loosest of `tols` whose largest
    relative energy error at t_final is not above dE_max, in batches of the SIMD width heyoka
    recommends or of the width of this machine's vectors, where they differ, whichever runs
    faster (on a virtual AMD EPYC that hides AVX-512 heyoka recommends 8 and runs the scan
    ~10% faster in 4): a runner giving (wall time, FTLE per cell), or {} without heyoka."""
    try:
        import heyoka as hy
    except ImportError:
        return {}
    from .catalog.indicators import IndicatorOptions
    system = System.create()
    n = system.n
    seed = IndicatorOptions().seed
    starts, E0 = [], []
    for delta in np.linspace(0.0, 10.0, cells):
        y0 = initial_state(system, "equilateral", delta=float(delta))
        w0 = deviation_vectors(system, y0, 1, seed)[0]
        starts.append(np.concatenate([y0, w0 / np.linalg.norm(w0), [0.0, 0.0, 0.0]]))
        E0.append(system.energy(y0))
    recommended = hy.recommended_simd_size()

    def runner(tol, width):
        batches = -(-cells // width)
        padded = np.array(starts + [starts[-1]] * (batches * width - cells))
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
            final = np.concatenate([np.array(r[0].state).T for r in done])[:cells]
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
    for width in {_vector_doubles()} - {recommended}:
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
            "trials": trials, "batches": -(-cells // width)}


def default_cell(t_final=2000.0, repeats=5, folder="results/bench", out=print):
    """A default survey cell (the README's defaults: 2 deviation vectors, 16 perturbed
    orbits, the phi section, histories, the torus analysis) through the worker's code path,
    against the same orbit with one tangent vector alone (`integrate`), best of `repeats`
    interleaved runs (the issue's target: at most 1.5x), and per orbit of the cell (its 18
    orbits -- 2 deviation vectors' and 16 perturbed -- run as SIMD lanes)."""
    from .pipeline.cells import CellTask, build_starts, jobs_per_cell, run_cells
    from .pipeline.config import load_config
    system = System.create()
    rows = []
    for label, fam, params in CASES:
        config = load_config({"survey": {"output": f"{folder}/cell.nc"},
                              "initial": {"family": fam, **params},
                              "integration": {"t_final": t_final},
                              "section": {"coordinate": "phi"}})
        task, starts = CellTask.of(config), build_starts(config)
        y0 = starts[0]
        w0 = deviation_vectors(system, y0, 1, seed=0)
        run_cells(task.short(), [0], starts)
        best = [math.inf, math.inf]
        for _ in range(repeats):
            for k, go in enumerate((lambda: run_cells(task, [0], starts),
                                    lambda: integrate(system, y0, t_final, tangents=w0))):
                t = time.perf_counter()
                go()
                best[k] = min(best[k], time.perf_counter() - t)
        rows.append((label, *best, jobs_per_cell(task)))
    out("")
    out(f"Default survey cell against its orbit with one tangent vector (t = {t_final:g}, best "
        f"of {repeats} interleaved runs; target: <= 1.5x)")
    out(f"{'case':26s} {'cell s':>8s} {'orbit+1 s':>10s} {'ratio':>7s} {'orbits':>7s} "
        f"{'per orbit':>10s}")
    for label, cell, orbit, orbits in rows:
        out(f"{label:26s} {cell:8.3f} {orbit:10.3f} {cell / orbit:6.2f}x {orbits:7d} "
            f"{cell / orbit / orbits:9.2f}x")
    return rows


@leaf
def _rhs_loop(Y, K, W, reps, L, masses, d, measure, prof, par, n_tan, rb):
    """reps times the 12 right-hand-side evaluations of a step of L lanes, at one state (rb:
    the reduced states' mass ratios, as the driver runs the paper's systems), into K's
    rows; W: the workspace. Without reference counting, as the driver (the rows' views
    would each cost an atomic increment and decrement)."""
    for _ in range(reps):
        for s in range(12):
            rhs_lanes(0.0, Y, K[s], L, masses, d, measure, prof, par, n_tan, W, rb)
    return K[11, 0]


@kernel
def _stage_loop(Y, reps, h, L, masses, d, measure, prof, par, n_tan, rb):
    """reps times a step's stages and error norms of L lanes, from one state."""
    nf = Y.size // L
    K, YT, YN = np.zeros((16, Y.size)), np.zeros(Y.size), np.zeros(Y.size)
    W, S = np.zeros(workspace_size(L, nf)), np.zeros(2 * (nf + 1) * L)
    H, err = np.full(L, h), np.zeros(L)
    HH = np.full(Y.size, h)
    rhs_lanes(0.0, Y, K[0], L, masses, d, measure, prof, par, n_tan, W, rb)
    acc = 0.0
    for _ in range(reps):
        stages(masses, d, measure, prof, par, n_tan, L, Y, HH, K, YT, YN, W, rb)
        error_norms(Y, YN, K, L, state_size(masses, d, rb), 1e-12, 1e-12, H, err, S)
        acc += err[0]
    return acc


@helper
def _plain_rhs(y, dy):
    """The paper's system written plainly for the step baseline: three unit masses in the
    plane, U = P^2/2, the relative motion (bodies 0 and 1 in the centre-of-mass frame, the
    third at -(q0 + q1)) and one tangent vector; 16 components, as survey integrates it."""
    ux, uy, vx, vy = y[0], y[1], y[2], y[3]
    wx, wy = -(ux + vx), -(uy + vy)
    ax, ay, bx, by, cx, cy = vx - ux, vy - uy, wx - vx, wy - vy, ux - wx, uy - wy
    L1, L2, L3 = math.sqrt(ax * ax + ay * ay), math.sqrt(bx * bx + by * by), \
        math.sqrt(cx * cx + cy * cy)
    r1, r2, r3 = 1.0 / L1, 1.0 / L2, 1.0 / L3
    e1x, e1y, e2x, e2y, e3x, e3y = ax * r1, ay * r1, bx * r2, by * r2, cx * r3, cy * r3
    U1 = L1 + L2 + L3                               # U' = P, U'' = 1
    dy[0], dy[1], dy[2], dy[3] = y[4], y[5], y[6], y[7]
    dy[4], dy[5] = U1 * (e1x - e3x), U1 * (e1y - e3y)
    dy[6], dy[7] = U1 * (e2x - e1x), U1 * (e2y - e1y)
    s1, s2, s3 = U1 * r1, U1 * r2, U1 * r3
    dux, duy, dvx, dvy = y[8], y[9], y[10], y[11]
    dwx, dwy = -(dux + dvx), -(duy + dvy)
    p1x, p1y, p2x, p2y, p3x, p3y = dvx - dux, dvy - duy, dwx - dvx, dwy - dvy, dux - dwx, \
        duy - dwy
    d1, d2, d3 = e1x * p1x + e1y * p1y, e2x * p2x + e2y * p2y, e3x * p3x + e3y * p3y
    dP = d1 + d2 + d3
    c1, c2, c3 = dP - s1 * d1, dP - s2 * d2, dP - s3 * d3
    g1x, g1y = c1 * e1x + s1 * p1x, c1 * e1y + s1 * p1y
    g2x, g2y = c2 * e2x + s2 * p2x, c2 * e2y + s2 * p2y
    g3x, g3y = c3 * e3x + s3 * p3x, c3 * e3y + s3 * p3y
    dy[8], dy[9], dy[10], dy[11] = y[12], y[13], y[14], y[15]
    dy[12], dy[13], dy[14], dy[15] = g1x - g3x, g1y - g3y, g2x - g1x, g2y - g1y


@helper
def _plain_stage(y, yt, K, h, comb, s):
    """Stage s of `_plain_dop853` from the tableau row comb (a helper, as numba cannot loop
    over the rows: each is a tuple of its own length)."""
    for i in range(y.size):
        yt[i] = fma(h, _dot(K, i, comb), y[i])
    _plain_rhs(yt, K[s])


@kernel
def _plain_dop853(z, t1, tol, h):
    """The baseline of a scalar step: DOP853 as plain code for one orbit of `_plain_rhs` --
    one function, fixed sizes, the right-hand side inlined, survey's tableau sums, error
    norm (over the orbit's 8 components) and step control, the tangent's log norm summed
    at each step, and nothing else (no events, samples, budgets, statuses or lanes).
    Returns the attempted steps, the sum (kept so the compiler cannot drop it) and the
    final state."""
    n = 16
    y, yt, yn, K = z.copy(), np.empty(n), np.empty(n), np.empty((13, n))
    _plain_rhs(y, K[0])
    t, err_old, attempts, acc = 0.0, ERR_FLOOR_ROOT, 0, 0.0
    while t < t1:
        if t + h >= t1:
            h = t1 - t
        attempts += 1
        _plain_stage(y, yt, K, h, A2, 1)
        _plain_stage(y, yt, K, h, A3, 2)
        _plain_stage(y, yt, K, h, A4, 3)
        _plain_stage(y, yt, K, h, A5, 4)
        _plain_stage(y, yt, K, h, A6, 5)
        _plain_stage(y, yt, K, h, A7, 6)
        _plain_stage(y, yt, K, h, A8, 7)
        _plain_stage(y, yt, K, h, A9, 8)
        _plain_stage(y, yt, K, h, A10, 9)
        _plain_stage(y, yt, K, h, A11, 10)
        _plain_stage(y, yt, K, h, A12, 11)
        for i in range(n):
            yn[i] = fma(h, _dot(K, i, B), y[i])
        e3 = e5 = 0.0
        for i in range(8):
            isk = 1.0 / fma(tol, max(abs(y[i]), abs(yn[i])), tol)
            er3 = fma(-BHH3, K[11, i], fma(-BHH2, K[8, i], fma(-BHH1, K[0, i], _dot(K, i, B))))
            er3, er5 = er3 * isk, _dot(K, i, ER) * isk
            e3, e5 = e3 + er3 * er3, e5 + er5 * er5
        err = abs(h) * e5 / math.sqrt(8 * (e5 + 0.01 * e3)) if e5 + e3 > 0.0 else 0.0
        r8, r128 = portable.root8(max(err, 1e-10))
        _plain_rhs(yn, K[12])
        if err <= 1.0:
            t += h
            for i in range(n):
                y[i], K[0, i] = yn[i], K[12, i]
            w = 0.0
            for i in range(8, n):
                w += y[i] * y[i]
            acc += portable.log(w) * h
            fac = 0.9 * r128 / r8 * portable.ipow(err_old, BETA_ROOTS)
            err_old = r128 if err >= 1e-4 else ERR_FLOOR_ROOT
            h *= min(6.0, max(1.0 / 3.0, fac))
        else:
            h *= max(1.0 / 3.0, 0.9 / r8)
    return attempts, acc, y


def plain_step(t_final, repeats):
    """ns per attempted step of `_plain_dop853` on the chaotic orbit of CASES, with a
    tangent vector (best of `repeats`), its steps, and its relative motion and survey's at
    t_final (8 components each)."""
    system = System.create()
    y0 = initial_state(system, CASES[0][1], **CASES[0][2])
    w = deviation_vectors(system, y0, 1, seed=0)
    frame = Frame.of(system, y0[None], w[None], [])
    z = frame.reduce(np.concatenate([y0, w[0]])[None], 1)[0]
    _plain_dop853(z, 1.0, 1e-12, 1e-3)
    best, (steps, _, y) = _best_time(lambda: _plain_dop853(z, t_final, 1e-12, 1e-3), repeats)
    ref = integrate(system, y0, t_final)
    return 1e9 * best / steps, steps, y[:8], frame.reduce(ref.y[None], 0)[0]


def step_costs(t_final=2000.0, repeats=5, lanes=(1, 4, 8, 16), out=print):
    """Where a DOP853 step's time goes, per orbit-step, on the paper's two orbits, for one
    orbit alone and for lanes of copies of it: the right-hand-side evaluations (12 per
    accepted step), the stage combinations with the error norm (the same 11 evaluations
    subtracted), and the rest of the driver (step control, events, samples, tangent
    renormalisation, MEGNO), as shares of `integrate_batch`'s time; compiled loops over
    survey's own kernels at the orbit's start, best of `repeats` interleaved runs."""
    system = System.create()
    rows = []
    for label, family, params in CASES:
        y0 = initial_state(system, family, **params)
        for n_tan in (0, 1):
            w = deviation_vectors(system, y0, n_tan, seed=0) if n_tan else None
            one = integrate(system, y0, t_final, tangents=w, megno=n_tan > 0)
            steps = one.n_steps + one.n_rejected
            h = t_final / one.n_steps
            args = system.kernel_args
            for L in lanes:
                starts = np.repeat(y0[None], L, 0)
                tangents = np.repeat(w[None], L, 0) if n_tan else None
                # the states the driver integrates: each orbit's relative motion
                frame = Frame.of(system, starts, np.zeros((L, n_tan, y0.size))
                                  if tangents is None else tangents, [])
                Y = np.ascontiguousarray(frame.reduce(
                    starts if tangents is None else
                    np.concatenate([starts, tangents.reshape(L, -1)], 1), n_tan).T).ravel()
                K, W = np.zeros((16, Y.size)), np.zeros(workspace_size(L, Y.size // L))
                _rhs_loop(Y, K, W, 1, L, *args, n_tan, frame.ratios)
                _stage_loop(Y, 1, h, L, *args, n_tan, frame.ratios)
                reps = max(1, steps // L)
                # interleaved, so a slow spell of the machine does not fall on one of three
                best = [math.inf] * 3
                for _ in range(repeats):
                    for k, go in enumerate((
                            lambda: _rhs_loop(Y, K, W, reps, L, *args, n_tan,
                                              frame.ratios),
                            lambda: _stage_loop(Y, reps, h, L, *args, n_tan,
                                                frame.ratios),
                            lambda: integrate_batch(system, starts, t_final, tangents=tangents,
                                                    megno=n_tan > 0, lanes=L))):
                        best[k] = min(best[k], _best_time(go, 1)[0])
                t_rhs, t_stage = best[0] * steps / (reps * L), best[1] * steps / (reps * L)
                t_all = best[2] / L
                rows.append((label, n_tan, L, steps, t_all, t_rhs, t_stage - t_rhs * 11 / 12))
    out("")
    out(f"Where a step goes (t = {t_final:g}, tol 1e-12; per orbit-step, ns; shares of "
        "integrate_batch's time; L orbits as SIMD lanes)")
    out(f"{'case':26s} {'tangents':>8s} {'lanes':>5s} {'steps':>7s} {'step ns':>8s} "
        f"{'12 rhs':>7s} {'stages+norm':>12s} {'rest':>6s}")
    for label, n_tan, L, steps, t_all, t_rhs, t_comb in rows:
        ns = 1e9 / steps
        rest = t_all - t_rhs - t_comb
        out(f"{label:26s} {n_tan:8d} {L:5d} {steps:7d} {t_all * ns:8.0f} "
            f"{t_rhs / t_all:7.0%} {t_comb / t_all:12.0%} {rest / t_all:6.0%}")
    plain, plain_steps, *_ = plain_step(t_final, repeats)
    alone = next(1e9 * t_all / steps for label, n_tan, L, steps, t_all, *_ in rows
                 if label == CASES[0][0] and n_tan == 1 and L == 1)
    out(f"the same orbit with a tangent in plain scalar code (bench._plain_dop853: one "
        f"function, the right-hand side inlined, no events, samples or lanes): {plain:.0f} ns "
        f"per attempted step ({plain_steps} steps); survey's one orbit alone {alone:.0f} ns, "
        f"{alone / plain:.2f}x (target <= 0.45 us)")
    return rows, plain


def _timed_command(args, env=None):
    """(seconds to the first output on stderr, seconds to the end) of a command whose
    stderr is a terminal (the command line speaks to terminals only)."""
    import os
    import pty
    import subprocess
    master, slave = pty.openpty()
    start = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=slave, env=env)
    os.close(slave)
    first = math.nan
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:         # the command closed its end
            break
        if not chunk:
            break
        if math.isnan(first):
            first = time.perf_counter() - start
    proc.wait()
    total = time.perf_counter() - start
    os.close(master)
    if proc.returncode:
        raise RuntimeError(f"{' '.join(args)} exited with {proc.returncode}")
    return first, total


def fixed_costs(folder="results/bench", repeats=3, out=print, cold=True):
    """What a survey costs beside its cells: a 1-cell survey ('sides', default settings
    otherwise, t = 10) end to end with numba's disk cache warm, by phase, best of
    `repeats`; and (`cold`) the command line compiling every kernel into an empty cache
    (what a new machine's first run costs), with the time to its first word."""
    from .pipeline.sweep import run_survey
    cfg = {"survey": {"name": "bench-1cell", "output": f"{folder}/bench-1cell.nc"},
           "initial": {"family": "sides"}, "integration": {"t_final": 10.0}}
    best = None
    for _ in range(repeats):
        timings = {}
        run_survey(cfg, progress=False, timings=timings)
        if best is None or timings["total"] < best["total"]:
            best = timings
    import subprocess
    import sys
    from pathlib import Path
    toml = Path(folder) / "bench-1cell.toml"
    toml.write_text(f'[survey]\nname = "bench-1cell"\noutput = "{toml.with_suffix(".nc")}"\n'
                    '[initial]\nfamily = "sides"\n[integration]\nt_final = 10.0\n')
    run = [sys.executable, "-m", "survey", "run", str(toml), "--no-report", "--no-progress"]
    command = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run(run, check=True, capture_output=True, env=user_env())
        command = min(command, time.perf_counter() - t)
    first = compiling = math.nan
    if cold:
        import tempfile
        with tempfile.TemporaryDirectory() as cache:
            first, compiling = _timed_command(run, user_env(NUMBA_CACHE_DIR=cache))
    out("")
    out(f"Fixed costs: a 1-cell survey ('sides', t = 10, warm cache, best of {repeats}), "
        "seconds")
    out("in process: " + "  ".join(f"{k} {v:.2f}" for k, v in best.items() if k != "tasks"))
    out(f"python -m survey run (interpreter, imports and regime summary included): "
        f"warm {command:.2f}" + (f"; cold (every kernel compiled into an empty cache) "
                                 f"{compiling:.1f}, its first word on the terminal after "
                                 f"{first:.2f}" if cold else ""))
    best.update(command=command, cold=compiling, first_word=first)
    return best


def newton_step(repeats=5, out=print):
    """What one step of the periodic-orbit shooting costs against the orbit with its full
    tangent block (2n vectors, in the error control) over the period: the figure-eight
    under gravity and the areal homographic orbit, best of `repeats` interleaved runs. A
    step is that integration plus the linear algebra; the target is about 1x."""
    from .numerics import periodic
    from .physics.families import initial_state
    gravity = System(np.ones(3), 2, make_potential("gravity", {"G": 1.0}, "pair"))
    x1, v3 = np.array([0.97000436, -0.24308753]), np.array([-0.93240737, -0.86473146])
    areal = System.create(potential="areal_barrier")
    cases = [("figure-eight (gravity)", gravity,
              gravity.state([x1, -x1, [0.0, 0.0]], [-v3 / 2, -v3 / 2, v3]), 6.33, False),
             ("areal homographic (rotating)", areal,
              initial_state(areal, "equilateral", side=3 ** 0.5, delta=0.0, energy=8.0),
              1.5, True)]
    out("")
    out(f"Newton shooting: one step against the orbit with its full tangent block (best of "
        f"{repeats}; target about 1x)")
    out(f"{'orbit':30s} {'runs':>5s} {'per run ms':>11s} {'orbit+2n ms':>11s} {'ratio':>6s}")
    rows = []
    for label, system, y0, guess, rotating in cases:
        found = periodic.periodic_orbit(system, y0, guess, rotating)
        # integrations: one per step, the last check, and for a rotating orbit the first
        # guess of its angle
        steps = found.residuals.size + int(rotating)
        best = [math.inf, math.inf]
        for _ in range(repeats):
            for k, go in enumerate((
                    lambda: periodic.periodic_orbit(system, y0, guess, rotating),
                    lambda: periodic._return(system, found.state, found.period, 1e-13))):
                t = time.perf_counter()
                go()
                best[k] = min(best[k], time.perf_counter() - t)
        per_step = best[0] / steps
        rows.append((label, steps, per_step, best[1]))
        out(f"{label:30s} {steps:5d} {1e3 * per_step:11.2f} {1e3 * best[1]:11.2f} "
            f"{per_step / best[1]:5.2f}x")
    return rows
