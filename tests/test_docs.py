"""The documentation: the reference pages name every declared config key, archive
variable, term, family, indicator and command option (survey.reference generates them; a
declaration it leaves out fails here); each command's page is its --help; the gallery knows
every figure in results/; the TOML in the docs and the README is a valid config; the README
stays a door; and the site builds with Sphinx with warnings as errors."""
import argparse
import re
import subprocess
import sys
import tomllib
from dataclasses import MISSING, fields
from pathlib import Path

import pytest

from survey import reference

ROOT = Path(__file__).parents[1]


def test_the_config_reference_names_every_key_with_its_default():
    from survey.pipeline.families import EQUILIBRIA_KEYS, PERIODIC_KEYS
    from survey.pipeline.orbits import ORBIT_KEYS, PLANE_KEYS
    from survey.pipeline.schema import SCHEMA
    page = reference.config_page()
    tables = {f"[{t}]": keys for t, keys in SCHEMA.items()}
    tables |= {"[equilibria]": EQUILIBRIA_KEYS, "[periodic]": PERIODIC_KEYS,
               "[[orbit]]": ORBIT_KEYS, "[[plane]]": PLANE_KEYS}
    sections = dict(re.findall(r"(?ms)^### `(\[[^`]+\])`\n(.*?)(?=^##|\Z)", page))
    assert set(sections) == set(tables)
    for table, keys in tables.items():
        rows = {m[0]: m[1] for m in re.findall(r"(?m)^\| `(\w+)` \| [^|]+ \| ((?:[^|\\]|\\.)*) \|",
                                               sections[table])}
        assert list(rows) == list(keys), table
        for name, key in keys.items():
            if isinstance(key.default, (int, float)) and not isinstance(key.default, bool):
                assert rows[name] == reference._cell(reference._value(key.default)), \
                    (table, name)


def test_orbit_and_plane_declarations_are_their_specs_fields():
    from survey.pipeline.orbits import ORBIT_KEYS, PLANE_KEYS, OrbitSpec, PlaneSpec
    assert list(ORBIT_KEYS) == [f.name for f in fields(OrbitSpec)]
    assert list(PLANE_KEYS) == [f.name for f in fields(PlaneSpec)]
    for keys, spec in ((ORBIT_KEYS, OrbitSpec), (PLANE_KEYS, PlaneSpec)):
        for f in fields(spec):
            if f.default is MISSING:        # required, or a factory's empty table
                assert keys[f.name].default in (None, {}), f.name
            else:
                assert keys[f.name].default == f.default, f.name


def test_the_archive_reference_names_every_variable_status_and_family_variable():
    from survey.catalog.families import FAMILY_VARIABLES
    from survey.catalog.status import Status
    from survey.catalog.variables import VARIABLES
    page = reference.variables_page()
    named = set(re.findall(r"(?m)^\| `(\w+)` \|", page))
    assert {v.name for v in VARIABLES} <= named
    assert {v.name for vs in FAMILY_VARIABLES.values() for v in vs} <= named
    for s in Status:
        assert f"| {s.value} | `{s.name.lower()}` |" in page


def test_the_reference_names_every_term_family_indicator_threshold_and_regime():
    from survey.catalog.indicators import REGISTRY
    from survey.catalog.regimes import Regime, Thresholds
    from survey.physics.families import FAMILIES
    from survey.physics.terms import TERMS
    terms, families = reference.terms_page(), reference.families_page()
    indicators = reference.indicators_page()
    for t in TERMS:
        assert f"| {t.kind} | `{t.name}` |" in terms
        for p in t.parameters:
            assert reference._cell(p.describe()) in terms
    for name, family in FAMILIES.items():
        assert f"| `{name}` |" in families
        for param in family.defaults:
            assert param in families.split(f"| `{name}` |")[1].split("\n")[0]
    for i in REGISTRY:
        assert f"| `{i.name}` |" in indicators and i.reference in indicators
    for f in fields(Thresholds):
        assert f"| `{f.name}` |" in indicators
    for r in Regime:
        assert f"| {r.value} | `{r.name.lower()}` |" in indicators


def test_the_commands_reference_is_every_commands_help():
    """Each command's section is its --help as the command line prints it, so the
    reference cannot drift from the parser; and every option of every command has a
    help text of its own."""
    page = reference.commands_page()
    for name, parser in reference.subcommands().items():
        section = page.split(f"## `{name}`\n\n```text\n")[1].split("\n```")[0]
        assert section == reference.help_text(parser).rstrip()
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help, f"{name} {action.option_strings or action.dest}: no help"
            for flag in action.option_strings:
                assert flag in section


def test_the_help_a_user_gets_is_the_reference(capsys):
    from survey.cli import main
    with pytest.raises(SystemExit):
        main(["verify", "--help"])
    printed = capsys.readouterr().out
    assert "--cells" in printed and "bit for bit" in printed


def test_the_gallery_knows_every_figure_in_results():
    page = reference.gallery_page(ROOT / "results", ROOT / "workflows", "../results/")
    for png in sorted((ROOT / "results").glob("*.png")):
        assert f"![{png.name}](../results/{png.name})" in page
    with pytest.raises(KeyError, match="no_such_workflow_map_regime"):
        reference.figure_kind("no_such_workflow_map_regime",
                              reference.figure_owners(ROOT / "workflows"))


def test_a_recorded_bench_part_is_what_it_printed(tmp_path):
    from survey.cli import record_bench
    path = record_bench("step", "survey 277 ns an orbit-step\n", tmp_path, 0.0)
    text = path.read_text()
    assert text.startswith("## `step`") and "1970-01-01 00:00 UTC" in text
    assert "```text\nsurvey 277 ns an orbit-step\n```" in text
    page = reference.bench_page(tmp_path)
    assert text in page and "Not recorded yet: `scan`" in page


def toml_blocks(text: str) -> list[str]:
    return re.findall(r"(?ms)^```toml\n(.*?)^```", text)


def test_every_full_config_in_the_docs_and_readme_is_valid():
    """A TOML example with an [initial] table is a config a user may copy: it must load;
    a fragment must at least be TOML."""
    from survey.pipeline.config import load_config
    pages = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
    full = 0
    for page in pages:
        for block in toml_blocks(page.read_text()):
            tables = tomllib.loads(block)
            if "initial" in tables and "periodic" not in tables and \
                    "equilibria" not in tables:
                load_config(tables, check_output=False)
                full += 1
    assert full >= 3


def test_the_readme_is_a_door():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    commands = re.findall(r"(?m)^pip install .*$", text.split("## Two commands")[1])
    assert commands[:2] == ["pip install -e . && python -m survey run           # the "
                            "embedded default survey",
                            "pip install -e '.[test]' && python -m pytest -q     # the test "
                            "suite"]
    for link in re.findall(r"\]\(((?:docs|results)/[^)#]+)", text):
        assert (ROOT / link).exists(), link


def test_the_documentation_builds_without_a_warning(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b",
                           "html", str(ROOT / "docs"), str(tmp_path / "html")],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    built = (tmp_path / "html" / "reference" / "config.html").read_text()
    assert "connect_timeout" in built and "manifold_gap" in built
