"""What survey's own parts cost beside the bare orbit: indicators, the torus analysis, the
general path of sums of terms, a default cell, the fixed costs of a survey, a Newton step."""
from __future__ import annotations


import contextlib
import math
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..catalog.variables import V
from ..numerics.indicators import deviation_vectors
from ..numerics.integrate import Frame, integrate, integrate_batch
from ..physics.families import initial_state
from ..physics.lanes import SIMD_LANES
from ..physics.system import System
from ..physics.terms import make_expression, make_potential
from .common import CASES, checked, timed_command, user_env


def indicator_overhead(t_final=2000.0, repeats=7, deviations=2, out=print):
    """Cost of MEGNO + the phi = pi/2 section + 64-point indicator histories over the bare
    orbit + tangent-vector integration (same vectors, same steps), per paper orbit. The
    variants are timed interleaved and each keeps its best time, which cancels most of the
    machine's drift."""
    from ..numerics.sections import section_event
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
    def model(self):
        model = super().model
        return model._replace(par=np.concatenate([model.par, [0.0] * 3]).reshape(1, 5))


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
                        ("yukawa", "the paper's P^2/2 + Yukawa pairs"),
                        ("3-D", "P^2/2 of three bodies in 3-D"),
                        ("four", "P^2/2 of four bodies in the plane (4 triangles)")):
        alone, many = lanes[name]
        out(f"  {label:55s} {alone:6.0f} {many:6.0f}  ({alone / many:.1f}x)")
    out(f"  the paper's 'sides' orbit in {SIMD_LANES} lanes: {lanes['paper']:.0f} ns")
    out(f"The same terms written as formulas (their programs run over the lanes), on the same "
        f"starts, ns per attempted orbit-step in {SIMD_LANES} lanes (target: formula <= 1.3x "
        f"built-in):")
    for name, label in (("four", "P^2/2 of four bodies as 'P**2/2'"),
                        ("mixed", "P^2/2 + Lennard-Jones pairs as '4*((1/r)**12 - (1/r)**6)'"),
                        ("yukawa", "P^2/2 + Yukawa pairs as 'exp(-r)/r'")):
        builtin, formula = lanes[name][1], lanes[f"{name} formula"][1]
        out(f"  {label:60s} built-in {builtin:6.0f}  formula {formula:6.0f}  "
            f"({formula / builtin:.2f}x)")
    return rows


def _others_in_lanes(repeats, orbits=64, t_final=100.0) -> dict:
    """ns per attempted orbit-step, alone and in SIMD_LANES lanes, of systems other than the
    paper's -- the LJAT trimer and the paper's P^2/2 beside Lennard-Jones or Yukawa pairs
    (orbits near the equilateral triangle), P^2/2 of three bodies in 3-D (the triangle
    tilted out of the plane) and of four in the plane (near a square), seeded momenta --
    the pairs beside P^2/2 and the four bodies' P^2/2 also written as formulas, on the
    same starts -- and of the paper's 'sides' orbit in as many lanes, best of `repeats`."""
    rng = np.random.default_rng(3)
    triangle = np.array([[0.0, 0.0, 0.0], [1.12, 0.0, 0.0], [0.56, 0.97, 0.0]])
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    P2 = make_potential("perimetric_power")
    systems = {"ljat": (System(np.ones(3), 2, (
        make_potential("lennard_jones", {}, "pair"),
        make_potential("axilrod_teller", {"strength": 0.3}))), triangle[:, :2]),
        "mixed": (System(np.ones(3), 2, (P2, make_potential("lennard_jones", {}, "pair"))),
                  triangle[:, :2]),
        "yukawa": (System(np.ones(3), 2, (P2, make_potential("yukawa", {}, "pair"))),
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
    # the same terms written as formulas, on the same starts as their built-in systems
    formulas = {"four": System(np.ones(4), 2, (make_expression("triplet", "P**2/2"),)),
                "mixed": System(np.ones(3), 2, (P2, make_expression(
                    "pair", "4*((1/r)**12 - (1/r)**6)"))),
                "yukawa": System(np.ones(3), 2, (P2, make_expression("pair", "exp(-r)/r")))}
    out = dict(orbits=orbits, t=t_final, paper=per_step(paper, sides, SIMD_LANES, t_final))
    for name, (system, at) in systems.items():
        q = at + 0.02 * rng.normal(size=(orbits,) + at.shape)
        p = 0.3 * rng.normal(size=(orbits,) + at.shape)
        p -= p.mean(1, keepdims=True)
        y0s = np.array([system.state(*qp) for qp in zip(q, p)])
        out[name] = (per_step(system, y0s[:4], 1, t_final),
                     per_step(system, y0s, SIMD_LANES, t_final))
        if name in formulas:
            out[f"{name} formula"] = (per_step(formulas[name], y0s[:4], 1, t_final),
                                      per_step(formulas[name], y0s, SIMD_LANES, t_final))
    return out


def torus_overhead(t_final=2000.0, repeats=6, out=print):
    """The torus analysis (Birkhoff digits, frequencies, resonance) per default survey cell
    -- 2 deviation vectors, 16 perturbed orbits, the phi section, histories -- against the
    same cell without it, through the worker's own code path (run_cells), best of
    `repeats` interleaved runs; and the classification of a 10^4-cell grid (target: the
    analysis adds < 15% per cell)."""
    import xarray as xr

    from ..analysis.classify import classify
    from ..pipeline.cells import CellTask, build_starts, run_cells
    from ..pipeline.config import load_config
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


def default_cell(t_final=2000.0, repeats=5, folder="results/bench", out=print):
    """A default survey cell (the README's defaults: 2 deviation vectors, 16 perturbed
    orbits, the phi section, histories, the torus analysis) through the worker's code path,
    against the same orbit with one tangent vector alone (`integrate`), best of `repeats`
    interleaved runs (the issue's target: at most 1.5x), and per orbit of the cell (its 18
    orbits -- 2 deviation vectors' and 16 perturbed -- run as SIMD lanes)."""
    from ..pipeline.cells import CellTask, build_starts, jobs_per_cell, run_cells
    from ..pipeline.config import load_config
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


def compile_times(config=None) -> list[tuple[str, float, float]]:
    """Where a first run's compiling goes, by numba's own compile events: the kernels a
    survey cell compiles (cells.warm_up and warm_beside, in this process) from an empty
    cache, each function's (name, seconds with what it compiled, seconds of its own).
    Run it in a process of its own with NUMBA_CACHE_DIR an empty folder (fixed_costs)."""
    from numba.core import event

    from ..pipeline.cells import CellTask, GridStarts, warm_beside, warm_up
    from ..pipeline.config import load_config

    class Listener(event.Listener):
        def __init__(self):
            self.open, self.rows = [], []

        def on_start(self, ev):
            f = ev.data["dispatcher"].py_func
            self.open.append([f"{f.__module__.removeprefix('survey.')}.{f.__qualname__}",
                              time.perf_counter(), 0.0])

        def on_end(self, ev):
            name, began, inner = self.open.pop()
            took = time.perf_counter() - began
            if self.open:
                self.open[-1][2] += took
            self.rows.append((name, took, took - inner))

    config = load_config(config or str(Path(__file__).parents[1] / "default.toml"),
                         check_output=False)
    task, starts = CellTask.of(config), GridStarts(config)
    first = starts.first(np.arange(config.n_cells))
    at, listener = starts(first), Listener()
    with event.install_listener("numba:compile", listener):
        warm_up(task, first, at)
        warm_beside(task, first, at)
    return listener.rows


def fixed_costs(folder="results/bench", repeats=3, out=print, cold=True, commands=None):
    """What a survey costs beside its cells: a 1-cell survey ('sides', default settings
    otherwise, t = 10) end to end with numba's disk cache warm, by phase, best of
    `repeats`; and (`cold`) the command line compiling every kernel into an empty cache
    (what a new machine's first run costs), with the time to its first word; and whether
    every command (or those given: command_talk) talks on a terminal."""
    from ..pipeline.sweep import run_survey
    cfg = {"survey": {"name": "bench-1cell", "output": f"{folder}/bench-1cell.nc"},
           "initial": {"family": "sides"}, "integration": {"t_final": 10.0}}
    best = None
    for _ in range(repeats):
        timings = {}
        run_survey(cfg, progress=False, timings=timings)
        if best is None or timings["total"] < best["total"]:
            best = timings
    import sys
    toml = Path(folder) / "bench-1cell.toml"
    toml.write_text(f'[survey]\nname = "bench-1cell"\noutput = "{toml.with_suffix(".nc")}"\n'
                    '[initial]\nfamily = "sides"\n[integration]\nt_final = 10.0\n')
    run = [sys.executable, "-m", "survey", "run", str(toml), "--no-report", "--no-progress"]
    command = math.inf
    for _ in range(repeats):
        t = time.perf_counter()
        checked(run)
        command = min(command, time.perf_counter() - t)
    first = compiling = math.nan
    rows = []
    if cold:
        import json
        import tempfile
        with tempfile.TemporaryDirectory() as cache:
            first, compiling, _ = timed_command(run, user_env(NUMBA_CACHE_DIR=cache))
        with tempfile.TemporaryDirectory() as cache:
            code = ("import json; from survey.bench.costs import compile_times; "
                    "print(json.dumps(compile_times()))")
            res = checked([sys.executable, "-c", code], user_env(NUMBA_CACHE_DIR=cache))
            rows = json.loads(res.splitlines()[-1])
    out("")
    out(f"Fixed costs: a 1-cell survey ('sides', t = 10, warm cache, best of {repeats}), "
        "seconds")
    out("in process: " + "  ".join(f"{k} {v:.2f}" for k, v in best.items() if k != "tasks"))
    out(f"python -m survey run (interpreter, imports and regime summary included): "
        f"warm {command:.2f}" + (f"; cold (every kernel compiled into an empty cache) "
                                 f"{compiling:.1f}, its first word on the terminal after "
                                 f"{first:.2f}" if cold else ""))
    if rows:
        own = sorted(rows, key=lambda r: -r[2])
        out(f"where compiling goes (the default survey's kernels in one process from an "
            f"empty cache, numba's compile events; {sum(r[2] for r in rows):.1f} s in all): "
            "seconds of its own (with what it compiled)")
        out("  " + "; ".join(f"{name} {mine:.1f} ({took:.1f})" for name, took, mine in own[:8]))
        again = Counter(name for name, _, _ in rows if not name.startswith("numba"))
        again = {name: k for name, k in again.items() if k > 1}
        out("survey's functions compiled more than once (a literal, an array's layout or "
            "another type: a second compilation of their code): " + (", ".join(
                f"{name} x{k}" for name, k in sorted(again.items())) or "none"))
    best.update(command=command, cold=compiling, first_word=first, compiling=rows,
                talk=command_talk(folder, cold=cold, commands=commands, out=out))
    return best


def talking_commands(folder) -> list[tuple[str, list[str]]]:
    """Every command a user runs, as (name, arguments) in an order that makes each one's
    input first: the default survey, its report, figures and verification, an orbit, the
    relative equilibria and a periodic orbit of shipped workflows, and reproduce's default
    into a folder of its own."""
    folder = Path(folder).resolve()
    archive, flows = str(folder / "talk" / "default.nc"), Path(__file__).parents[2] / "workflows"
    return [("run", ["run", "--output", archive]),
            ("report", ["report", archive, "--out", str(folder / "talk" / "report")]),
            ("plot", ["plot", archive, "--out", str(folder / "talk" / "plot")]),
            ("verify", ["verify", archive, "--cells", "2"]),
            ("orbit", ["orbit", "--family", "sides", "--t-final", "100"]),
            ("equilibria", ["equilibria", str(flows / "rotating_triangle_equilibria.toml")]),
            ("periodic", ["periodic", str(flows / "figure_eight_periodic.toml")]),
            ("reproduce", ["reproduce", "--only", "default", "--workflows", str(flows),
                           "--results", str(folder / "talk" / "results")])]


def command_talk(folder, cold=True, commands=None, out=print) -> dict:
    """Whether every command talks on a terminal: each run as a user runs it, with a
    terminal for its output, warm (numba's cache holding its kernels) and (`cold`) with an
    empty cache of its own, timed word by word -- its first word and its longest silence
    (the target: none over 2 s)."""
    import sys
    import tempfile
    commands = commands or talking_commands(folder)
    (Path(folder) / "talk").mkdir(parents=True, exist_ok=True)
    rows = {}
    for name, args in commands:
        argv = [sys.executable, "-m", "survey", *args]
        cold_run = None
        if cold:
            with tempfile.TemporaryDirectory() as cache:
                cold_run = timed_command(argv, user_env(NUMBA_CACHE_DIR=cache))
        timed_command(argv, user_env())             # fills the cache for the warm run
        rows[name] = (cold_run, timed_command(argv, user_env()))
    out("")
    out("Every command on a terminal: first word / longest silence / whole, seconds "
        "(target: silent at most 2 s)" + ("; cold: an empty kernel cache of its own" if cold
                                          else ""))
    for name, (c, w) in rows.items():
        cold_text = f"cold {c.first:5.2f} / {c.silence:5.2f} / {c.total:6.1f}   " if c else ""
        out(f"  {name:<11} {cold_text}warm {w.first:5.2f} / {w.silence:5.2f} / {w.total:6.1f}")
    loudest = max(max(w.silence, c.silence if c else 0.0) for c, w in rows.values())
    out(f"  longest silence of any command: {loudest:.2f} s "
        f"({'met' if loudest <= 2.0 else 'not met'})")
    return rows


def newton_step(repeats=5, out=print):
    """What one step of the periodic-orbit shooting costs against the orbit with its full
    tangent block (2n vectors, in the error control) over the period: the figure-eight
    under gravity and the areal homographic orbit, best of `repeats` interleaved runs. A
    step is that integration plus the linear algebra; the target is about 1x."""
    from ..numerics import periodic
    from ..physics.families import initial_state
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
                    lambda: periodic.flow_map(system, found.state, found.period, 1e-13))):
                t = time.perf_counter()
                go()
                best[k] = min(best[k], time.perf_counter() - t)
        per_step = best[0] / steps
        rows.append((label, steps, per_step, best[1]))
        out(f"{label:30s} {steps:5d} {1e3 * per_step:11.2f} {1e3 * best[1]:11.2f} "
            f"{per_step / best[1]:5.2f}x")
    return rows
