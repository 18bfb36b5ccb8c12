"""results/ is what a reviewer reads first: every archive in it was written by the current
code from the workflow file whose text it stores, with its report and figures beside it."""
from pathlib import Path

import pytest
import xarray as xr

from survey.pipeline import orbits
from survey.pipeline.sweep import verify

ROOT = Path(__file__).parents[1]
RESULTS = ROOT / "results"
ARCHIVES = sorted(RESULTS.glob("*.nc"))


def workflow_of(archive: Path) -> Path:
    return ROOT / "survey" / "default.toml" if archive.stem == "default" \
        else ROOT / "workflows" / f"{archive.stem}.toml"


def test_every_survey_workflow_has_its_archive_report_and_figures():
    for path in sorted((ROOT / "workflows").glob("*.toml")):
        if orbits.is_orbit_workflow(path):
            for spec in orbits.load_workflow(path):
                assert list(RESULTS.glob(f"{spec.name}_*.png")), spec.name
            continue
        assert (RESULTS / f"{path.stem}.nc").exists(), path.stem
        assert (RESULTS / f"{path.stem}_report.md").exists(), path.stem
        assert list(RESULTS.glob(f"{path.stem}_*.png")), path.stem
        assert f"{path.stem}" in (RESULTS / "README.md").read_text()


@pytest.mark.parametrize("archive", ARCHIVES, ids=[a.stem for a in ARCHIVES])
def test_each_archive_stores_its_workflow_and_verifies(archive):
    """The stored config is the workflow file's text, and two recomputed cells (the first
    and the last) agree with the archive -- bit for bit on this kind of machine; on
    another, within rounding (1e-12 of the value)."""
    with xr.open_dataset(archive) as ds:
        assert ds.attrs["config"] == workflow_of(archive).read_text()
        assert not ds.attrs["git_commit"].endswith("-dirty")
    differences = {}
    ok, lines = verify(archive, cells=2, differences=differences)
    assert ok or max(differences.values()) <= 1e-12, lines
