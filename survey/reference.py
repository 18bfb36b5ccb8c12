"""The reference pages of the documentation, generated from the declarations they describe
(never typed twice): config keys (pipeline.schema and the special-solution and orbit-workflow
tables), archive variables and statuses (catalog), interaction terms, initial-condition
families, indicators and regimes, and every command's --help (from the parser the command
line uses). docs/conf.py writes them into docs/_generated/ at each build; the tests check
that every declared name is in them, and `python -m survey.reference DIR` writes them
anywhere.

Also the gallery: every figure in results/ with the workflow that made it and what a figure
of its kind shows."""
from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path


def _cell(text) -> str:
    """Text safe inside a Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|").replace("<", "&lt;") \
        .replace(">", "&gt;")


def _value(v) -> str:
    if v is None or v == "":
        return "—"
    if isinstance(v, float) and math.isfinite(v):
        return f"{v:.10g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return "{}" if v == {} else str(v)


KINDS = {"str": "text", "int": "integer", "float": "number", "bool": "true/false",
         "floats": "list of numbers", "ints": "list of integers", "strs": "list of names",
         "table": "table", "terms": "list of term tables", "axis": "number or grid axis"}


def _bounds(key) -> str:
    parts = []
    if key.choices is not None:
        parts.append("one of " + ", ".join(f"`{c}`" for c in key.choices))
    if key.above is not None:
        parts.append(f"> {key.above:g}")
    if key.low is not None:
        parts.append(f">= {key.low:g}")
    if key.high is not None:
        parts.append(f"<= {key.high:g}")
    return "; ".join(parts) or "—"


def key_table(keys: dict) -> list[str]:
    """A Markdown table of pipeline.schema.Key declarations."""
    out = ["| key | type | default | bounds | unit | meaning |",
           "| --- | --- | --- | --- | --- | --- |"]
    for name, key in keys.items():
        meaning = key.doc + (f" ({key.hint})" if key.hint else "")
        out.append(f"| `{name}` | {KINDS[key.kind]} | {_cell(_value(key.default))} | "
                   f"{_cell(_bounds(key))} | {key.unit or '—'} | {_cell(meaning)} |")
    return out


def config_page() -> str:
    from .pipeline.families import EQUILIBRIA_KEYS, PERIODIC_KEYS
    from .pipeline.orbits import ORBIT_KEYS, PLANE_KEYS
    from .pipeline.schema import SCHEMA
    out = ["## Survey config tables", "",
           "A survey config (`python -m survey run grid.toml`) holds these tables; every key "
           "is optional unless its meaning says otherwise. Grid axes: any number written "
           "`{start = .., stop = .., num = ..}` or a list where the type says *number or "
           "grid axis*, and every numeric [initial] family parameter and term parameter.", ""]
    for table, keys in SCHEMA.items():
        out += [f"### `[{table}]`", "", *key_table(keys), ""]
    out += ["## Special-solution tables", "",
            "`python -m survey equilibria config.toml` reads the config's `[system]`, its "
            "one `[initial]` start and `[equilibria]`; `periodic` the same with `[periodic]`.",
            "", "### `[equilibria]`", "", *key_table(EQUILIBRIA_KEYS), "",
            "### `[periodic]`", "", *key_table(PERIODIC_KEYS), "",
            "## Orbit workflow tables", "",
            "`python -m survey orbit workflow.toml --plot DIR` reads `[[orbit]]` and "
            "`[[plane]]` tables.", "", "### `[[orbit]]`", "", *key_table(ORBIT_KEYS), "",
            "### `[[plane]]`", "", *key_table(PLANE_KEYS), ""]
    return "\n".join(out)


def variables_page() -> str:
    from .catalog.families import FAMILY_VARIABLES
    from .catalog.status import Status
    from .catalog.variables import VARIABLES, V
    out = ["## Survey archive variables", "",
           "| variable | meaning | units | dimensions beyond the grid | cells |",
           "| --- | --- | --- | --- | --- |"]
    for v in VARIABLES:
        units = "flags" if v.name == V.status else v.units
        extra = "spatial (3-D)" if v.name == V.angular_momentum else ", ".join(v.extra)
        note = "" if v.reproducible else " (not reproducible)"
        out.append(f"| `{v.name}` | {_cell(v.long_name + note)} | {units} | {extra} | "
                   f"{v.cells} |")
    out += ["", "## `status` values", "", "| value | name | meaning |", "| --- | --- | --- |"]
    out += [f"| {s.value} | `{s.name.lower()}` | {_cell(s.meaning)} |" for s in Status]
    out += ["", "## Family archive variables", "",
            "`equilibria` and `periodic --output` write a family archive (`{parameter}` is "
            "the family's parameter); a `[[plane]]` with `manifolds` writes a manifold "
            "archive.", ""]
    for kind, variables in FAMILY_VARIABLES.items():
        out += [f"### {kind}", "", "| variable | dimensions | meaning | type | units |",
                "| --- | --- | --- | --- | --- |"]
        out += [f"| `{v.name}` | {', '.join(v.dims)} | {_cell(v.long_name) or '—'} | "
                f"{v.dtype} | {v.units or '—'} |" for v in variables]
        out.append("")
    return "\n".join(out)


def terms_page() -> str:
    from .physics.terms import EXPRESSION_KINDS, TERMS
    out = ["| kind | name | U | parameters (defaults, bounds) | notes |",
           "| --- | --- | --- | --- | --- |"]
    for t in TERMS:
        params = ", ".join(p.describe() for p in t.parameters)
        out.append(f"| {t.kind} | `{t.name}` | {_cell(t.formula)} | {_cell(params)} | "
                   f"{_cell(t.note)} |")
    out += ["", "Terms written as formulas (`expression = \"...\"`): kinds "
            + ", ".join(f"`{k}`" for k in EXPRESSION_KINDS) + "."]
    return "\n".join(out)


def families_page() -> str:
    from .physics.families import FAMILIES
    out = ["| family | parameters (defaults) | bodies | what it starts |",
           "| --- | --- | --- | --- |"]
    for f in FAMILIES.values():
        params = ", ".join(f"{k} = {_value(v)}" if v is not None else f"{k} (required)"
                           for k, v in f.defaults.items())
        out.append(f"| `{f.name}` | {_cell(params)} | "
                   f"{'any N, d' if f.any_n else 'three in the plane'} | {_cell(f.doc)} |")
    return "\n".join(out)


def indicators_page() -> str:
    from dataclasses import fields

    from .catalog.indicators import REGISTRY
    from .catalog.regimes import Regime, Thresholds
    out = ["## Indicators and lines of evidence", "",
           "| name | computed | archive variables | deviation vectors | votes on the regime "
           "| reference |", "| --- | --- | --- | --- | --- | --- |"]
    for i in REGISTRY:
        vote = (f"`{i.vote.variable}`: `{i.vote.thresholds}_regular`, "
                f"`{i.vote.thresholds}_chaotic`" if i.vote else "no")
        where = "with deviation vectors" if i.source == "tangent" else "from the orbit's samples"
        out.append(f"| `{i.name}` | {where} | {', '.join(f'`{v}`' for v in i.variables)} | "
                   f"{i.deviations if i.source == 'tangent' else '—'} | {vote} | "
                   f"{_cell(i.reference)} |")
    out += ["", "## Thresholds", "", "Keys of `[tori]` (and fields of `survey.Thresholds`).",
            "", "| threshold | default | meaning |", "| --- | --- | --- |"]
    out += [f"| `{f.name}` | {_value(f.default)} | {_cell(f.metadata['doc'])} |"
            for f in fields(Thresholds)]
    out += ["", "## `regime` values", "", "| value | name | meaning |", "| --- | --- | --- |"]
    out += [f"| {r.value} | `{r.name.lower()}` | {_cell(r.meaning)} |" for r in Regime]
    return "\n".join(out)


def subcommands(parser=None) -> dict[str, argparse.ArgumentParser]:
    """Each command's parser, by name, as the command line builds them."""
    from .cli import build_parser
    parser = parser or build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def help_text(parser: argparse.ArgumentParser) -> str:
    """A parser's --help at a fixed width, whatever the terminal."""
    import os
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "92"
    try:
        return parser.format_help()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


def commands_page() -> str:
    from .cli import build_parser
    parser = build_parser()
    out = ["Every command is `python -m survey COMMAND ...` (or `survey COMMAND ...`); "
           "this is each one's `--help`.", "", "```text", help_text(parser).rstrip(), "```", ""]
    for name, p in subcommands(parser).items():
        out += [f"## `{name}`", "", "```text", help_text(p).rstrip(), "```", ""]
    return "\n".join(out)


# what a figure of each kind shows: the suffix of its file name after the archive's stem
FIGURE_KINDS = {
    "map_regime": "the regime of every cell over two grid axes (hatched: verdicts not "
                  "confirmed at the longer horizon), with the special solutions marked",
    "map_regime_height": "the regime over the grid with the energy measured from the "
                         "equilibrium's (E - E_min)",
    "map_megno": "MEGNO <Y> over two grid axes, with its histogram",
    "map_megno_section": "MEGNO over a grid of section coordinates with the crossings of "
                         "its orbits overlaid",
    "map_ftle": "the finite-time Lyapunov exponent over two grid axes (log scale)",
    "map_fli": "the fast Lyapunov indicator over two grid axes",
    "map_birkhoff_digits": "weighted Birkhoff digits of convergence over two grid axes "
                           "(many digits: a torus)",
    "map_escape": "which exit each cell's orbit escaped through, and when",
    "scan": "the indicators along one grid axis with the ensemble's spread, the regime "
            "shaded behind",
    "section": "every section crossing projected onto the section's plane, one panel per "
               "shell",
    "section_slice": "a 3-D slice of one shell's 4-D section, where tori leave closed "
                     "curves",
    "convergence": "convergence histories of the indicators of chosen cells",
    "approach": "the FTLE against each cell's closest approach and least area",
    "frequency_map": "the fundamental frequencies of the regular cells with the "
                     "resonance lines",
    "regular_share": "the share of seeded starts decided regular, with 95% Wilson "
                     "intervals",
    "plane": "the section of the isosceles plane: orbits, periodic orbits with their "
             "stability, manifolds",
    "paths": "the bodies' paths with the disk of radius P_max/3",
    "inequities": "the orbit in inequity space",
    "perimeter_area": "perimeter and area against time",
    "sides": "side lengths against time, near collisions marked",
}
FAMILY_FIGURE = "the family's bifurcation diagram: its members along the parameter, " \
                "coloured by stability"


def figure_owners(workflows: Path) -> dict[str, str]:
    """The names figures in results/ are written under -> the workflow that makes them: each
    survey workflow's own name, each [[orbit]] and [[plane]] of an orbit workflow, and
    `default` (the embedded default, survey/default.toml)."""
    import tomllib
    owners = {"default": "default"}
    for path in sorted(workflows.glob("*.toml")):
        owners[path.stem] = path.stem
        tables = tomllib.loads(path.read_text())
        for entry in tables.get("orbit", []) + tables.get("plane", []):
            owners[entry["name"]] = path.stem
    return owners


def figure_kind(stem: str, owners: dict[str, str]) -> tuple[str, str]:
    """(workflow, what it shows) of a figure file stem in results/: its kind by the
    suffix after the name it is written under (a family's own name: its diagram)."""
    if stem in owners:
        return owners[stem], FAMILY_FIGURE
    for kind in sorted(FIGURE_KINDS, key=len, reverse=True):
        head = stem[:-len(kind) - 1]
        if stem.endswith("_" + kind) and head in owners:
            return owners[head], FIGURE_KINDS[kind]
    raise KeyError(f"{stem}.png: not a workflow's name followed by a figure kind of "
                   "survey.reference.FIGURE_KINDS")


def workflow_summary(path: Path) -> str:
    """A workflow's opening comment, as one paragraph."""
    lines = []
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        lines.append(line.lstrip("#").strip())
    return " ".join(lines)


def gallery_page(results: Path, workflows: Path, image_prefix: str) -> str:
    """Every figure in results/ under its workflow, with what it shows."""
    owners = figure_owners(workflows)
    groups: dict[str, list[tuple[str, str]]] = {}
    for png in sorted(results.glob("*.png")):
        owner, what = figure_kind(png.stem, owners)
        groups.setdefault(owner, []).append((png.name, what))
    out = []
    for owner in sorted(groups):
        path = workflows / f"{owner}.toml"
        if owner == "default":
            path = Path(__file__).with_name("default.toml")
        out += [f"## {owner}", "", workflow_summary(path), "",
                f"Made by `{path.relative_to(path.parents[1])}` (`python -m survey "
                f"reproduce --only {owner}`).", ""]
        archive = results / f"{owner}.nc"
        explorable = _explorable(archive)
        if explorable:
            out += [f"In the explorer (hover a cell, click it for its orbit): `python -m "
                    f"survey explore results/{archive.name}`.", ""]
        for name, what in groups[owner]:
            out += [f"### {name}", "", what[0].upper() + what[1:] + ".", "",
                    f"![{name}]({image_prefix}{name})", ""]
            layer = name.removesuffix(".png").removeprefix(f"{owner}_map_")
            if explorable and f"{owner}_map_{layer}.png" == name and layer in explorable:
                out += [f"The same map in the explorer: <http://127.0.0.1:5006/?layer="
                        f"{layer}> while `python -m survey explore results/{archive.name}` "
                        "runs.", ""]
    return "\n".join(out)


def _explorable(archive: Path) -> set[str]:
    """The layers the explorer colours a survey archive's map by (the regime and the
    mapped indicators it holds), or an empty set for a file that is none."""
    if not archive.exists():
        return set()
    import netCDF4
    from .catalog.indicators import REGISTRY
    from .catalog.variables import V
    with netCDF4.Dataset(archive) as nc:
        if "grid_axes" not in nc.ncattrs() or V.regime not in nc.variables:
            return set()
        return {V.regime, "regular_share"} & set(nc.variables) | \
            {i.headline for i in REGISTRY if i.map is not None and i.headline in nc.variables}


def bench_page(folder: Path) -> str:
    """The recorded bench parts (docs/bench/PART.md), in the order bench runs them."""
    from .cli import BENCH_PARTS
    found = [folder / f"{p}.md" for p in BENCH_PARTS if (folder / f"{p}.md").exists()]
    missing = [p for p in BENCH_PARTS if not (folder / f"{p}.md").exists()]
    out = [p.read_text() for p in found]
    if missing:
        out.append("Not recorded yet: " + ", ".join(f"`{p}`" for p in missing) + ".")
    return "\n".join(out)


PAGES = {"config.md": config_page, "variables.md": variables_page, "terms.md": terms_page,
         "families.md": families_page, "indicators.md": indicators_page,
         "commands.md": commands_page}


def write(folder, root: Path | None = None) -> list[Path]:
    """Every generated page into `folder` (the gallery too, given the repository root),
    rewriting only those whose text changed."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    texts = {name: make() for name, make in PAGES.items()}
    if root is not None:
        texts["gallery.md"] = gallery_page(root / "results", root / "workflows",
                                           "../results/")
        texts["bench.md"] = bench_page(root / "docs" / "bench")
    written = []
    for name, text in texts.items():
        path = folder / name
        text = re.sub(r"\n{3,}", "\n\n", text).rstrip() + "\n"
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        written.append(path)
    return written


if __name__ == "__main__":
    for p in write(sys.argv[1] if len(sys.argv) > 1 else "docs/_generated",
                   Path(__file__).parents[1]):
        print(p)
