"""Command line: `python -m survey <command>`."""
from __future__ import annotations

import argparse
import sys


def _bench(args):
    from . import bench
    parts = set(args.only or ["integrator", "indicators", "tori", "survey", "memory"])
    if "integrator" in parts:
        bench.run(t_final=args.t_final, t_scipy=args.t_scipy, repeats=args.repeats)
    if "indicators" in parts:
        bench.indicator_overhead(t_final=args.t_final)
    if "tori" in parts:
        bench.torus_overhead(t_final=args.t_final)
    if "survey" in parts:
        bench.survey_scaling()
    if "memory" in parts:
        bench.survey_memory()
    return 0


def _orbit(args):
    """Integrate one family member with a tangent vector and report what it conserved."""
    import time

    import numpy as np

    from .dynamics import System
    from .families import initial_state
    from .indicators import deviation_vectors
    from .integrator import integrate

    from .config import ConfigError
    from .integrator import RTOL_MIN

    params = {}
    for item in args.param:
        key, _, value = item.partition("=")
        try:
            params[key] = float(value)
        except ValueError:
            raise ConfigError(f"--param {item}", "expected KEY=NUMBER") from None
        if not np.isfinite(params[key]):
            raise ConfigError(f"--param {item}", "the value must be a finite number")
    if not (np.isfinite(args.t_final) and args.t_final > 0):
        raise ConfigError("--t-final", f"must be a finite number > 0, got {args.t_final!r}")
    if not RTOL_MIN <= args.tol < 1:
        raise ConfigError("--tol", f"must be in [{RTOL_MIN:.2g}, 1) (double precision cannot "
                                   f"honour less), got {args.tol!r}")
    try:
        system = System.create(potential=args.potential)
        y0 = initial_state(system, args.family, **params)
    except ValueError as exc:
        raise ConfigError("orbit", str(exc)) from None
    E0, J0 = system.energy(y0), system.angular_momentum(y0)
    t_eval = np.linspace(0.0, args.t_final, 1001)
    start = time.perf_counter()
    w0 = deviation_vectors(system, y0, 1, seed=0)[0]
    integrate(system, y0, 1e-3, tangents=w0, t_eval=t_eval[:1])
    print(f"compiled kernels ready in {time.perf_counter() - start:.1f} s "
          "(cached on disk after the first run)")
    start = time.perf_counter()
    out = integrate(system, y0, args.t_final, tangents=w0,
                    t_eval=t_eval, rtol=args.tol, atol=args.tol)
    wall = time.perf_counter() - start
    done = ~np.isnan(out.samples[:, 0])
    s = out.samples[done]
    print(f"{args.family} {params or ''} with {system.potential.describe()}")
    print(f"E = {E0:.10g}, J = {J0:.10g}; integrated to t = {out.t:g}: {out.status.name}, "
          f"{out.n_steps} steps, {out.n_rhs} RHS evaluations, {wall:.2f} s")
    print(f"max |E/E0 - 1| = {np.abs(system.energy(s) / E0 - 1).max():.2e}, "
          f"max |J - J0| = {np.abs(system.angular_momentum(s) - J0).max():.2e}, "
          f"max |p_total| = {np.abs(system.momentum(s)).max():.2e}")
    print(f"finite-time Lyapunov exponent ln(|w(t)|/|w0|)/t = {out.log_growth[0] / out.t:.5f}")
    return 0


def _run(args):
    from pathlib import Path

    from .config import ensure_writable, load_config, parse_config
    from .sweep import run_survey
    if args.config is None:
        text = (Path(__file__).parent / "default.toml").read_text()
        config = parse_config(text, "embedded default (survey/default.toml)")
    else:
        config = load_config(args.config)
    if args.output:
        ensure_writable(Path(args.output))
        config.tables["survey"]["output"] = args.output
    progress = False if args.no_progress else None
    path = run_survey(config, workers=args.workers, scheduler=args.scheduler,
                      progress=progress, command="python -m survey " + " ".join(sys.argv[1:]))
    print(f"wrote {path} ({config.n_cells} cells)")
    import xarray as xr

    from .tori import summary
    with xr.open_dataset(path) as ds:
        print("\n".join(summary(ds)))
    return 0


def _verify(args):
    from .sweep import verify
    if args.cells < 1:
        from .config import ConfigError
        raise ConfigError("--cells", f"must be >= 1, got {args.cells}")
    ok, lines = verify(args.archive, cells=args.cells)
    print("\n".join(lines))
    return 0 if ok else 1


def build_parser():
    parser = argparse.ArgumentParser(prog="python -m survey",
                                     description="Order and chaos in triplet-interaction "
                                                 "Hamiltonian systems.")
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a survey: integrate every cell of a TOML grid on dask "
                                   "workers and write one NetCDF archive (no config: the "
                                   "embedded default)")
    r.add_argument("config", nargs="?", help="survey TOML file (python -m survey FILE.toml "
                                              "is the same)")
    r.add_argument("--workers", type=int, help="local worker processes (default: [dask] "
                                                "workers, 2)")
    r.add_argument("--scheduler", help="address of an existing dask scheduler")
    r.add_argument("--output", help="archive path (overrides [survey] output)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.set_defaults(func=_run)
    v = sub.add_parser("verify", help="recompute a sample of an archive's cells from its "
                                      "stored config and compare bit for bit")
    v.add_argument("archive")
    v.add_argument("--cells", type=int, default=8)
    v.set_defaults(func=_verify)
    b = sub.add_parser("bench", help="survey's DOP853 vs scipy and heyoka on the paper's orbits")
    b.add_argument("--t-final", type=float, default=2000.0)
    b.add_argument("--t-scipy", type=float, default=50.0,
                   help="span scipy is run over before extrapolating (default 50)")
    b.add_argument("--repeats", type=int, default=2)
    b.add_argument("--only", action="append", choices=["integrator", "indicators", "tori",
                                                       "survey", "memory"],
                   help="run only these parts (repeatable)")
    b.set_defaults(func=_bench)
    o = sub.add_parser("orbit", help="integrate one orbit of a paper family and report "
                                     "conservation and its Lyapunov exponent")
    o.add_argument("--family", default="sides")
    o.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="family parameter, e.g. --param delta=3 (repeatable)")
    o.add_argument("--potential", default="perimetric_power")
    o.add_argument("--t-final", type=float, default=500.0)
    o.add_argument("--tol", type=float, default=1e-12, help="rtol = atol (default 1e-12)")
    o.set_defaults(func=_orbit)
    return parser


def main(argv=None):
    """Run a command; every failure is one line on stderr: exit 2 for bad input (a config,
    an argument, a file that is not an archive), 1 for a survey that could not finish (a
    full disk, a busy output), 130 when interrupted."""
    from .archive import ArchiveError
    from .config import ConfigError
    from .sweep import SurveyError
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0].endswith(".toml"):
        argv.insert(0, "run")
    args = build_parser().parse_args(argv)
    try:
        if getattr(args, "workers", None) is not None and args.workers < 1:
            raise ConfigError("--workers", f"must be >= 1, got {args.workers}")
        return args.func(args)
    except (ConfigError, ArchiveError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except SurveyError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        again = " -- run the same command to resume" if args.command == "run" else ""
        print(f"interrupted{again}", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
