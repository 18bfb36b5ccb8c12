"""results/ is what a reviewer reads first: every archive in it was written by the current
code from the workflow file whose text it stores, with its report and figures beside it."""
import tomllib
from pathlib import Path

import pytest
import xarray as xr

from survey.pipeline import orbits
from survey.pipeline.config import parse_config
from survey.pipeline.special import special_table
from survey.pipeline.sweep import verify

ROOT = Path(__file__).parents[1]
RESULTS = ROOT / "results"
ARCHIVES = sorted(RESULTS.glob("*.nc"))


def check_variant(archive: Path) -> str | None:
    """The [check] variant an archive is the run of, or None for a workflow's own."""
    stem, _, variant = archive.stem.rpartition("_check_")
    return variant if stem else None


def workflow_of(archive: Path) -> Path:
    stem = archive.stem.rpartition("_check_")[0] or archive.stem
    return ROOT / "survey" / "default.toml" if stem == "default" \
        else ROOT / "workflows" / f"{stem}.toml"


def stored_text(archive: Path) -> str:
    """The config text an archive must store: its workflow's, or for the [check] run of a
    workflow the text that run derives from it."""
    text = workflow_of(archive).read_text()
    if check_variant(archive):
        return parse_config(text, check_output=False).checks()[check_variant(archive)].text
    return text


def test_every_survey_workflow_has_its_archive_report_and_figures():
    for path in sorted((ROOT / "workflows").glob("*.toml")):
        if special_table(path):
            assert (RESULTS / f"{path.stem}.md").exists(), path.stem
            assert f"{path.stem}" in (RESULTS / "README.md").read_text()
            if "parameter" in tomllib.loads(path.read_text()).get("periodic", {}):
                assert (RESULTS / f"{path.stem}.png").exists(), path.stem  # its diagram
            continue
        if orbits.is_orbit_workflow(path):
            for spec in orbits.load_workflow(path):
                assert list(RESULTS.glob(f"{spec.name}_*.png")), spec.name
            continue
        assert (RESULTS / f"{path.stem}.nc").exists(), path.stem
        for variant in parse_config(path.read_text(), check_output=False).checks():
            assert (RESULTS / f"{path.stem}_check_{variant}.nc").exists(), path.stem
        assert (RESULTS / f"{path.stem}_report.md").exists(), path.stem
        assert list(RESULTS.glob(f"{path.stem}_*.png")), path.stem
        assert f"{path.stem}" in (RESULTS / "README.md").read_text()


@pytest.mark.parametrize("archive", ARCHIVES, ids=[a.stem for a in ARCHIVES])
def test_each_archive_stores_its_workflow_and_verifies(archive):
    """The stored config is the workflow file's text, and two recomputed cells (the first
    and the last) agree with the archive bit for bit, on any machine
    (tests/pipeline/test_portable_archives.py)."""
    with xr.open_dataset(archive) as ds:
        assert ds.attrs["config"] == stored_text(archive)
        assert not ds.attrs["git_commit"].endswith("-dirty")
    ok, lines = verify(archive, cells=2)
    assert ok, lines


def test_reproduce_replaces_only_what_changed_and_check_names_it(tmp_path, capsys):
    """`reproduce` into an empty folder writes everything; `--check` then exits 0; after a
    report is edited and a figure deleted, `reproduce` restores exactly those two and leaves
    the archive's file alone (its provenance would differ, its results do not)."""
    from survey.cli import main
    from survey.presentation.report import without_provenance
    run = ["reproduce", "--only", "default", "--results", str(tmp_path), "--no-progress"]
    assert main(run) == 0
    assert "updated" in capsys.readouterr().out
    assert main(run + ["--check"]) == 0, capsys.readouterr().out
    report, figure = tmp_path / "default_report.md", sorted(tmp_path.glob("default_*.png"))[0]
    made = report.read_text()
    report.write_text(made + "\nan edit\n")
    figure.unlink()
    archive = (tmp_path / "default.nc").read_bytes()
    assert main(run + ["--check"]) == 1
    out = capsys.readouterr().out
    assert report.name in out and figure.name in out, out
    assert main(run) == 0
    out = capsys.readouterr().out
    assert "updated 2 file(s)" in out and report.name in out and figure.name in out, out
    assert without_provenance(report.read_text()) == without_provenance(made)
    assert figure.exists() and (tmp_path / "default.nc").read_bytes() == archive
    assert not (tmp_path / ".staging").exists()
