"""Command line: `python -m survey <command>`."""
from __future__ import annotations

import argparse
import os
import sys
import textwrap
from pathlib import Path

from .catalog import defaults

# commands that run the integrator, so compile its kernels on a machine's first run
COMPILING_COMMANDS = ("run", "reproduce", "verify", "orbit", "explore", "bench", "equilibria",
                      "periodic")
# the embedded default survey (`python -m survey run`)
DEFAULT_CONFIG = Path(__file__).parent / "default.toml"
# the parts of `bench`, in the order they run, with what each measures (its --help)
BENCH_PARTS = {
    "scan": "a 101-orbit grid end to end against heyoka's SIMD batch ensemble (on the same "
            "work, and survey's default with its re-runs of verdicts in doubt)",
    "cell": "a default survey cell against its orbit with one tangent vector",
    "fixed": "what a 1-cell survey costs by phase and on the command line, warm and cold "
             "(every kernel compiled into an empty cache, with the time to its first word "
             "and where the compiling goes, function by function)",
    "integrator": "survey's DOP853 against scipy's DOP853 and heyoka on the paper's orbits",
    "step": "where a DOP853 step's time goes (right-hand side, stage combinations and error "
            "norm, the rest of the loop) and the machine's limit (the step's floating-point "
            "operations, counted, at the core's measured peak multiply-add rate)",
    "indicators": "what MEGNO and a section add to an orbit",
    "tori": "what the torus analysis adds to a cell",
    "terms": "the paper's system on its own compiled path against the general path of sums "
             "of terms, and other systems (LJAT, 3-D, four bodies) alone and in SIMD lanes",
    "survey": "the scaling on 1 vs 2 workers",
    "refine": "how busy a refined map keeps 2 workers (each one's idle share of the compute "
              "phase)",
    "memory": "the driver's peak memory for 10^4 and 10^5 cells",
    "scale": "the cost per cell of (delta, energy) maps of 10^3 to 10^5 cells, the smallest "
             "one's compute against heyoka's batch mode on its orbits, and how soon a "
             "10^6-cell grid saves its first chunk, with the driver's memory then",
    "newton": "a step of the periodic-orbit shooting against the orbit with its full "
              "tangent block",
    "explore": "the explorer on a 10^4-cell map in headless Chromium: the command to an "
               "interactive page, a click to the cell's orbit (t = 2000) drawn, beside the "
               "`orbit` command on the same kind of orbit",
}


def _bench(args):
    from .catalog.errors import ConfigError
    for flag, value, low in (("--t-final", args.t_final, 0.0), ("--t-scipy", args.t_scipy, 0.0),
                             ("--repeats", args.repeats, 0)):
        if not value > low:         # (NaN fails too)
            raise ConfigError(flag, f"must be > {low:g}, got {value!r}")
    from . import bench
    t = args.t_final
    parts = {"scan": lambda: bench.scan_vs_heyoka(t_final=t),
             "cell": lambda: bench.default_cell(t_final=t),
             "fixed": bench.fixed_costs,
             "integrator": lambda: bench.run(t_final=t, t_scipy=args.t_scipy,
                                             repeats=args.repeats),
             "step": lambda: bench.step_costs(t_final=t),
             "indicators": lambda: bench.indicator_overhead(t_final=t),
             "tori": lambda: bench.torus_overhead(t_final=t),
             "terms": lambda: bench.interaction_terms(t_final=t),
             "survey": bench.survey_scaling,
             "refine": bench.refined_map,
             "memory": bench.survey_memory,
             "scale": bench.survey_scale,
             "newton": bench.newton_step,
             "explore": bench.explorer_latency}
    for name in BENCH_PARTS:
        if name in (args.only or BENCH_PARTS):
            if args.record is None:
                parts[name]()
                continue
            import contextlib
            import io
            import time

            printed, start = io.StringIO(), time.time()
            with contextlib.redirect_stdout(Tee(sys.stdout, printed)):
                parts[name]()
            print(f"recorded {record_bench(name, printed.getvalue(), args.record, start)}")
    return 0


class Tee:
    """A text stream writing to several (what a bench part prints, shown and recorded)."""

    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for s in self.streams:
            s.write(text)
        return len(text)

    def flush(self):
        for s in self.streams:
            s.flush()


def record_bench(part: str, printed: str, folder, started: float) -> Path:
    """What a bench part printed, as the page docs/bench/PART.md: the output itself, never
    retyped, with when, where and by which commit it was measured."""
    import os
    import time

    from .pipeline.archive import git_commit, machine
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(started))
    text = (f"## `{part}`\n\n`python -m survey bench --only {part}`, recorded {when} at "
            f"commit `{git_commit()}` on {machine()}, {os.cpu_count()} cores.\n\n"
            f"```text\n{printed.rstrip()}\n```\n")
    path = Path(folder) / f"{part}.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def _orbit(args):
    """One orbit of a family, the orbits of a survey config's cells, or every orbit of an
    orbit workflow file: what they conserved, their Lyapunov exponent, the ranges of their
    shape and their closest approaches; with --plot the paper's single-orbit figures."""
    from .catalog.errors import ConfigError
    from .pipeline import orbits
    from .pipeline.resources import ensure_folder
    if args.plot:
        ensure_folder(args.plot, "--plot")
    if args.workflow and orbits.is_orbit_workflow(args.workflow):
        if not args.plot:
            raise ConfigError("--plot", "an orbit workflow draws figures: give --plot DIR")
        for path in orbit_workflow(args.workflow, args.plot):
            print(f"wrote {path}")
        return 0
    if args.workflow:
        given = [flag for flag, value in (("--family", args.family), ("--param", args.param),
                                          ("--potential", args.potential),
                                          ("--potential-param", args.potential_param),
                                          ("--masses", args.masses), ("--tol", args.tol))
                 if value not in (None, [])]
        if given:
            raise ConfigError(given[0], "comes from the config file's [system], [initial] "
                                        "and [integration]; edit it there (or drop the file)")
        spec = orbits.from_survey_config(args.workflow, args.cell, args.t_final,
                                         args.zoom_until)
    else:
        if args.cell:
            raise ConfigError("--cell", "picks cells of a survey config: give its file")
        system = {"potential": args.potential or defaults.POTENTIAL,
                  "params": _numbers(args.potential_param, "--potential-param")}
        if args.masses:
            system["masses"] = _numbers([args.masses], "--masses", listed=True)
            system["bodies"] = len(system["masses"])
        spec = orbits.check(orbits.OrbitSpec(
            name=args.family or "sides", family=args.family or "sides",
            params=_numbers(args.param, "--param"), system=system,
            t_final=defaults.ORBIT_T_FINAL if args.t_final is None else args.t_final,
            tol=defaults.RTOL if args.tol is None else args.tol,
            zoom_until=args.zoom_until), "orbit", cli=True)
    from .pipeline.progress import notice
    with notice(f"integrating the orbits to t = {spec.t_final:g}", sys.stderr.isatty()):
        runs = orbits.run_orbits(spec)
    print("\n".join(line for run in runs for line in orbits.describe(spec, run)))
    if args.plot:
        from .presentation import orbit_plots, plots
        figs = orbit_plots.spec_figures(spec.name, spec.zoom_until, runs)
        for path in plots.save(figs, args.plot, spec.name):
            print(f"wrote {path}")
    return 0


def _numbers(items, flag, listed=False):
    """KEY=NUMBER options as a dict (or, listed, one comma-separated list of numbers)."""
    import math

    from .catalog.errors import ConfigError
    if listed:
        try:
            values = [float(v) for v in items[0].split(",")]
        except ValueError:
            raise ConfigError(f"{flag} {items[0]}", "expected numbers separated by commas, "
                                                    "e.g. 1,0.001,0.0001") from None
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{flag} {items[0]}", "the values must be finite numbers")
        return values
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        try:
            out[key] = float(value)
        except ValueError:
            raise ConfigError(f"{flag} {item}", "expected KEY=NUMBER") from None
        if not math.isfinite(out[key]):
            raise ConfigError(f"{flag} {item}", "the value must be a finite number")
    return out


def orbit_workflow(path, folder) -> list:
    """Draw every figure of an orbit workflow into `folder`; returns the files."""
    from .pipeline import orbits
    from .presentation import orbit_plots, plots
    written = []
    for spec in orbits.load_workflow(path):
        if isinstance(spec, orbits.PlaneSpec):
            run = orbits.run_plane(spec)
            written += plots.save({"plane": orbit_plots.plane_figure(spec.name, spec, run)},
                                  folder, spec.name)
            if spec.manifolds:
                from .pipeline.archive import write_family
                from .pipeline.families import manifold_dataset
                written.append(write_family(
                    manifold_dataset(spec, run.manifolds, orbits.plane_text(spec)),
                    Path(folder) / f"{spec.name}_plane.nc", f"python -m survey orbit {path}"))
            print("\n".join(orbits.describe_plane(spec, run)))
            continue
        runs = orbits.run_orbits(spec)
        written += plots.save(orbit_plots.spec_figures(spec.name, spec.zoom_until, runs),
                              folder, spec.name)
        print("\n".join(line for run in runs for line in orbits.describe(spec, run)))
    return written


def _plot(args):
    from .catalog.errors import ConfigError
    from .catalog.indicators import REGISTRY
    from .catalog.variables import V
    from .pipeline.progress import notice
    with notice(f"reading {args.archive}", sys.stderr.isatty()):    # xarray, matplotlib
        from .pipeline.archive import open_archive
        from .pipeline.resources import ensure_folder
        from .presentation import plots
    known = [V.regime] + [i.headline for i in REGISTRY if i.map is not None]
    for name in args.var or []:
        if name not in known:
            raise ConfigError(f"--var {name}", f"is not a variable plots draw; one of "
                                               f"{', '.join(known)}")
    out = ensure_folder(args.out or Path(args.archive).parent, "--out")
    with open_archive(args.archive) as ds:
        _survey_archive(args.archive, ds, "plot")
        ds = _with_report_attributes(ds)
        with notice("drawing the figures", sys.stderr.isatty()):
            paths = plots.draw(ds, out, Path(args.archive).stem, args.var or None)
        for path in paths:
            print(f"wrote {path}")
    return 0


def _with_report_attributes(ds):
    """An archive with what its report reads beside the cells -- its resolved config
    (pipeline.config.Config.resolved_text) and what only a solver computes
    (pipeline.special.report_attributes) -- stored by every survey since they were,
    computed here for an archive written before."""
    if "config_resolved" not in ds.attrs:
        from .pipeline.config import parse_config
        ds = ds.assign_attrs(config_resolved=parse_config(
            ds.attrs["config"], check_output=False).resolved_text)
    if "special_cells" in ds.attrs:
        return ds
    from .pipeline.progress import notice, watch_compiles
    from .pipeline.special import report_attributes
    if sys.stderr.isatty():
        watch_compiles()
    with notice("solving the special solutions the cells start on (an archive written "
                "before survey stored them)", sys.stderr.isatty()):
        return ds.assign_attrs(report_attributes(ds))


def _survey_archive(path, ds, command: str):
    """A family archive (equilibria/periodic --output) is refused by the survey commands."""
    from .catalog.errors import ArchiveError
    if "family" in ds.attrs:
        raise ArchiveError(f"{path}: a family archive; `{command}` reads survey archives "
                           "(a periodic family's diagram is drawn by `python -m survey "
                           "reproduce` from its workflow)")


def _report(args):
    import contextlib

    from .pipeline.progress import notice
    archive = Path(args.archive)
    with notice(f"reading {archive}", sys.stderr.isatty()):         # xarray, matplotlib
        from .pipeline.archive import check_archives, open_archive
        from .pipeline.resources import ensure_folder
        from .presentation import report
    out = ensure_folder(args.out or archive.parent, "--out")
    with open_archive(archive) as ds, contextlib.ExitStack() as stack:
        _survey_archive(archive, ds, "report")
        checks = {v: stack.enter_context(open_archive(f)) for v, f in check_archives(archive)}
        ds = _with_report_attributes(ds)
        with notice("writing the report and drawing its figures", sys.stderr.isatty()):
            path = report.write(ds, out, archive.stem, checks=checks)
    print(f"wrote {path} and its figures")
    return 0


def _reproduce(args):
    """Every workflow in workflows/ and the embedded default: surveys to their archives,
    figures and reports; orbit workflows to their figures. Everything is made in
    results/.staging first; a file replaces its copy in results/ only if its content changed
    (provenance -- dates, commit, machine -- aside), so an unchanged checkout stays clean.
    With --check nothing is replaced: the files that differ are named and the exit code
    is 1."""
    import shutil

    from .pipeline import families, orbits
    from .pipeline.config import load_config
    from .presentation import families as family_words
    from .catalog.errors import ConfigError
    from .pipeline.resources import ensure_folder
    if not Path(args.workflows).is_dir():
        raise ConfigError("--workflows", f"{args.workflows} is not a folder of workflows")
    paths = sorted(Path(args.workflows).glob("*.toml")) + [DEFAULT_CONFIG]
    unknown = sorted(set(args.only or []) - {p.stem for p in paths})
    if unknown:
        raise ConfigError(f"--only {unknown[0]}", "is not a workflow; one of "
                                                  + ", ".join(p.stem for p in paths))
    if args.only:
        paths = [p for p in paths if p.stem in args.only]
    results = ensure_folder(args.results, "--results")
    staging = results / ".staging"
    staging.mkdir(parents=True, exist_ok=True)
    for path in paths:
        print(f"== {path}")
        if families.special_table(path):
            solved = families.solve(path)
            diagram = families.dataset(solved) if solved.is_family and \
                solved.kind == "periodic" else None
            print(f"made {family_words.write_report(solved, staging, diagram)}")
            continue
        if orbits.is_orbit_workflow(path):
            for out in orbit_workflow(path, staging):
                print(f"made {out}")
            continue
        config = load_config(path)
        config = config.with_output(staging / f"{config.name}.nc")
        made = _survey(config, command=f"python -m survey reproduce ({path.name})",
                       progress=False if args.no_progress else None)
        print(f"made {made}, its report and figures")
    _render_readme(Path(args.workflows) / "results_readme.md", staging, results)
    changed = []
    for new in sorted(p for p in staging.iterdir() if p.is_file()):
        old = results / new.name
        why = _differs(old, new)
        if why:
            changed.append(f"{old}: {why}")
            if not args.check:
                os.replace(new, old)
    if args.check:
        print("\n".join([f"{len(changed)} file(s) in {results} are not what the current code "
                         "makes:"] + changed) if changed else
              f"{results} is what the current code makes")
    else:
        print("\n".join([f"updated {len(changed)} file(s):"] + changed) if changed else
              f"nothing changed in {results}")
    shutil.rmtree(staging, ignore_errors=True)
    return 1 if args.check and changed else 0


def _render_readme(template: Path, staging: Path, results: Path):
    """results/README.md from its template, filled from the files just made (staging) over
    those already in results/; not rendered, with the reason, where a file it quotes is
    in neither (a --only run into a new folder)."""
    from .presentation.results_text import render
    if not template.exists():
        return
    try:
        text = render(template.read_text(), staging, results)
    except FileNotFoundError as missing:
        print(f"{results / 'README.md'} not rendered: {missing}")
        return
    (staging / "README.md").write_text(text)
    print(f"made {staging / 'README.md'} from {template}")


def _differs(old, new) -> str:
    """Why `new` should replace `old` ('' if only provenance differs): archives by their
    results (survey.pipeline.sweep.same_results), reports without their provenance line,
    other files byte for byte; an archive or report made by uncommitted code is replaced
    by one made by committed code."""
    from .pipeline.sweep import same_results
    from .presentation import report
    if not old.exists():
        return "new"
    if new.suffix in (".nc", ".md") and _uncommitted(old) and not _uncommitted(new):
        return "made by uncommitted code"
    if new.suffix == ".nc":
        return "; ".join(same_results(old, new))
    if new.suffix == ".md":
        strip = report.without_provenance
        return "" if strip(old.read_text()) == strip(new.read_text()) else "text differs"
    return "" if old.read_bytes() == new.read_bytes() else "content differs"


def _uncommitted(path) -> bool:
    """Whether an archive's or report's provenance names a commit with uncommitted changes."""
    if path.suffix == ".nc":
        import xarray as xr
        with xr.open_dataset(path) as ds:
            return str(ds.attrs.get("git_commit", "")).endswith("-dirty")
    return "-dirty`" in path.read_text()


def _run(args):
    from .pipeline.config import load_config, parse_config
    from .pipeline.resources import ensure_writable
    if args.config is None:
        config = parse_config(DEFAULT_CONFIG.read_text(), "embedded default (survey/default.toml)")
    else:
        config = load_config(args.config)
    if args.output:
        ensure_writable(Path(args.output), "--output", [args.config] if args.config else [])
        config = config.with_output(args.output)
    _survey(config, command="python -m survey " + " ".join(sys.argv[1:]),
            progress=False if args.no_progress else None, workers=args.workers,
            scheduler=args.scheduler, summary=True, write_report=not args.no_report)
    return 0


def _survey(config, command, summary=False, write_report=True, **kw) -> Path:
    """Run a survey -- and its [check] runs, the same survey with one thing changed each,
    if it has them -- then write its report beside the archive."""
    import contextlib

    from .analysis.classify import summary as summarise
    from .catalog.variables import V
    from .pipeline.sweep import run_survey
    # the report's modules (matplotlib among them) load while the workers compute
    path = run_survey(config, command=command,
                      imports=("survey.presentation.report",) if write_report else (), **kw)
    import xarray as xr
    if summary:
        with xr.open_dataset(path) as ds:
            refined = f", {int((ds['level'] > 0).sum())} of them added by refinement" \
                if "level" in ds.coords else ""
            print(f"wrote {path} ({ds[V.status].size} cells{refined})")
    checks = {}
    for variant, second in config.checks().items():
        print("checking: the same survey with " + defaults.check_change(
            variant, vars(second.settings.indicators), vars(second.settings.integration)))
        checks[variant] = run_survey(second, command=f"{command} [check] {variant}", **kw)
        if summary:
            print(f"wrote {checks[variant]}")
    with contextlib.ExitStack() as stack:
        ds = stack.enter_context(xr.open_dataset(path))
        others = {k: stack.enter_context(xr.open_dataset(v)) for k, v in checks.items()}
        if summary:
            print("\n".join(summarise(ds)))
        if write_report:      # imported here: matplotlib alone takes 0.3 s to import
            from .pipeline.progress import notice
            from .presentation import report
            with notice("writing the report and drawing its figures",
                        kw.get("progress") is not False and sys.stderr.isatty()):
                written = report.write(ds, path.parent, path.stem, checks=others)
            if summary:
                print(f"report and figures: {written} (and {path.stem}_*.png beside it)")
    return path


def _special(args):
    """`equilibria` and `periodic`: the special solutions of a config's system, or with a
    parameter their family (and with --output, its archive)."""
    from .pipeline import archive, families
    from .presentation import families as family_words
    solved = families.solve(args.config, args.command, args.output)
    if args.output:
        written = archive.write_family(families.dataset(solved), args.output,
                                       "python -m survey " + " ".join(sys.argv[1:]))
        print(f"wrote {written}")
    print(family_words.as_json(solved) if args.json else family_words.as_text(solved))
    return 0


def _verify(args):
    from .catalog.errors import ConfigError
    from .pipeline.progress import notice
    if args.cells < 1:
        raise ConfigError("--cells", f"must be >= 1, got {args.cells}")
    with notice(f"verifying {args.archive}", sys.stderr.isatty()):
        from .pipeline.families import is_family, verify_family
        from .pipeline.sweep import verify
        ok, lines = verify_family(args.archive, args.cells) if is_family(args.archive) \
            else verify(args.archive, cells=args.cells)
    print("\n".join(lines))
    return 0 if ok else 1


def _explore(args):
    from . import explore
    return explore.main(args.archive, args.host, args.port, browser=not args.no_browser)


DESCRIPTIONS = {
    "equilibria": "The relative equilibria (rigid rotations, or rest) of a config's [system] "
                  "near its one [initial] start, [equilibria] starts seeded configurations "
                  "and (three bodies in the plane) a cover of the shape sphere, distinct up "
                  "to rotations, reflections and permutations: shape, rotation rate, E, J, "
                  "the reduced linearisation's eigenvalues, normal-mode frequencies with "
                  "Krein signs, stable or not. With [equilibria] parameter: the family along "
                  "it and where its stability changes, each member checked.",
    "periodic": "The periodic orbit ([periodic] rotating = true: relative periodic) through "
                "a config's [initial] start by Newton shooting from [periodic] period (or a "
                "Lyapunov orbit of an equilibrium's normal mode: mode): the period, the Newton "
                "residuals, the non-trivial Floquet multipliers, elliptic / hyperbolic / "
                "complex unstable, the rates at which nearby orbits leave, Greene's residues. "
                "With [periodic] parameter: the family along it with its folds and "
                "bifurcations, each member checked.",
    "orbit": "Integrate orbits with a tangent vector and print E, J, conservation errors, "
             "steps, the finite-time Lyapunov exponent and MEGNO, the crossings of the "
             "surface of section (the config's [section]; three bodies in the plane: phi = "
             "pi/2 without one), the ranges of P, |A| and I, each "
             "pair's closest approach with its time and the bound P_max. The orbit is a "
             "family member given by flags; or FILE is a survey config (its [system], "
             "[initial] and tolerance: all its cells, up to 8, or those given by --cell); or "
             "FILE is an orbit workflow ([[orbit]] and [[plane]] tables, with --plot). With "
             "--plot DIR the paper's single-orbit figures: paths with the disk of radius "
             "P_max/3, inequity space, P and A against time, side lengths with near "
             "collisions.",
}


def build_parser():
    parser = argparse.ArgumentParser(prog="python -m survey",
                                     description="Order and chaos in triplet-interaction "
                                                 "Hamiltonian systems.")
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a survey: integrate every cell of a TOML grid on dask "
                                   "workers and write one NetCDF archive (no config: the "
                                   "embedded default)",
                       description="Integrate every cell of a TOML grid on dask workers and "
                                   "write one NetCDF archive, then its figures and report "
                                   "beside it; a bare `run` uses the embedded default "
                                   "(survey/default.toml). `python -m survey grid.toml` is "
                                   "`run grid.toml`. An interrupted survey resumes from its "
                                   "checkpoints when the same command runs again.")
    r.add_argument("config", nargs="?", help="survey TOML file (python -m survey FILE.toml "
                                              "is the same)")
    r.add_argument("--workers", type=int, help="local worker processes (default: [dask] "
                                                "workers, 2)")
    r.add_argument("--scheduler", help="address of an existing dask scheduler")
    r.add_argument("--output", help="archive path (overrides [survey] output)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--no-report", action="store_true", help="no figures and report beside "
                                                           "the archive")
    r.set_defaults(func=_run)
    pl = sub.add_parser("plot", help="figures of an archive: maps, scans, the section, "
                                     "convergence histories, the frequency map",
                        description="The figures that fit the grid: for two axes maps of the "
                                    "regime, MEGNO, FTLE, FLI and Birkhoff digits with "
                                    "histograms (on a section grid the MEGNO map with the "
                                    "crossings overlaid); for one axis the indicators with "
                                    "their spread and the regime shaded behind; the section "
                                    "crossings, one panel per shell, and for one shell a 3-D "
                                    "slice of its 4-D section; for seeded starts per grid "
                                    "point their regular share; convergence histories; the "
                                    "frequency map with its resonance lines.")
    pl.add_argument("archive", help="a survey archive (.nc)")
    pl.add_argument("--out", help="folder (default: the archive's)")
    pl.add_argument("--var", action="append", help="only these indicators (repeatable)")
    pl.set_defaults(func=_plot)
    rp = sub.add_parser("report", help="the KAM-torus detection report of an archive "
                                       "(Markdown, with its figures)",
                        description="The KAM-torus detection report (Markdown) with its "
                                    "figures: what was run, the share of each regime, the "
                                    "spread of the indicators over nearby orbits, where chaos "
                                    "sets in, the tori with their frequencies and nearest "
                                    "resonances, where the indicators agree, the thresholds "
                                    "and why, conservation and failures. Every sentence is "
                                    "computed from the archive.")
    rp.add_argument("archive", help="a survey archive (.nc)")
    rp.add_argument("--out", help="folder (default: the archive's)")
    rp.set_defaults(func=_report)
    rr = sub.add_parser("reproduce", help="run every workflow in workflows/ and the "
                                          "embedded default, and write results/: archives, "
                                          "figures, reports",
                        description="Run every workflow in workflows/ and the embedded "
                                    "default into results/.staging, then replace a file in "
                                    "results/ only where its content changed (an archive's "
                                    "results, a report's text without its provenance line, a "
                                    "figure's bytes), so unchanged code leaves the checkout "
                                    "clean.")
    rr.add_argument("--workflows", default="workflows",
                    help="the folder of workflows (default workflows)")
    rr.add_argument("--results", default="results", help="the folder to update (default results)")
    rr.add_argument("--check", action="store_true",
                    help="change nothing; exit 1 naming the files that are not what the "
                         "current code makes")
    rr.add_argument("--only", action="append", help="only these workflows (file stem)")
    rr.add_argument("--no-progress", action="store_true", help="no progress bars")
    rr.set_defaults(func=_reproduce)
    for name, what in (("equilibria", "relative equilibria (rigid rotations, or rest) of a "
                                      "config's system near its [initial] start, with their "
                                      "linear stability"),
                       ("periodic", "the periodic orbit (or relative periodic orbit) through "
                                    "a config's [initial] start, by Newton shooting, with its "
                                    "Floquet multipliers")):
        sp = sub.add_parser(name, help=f"{what}; table [{name}]",
                            description=DESCRIPTIONS[name])
        sp.add_argument("config", help=f"TOML file: [system], one [initial] start, [{name}]")
        sp.add_argument("--json", action="store_true", help="print the numbers as JSON")
        sp.add_argument("--output", help=f"with [{name}] parameter: write the family (NetCDF)")
        sp.set_defaults(func=_special)
    v = sub.add_parser("verify", help="recompute a sample of an archive's cells from its "
                                      "stored config and compare bit for bit (a family "
                                      "archive: every member; a manifold archive: its "
                                      "orbits, a sample of its points and its first "
                                      "homoclinic point)",
                       description="Check a survey archive against the config stored in it "
                                   "(the config's sha256, the grid coordinates, the "
                                   "variables, their dimensions and attributes), then "
                                   "recompute K cells (first, last, random) and compare every "
                                   "reproducible variable bit for bit, on any machine (the "
                                   "archive names the one that made it). A family archive "
                                   "(equilibria/periodic --output) is computed again whole "
                                   "and compared member by member; a manifold archive "
                                   "([[plane]] manifolds) by its orbits, a sample of its "
                                   "points and its first homoclinic point. Exit 0 if all "
                                   "agree, 1 if not.")
    v.add_argument("archive", help="a survey, family or manifold archive (.nc)")
    v.add_argument("--cells", type=int, default=8,
                   help="cells (a manifold archive: points) to recompute (default 8)")
    v.set_defaults(func=_verify)
    x = sub.add_parser("explore", help="a survey archive's maps in a browser: hover a cell "
                                       "for its evidence, click it for its orbit (a family "
                                       "archive: its diagram, click a member)",
                       description="Serve an archive's maps (the regime and every mapped "
                                   "indicator; a one-axis scan as a line; a one-shell "
                                   "archive's section, and its 4-D section of three bodies "
                                   "in the plane turned in 3-D) as a web page on this "
                                   "machine. The pointer over a cell shows its parameters, "
                                   "regime, confidence, horizon and indicators; a click "
                                   "integrates its orbit with survey's kernels (what `orbit "
                                   "CONFIG --cell K` prints, the same numbers) and draws its "
                                   "paths, section crossings and indicators' convergence, "
                                   "with the archive's frequencies, the cell as a config "
                                   "([initial] family = \"explicit\") and the command that "
                                   "reproduces it. A family archive (periodic or "
                                   "equilibria --output): its diagram along the parameter, "
                                   "stable and unstable members, bifurcations; a click "
                                   "integrates a member over its period with its "
                                   "multipliers. Needs Bokeh: pip install "
                                   "'survey[explore]'.")
    x.add_argument("archive", help="a survey archive, or a family archive (.nc)")
    x.add_argument("--port", type=int, default=5006,
                   help="the port to serve on (default 5006; 0: any free port)")
    x.add_argument("--host", default="127.0.0.1",
                   help="the address to listen on (default 127.0.0.1: this machine only; "
                        "from elsewhere, reach it over an SSH tunnel: ssh -L 5006:"
                        "127.0.0.1:5006 HOST)")
    x.add_argument("--no-browser", action="store_true",
                   help="print the address, open no browser")
    x.set_defaults(func=_explore)
    b = sub.add_parser("bench", help="speed as ratios against baselines measured in the same "
                                     "run (pip install -e '.[bench]')",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Speed as ratios against baselines measured in the same "
                                   "run, printed beside\neach target. Parts (--only):\n\n"
                                   + "\n".join(textwrap.fill(f"{k}: {v}", 88,
                                                              subsequent_indent="    ")
                                                for k, v in BENCH_PARTS.items()))
    b.add_argument("--t-final", type=float, default=defaults.T_FINAL,
                   help=f"span of the timed orbits (default {defaults.T_FINAL:g})")
    b.add_argument("--t-scipy", type=float, default=50.0,
                   help="span scipy is run over before extrapolating (default 50)")
    b.add_argument("--repeats", type=int, default=2,
                   help="runs of each timing, the best kept (default 2)")
    b.add_argument("--only", action="append", choices=list(BENCH_PARTS),
                   help="run only these parts (repeatable)")
    b.add_argument("--record", nargs="?", const="docs/bench", metavar="DIR",
                   help="also write what each part printed, with the date and the machine, "
                        "to DIR/PART.md (default docs/bench: the documentation's "
                        "performance page)")
    b.set_defaults(func=_bench)
    o = sub.add_parser("orbit", help="integrate orbits -- a family member given by flags, "
                                     "the cells of a survey config, or an orbit workflow -- "
                                     "and report conservation, the Lyapunov exponent, the "
                                     "ranges of P, |A|, I and the closest approaches; --plot "
                                     "DIR draws the paper's single-orbit figures",
                       description=DESCRIPTIONS["orbit"])
    o.add_argument("workflow", nargs="?", metavar="FILE",
                   help="an orbit workflow ([[orbit]] tables) or a survey config (its "
                        "[system], [initial] and tolerance; --cell picks grid cells)")
    o.add_argument("--plot", metavar="DIR", help="write the figures into DIR")
    o.add_argument("--cell", type=int, action="append", default=[], metavar="K",
                   help="a survey config's flat cell index (repeatable; default all, at "
                        "most 8)")
    o.add_argument("--family", help="initial-condition family (default sides)")
    o.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="family parameter, e.g. --param delta=3 (repeatable)")
    o.add_argument("--potential", help=f"triplet potential (default {defaults.POTENTIAL})")
    o.add_argument("--potential-param", action="append", default=[], metavar="KEY=VALUE",
                   help="potential parameter, e.g. --potential-param exponent=3")
    o.add_argument("--masses", metavar="M1,M2,...", help="masses, one per body")
    o.add_argument("--t-final", type=float, help=f"end time (default "
                   f"{defaults.ORBIT_T_FINAL:g}, or the config's t_final)")
    o.add_argument("--tol", type=float, help=f"rtol = atol (default {defaults.RTOL:g})")
    o.add_argument("--zoom-until", type=float, default=0.0, metavar="T",
                   help="draw paths and side lengths for t <= T only (P, |A| and "
                        "inequities: the whole run)")
    o.set_defaults(func=_orbit)
    return parser


def main(argv=None):
    """Run a command; every failure is one line on stderr: exit 2 for bad input (a config,
    an argument, a file that is not an archive), 1 for a survey that could not finish (a
    full disk, a busy output), 130 when interrupted."""
    from .catalog.errors import ArchiveError, ConfigError, SurveyError
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0].endswith(".toml"):
        argv.insert(0, "run")
    args = build_parser().parse_args(argv)
    if args.command in COMPILING_COMMANDS and sys.stderr.isatty():
        # before the heavy imports, so that it shows at once
        from .machine.jit import kernels_cached
        from .pipeline.progress import FIRST_COMPILE
        if not kernels_cached():
            print("survey: first run here: the kernels compile before the work starts "
                  f"({FIRST_COMPILE}, once)", file=sys.stderr, flush=True)
        from .pipeline.progress import watch_compiles
        watch_compiles()        # any other kernel a command compiles says so too
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
    except BrokenPipeError:     # the reader of our output went away (| head): stop quietly,
        sys.stdout = open(os.devnull, "w")      # and flush what is left nowhere
        return 141              # 128 + SIGPIPE, as a shell reports a process the pipe ended


def entry():
    """The command line's process: main(), then out without the interpreter's teardown of
    numba, LLVM, dask and matplotlib (0.5-0.7 s measured, longer than a small survey's
    archive). Everything is written and closed by then; only the streams need flushing."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(code or 0))


if __name__ == "__main__":
    entry()
