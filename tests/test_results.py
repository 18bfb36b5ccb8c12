"""results/ is what a reviewer reads first: every archive in it was written by the current
code from the workflow file whose text it stores, with its report and figures beside it."""
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from survey.pipeline import orbits
from survey.pipeline.config import parse_config
from survey.catalog.families import FAMILY_VARIABLES
from survey.catalog.variables import V
from survey.pipeline.families import is_family, special_table, verify_family
from survey.pipeline.sweep import REPORT_ATTRIBUTES, verify
from survey.presentation.results_text import PLACEHOLDER, render

ROOT = Path(__file__).parents[1]
RESULTS = ROOT / "results"
ARCHIVES = sorted(RESULTS.glob("*.nc"))


def check_variant(archive: Path) -> str | None:
    """The [check] variant an archive is the run of, or None for a workflow's own."""
    stem, _, variant = archive.stem.rpartition("_check_")
    return variant if stem else None


def plane_of(archive: Path):
    """The [[plane]] spec of an orbit workflow whose manifolds an archive holds, or None."""
    for path in sorted((ROOT / "workflows").glob("*.toml")):
        if orbits.is_orbit_workflow(path):
            for spec in orbits.load_workflow(path):
                if f"{getattr(spec, 'name', '')}_plane" == archive.stem:
                    return spec
    return None


def workflow_of(archive: Path) -> Path:
    stem = archive.stem.rpartition("_check_")[0] or archive.stem
    return ROOT / "survey" / "default.toml" if stem == "default" \
        else ROOT / "workflows" / f"{stem}.toml"


def stored_text(archive: Path) -> str:
    """The config text an archive must store: its workflow's, or for the [check] run of a
    workflow the text that run derives from it."""
    plane = plane_of(archive)
    if plane is not None:
        return orbits.plane_text(plane)
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
                if getattr(spec, "manifolds", ()):
                    assert (RESULTS / f"{spec.name}_plane.nc").exists(), spec.name
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
    (tests/pipeline/test_portable_archives.py); an archive of an isosceles plane's
    manifolds stores its [[plane]] table and verifies its orbits, two points and its first
    homoclinic point. A survey archive stores what its report reads beside the cells --
    its resolved config, special cells and section slice (sweep.REPORT_ATTRIBUTES) -- so
    `python -m survey report` (which fills in what an archive lacks) and
    ds.survey.report() read the same, whoever writes it."""
    with xr.open_dataset(archive) as ds:
        assert ds.attrs["config"] == stored_text(archive)
        assert not ds.attrs["git_commit"].endswith("-dirty")
        if "family" not in ds.attrs:    # what its report needs from a solver, stored: the
            #                             command and ds.survey.report() write the same
            assert set(REPORT_ATTRIBUTES) <= set(ds.attrs), archive.name
        else:                           # a family's variables are the catalog's
            declared = {v.name: v for v in FAMILY_VARIABLES[ds.attrs["family"]]}
            assert set(ds.data_vars) == set(declared) - set(ds.coords)
            for name in ds.data_vars:
                assert ds[name].dims == declared[name].dims
                assert ds[name].attrs.get("long_name", "") == declared[name].long_name
    ok, lines = verify_family(archive, cells=2) if is_family(archive) else \
        verify(archive, cells=2)
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


NUMBER = re.compile(r"(?<![\w.^/-])-?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])")


def typed_numbers(text: str) -> list[str]:
    """The numbers typed in a text, outside its placeholders, code spans, file names and
    citations' years (Meiss 2023)."""
    text = PLACEHOLDER.sub(" ", text)
    text = re.sub(r"`[^`]*`", " ", text)
    text = re.sub(r"[A-Z][\w'-]+,? (?:19|20)\d\d\b", " ", text)
    return NUMBER.findall(text)


def unsourced(text: str, sources: str) -> list[str]:
    found = set(re.findall(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?", sources))
    return sorted({n for n in typed_numbers(text) if n.lstrip("-") not in found})


def number_sources() -> str:
    """Where a typed number may come from: the paper, the workflows, the embedded default
    and the configuration reference (SCHEMA's defaults)."""
    from survey.reference import config_page
    texts = [(ROOT / "tests" / "data" / "triplet-interactions.tex").read_text(),
             (ROOT / "survey" / "default.toml").read_text(), config_page(),
             (ROOT / "pyproject.toml").read_text()]
    texts += [p.read_text() for p in sorted((ROOT / "workflows").glob("*.toml"))]
    return "\n".join(texts)


def test_results_readme_is_what_reproduce_renders_and_every_number_has_a_source():
    """results/README.md is its template rendered from the archives and generated files in
    results/ (no number typed by hand), and every number typed in the template is the
    paper's, a workflow's or a default's: a number with no source fails."""
    template = (ROOT / "workflows" / "results_readme.md").read_text()
    assert (RESULTS / "README.md").read_text() == render(template, RESULTS)
    missing = unsourced(template, number_sources())
    assert not missing, f"numbers typed in workflows/results_readme.md with no source: " \
                        f"{missing}"


# the docs' engineering history: each number measured when its change was made (dated
# there), not a claim about the code as it is
HISTORY = "## Engineering notes on speed"


def test_the_docs_type_no_number_without_a_source():
    """The README and the documentation describe methods; what survey finds is in
    results/README.md and the reports, what it costs in the bench's recorded pages. A
    number they type must be the paper's, a workflow's, a default's or a constant's of the
    code, one a test asserts, or one a generated file in results/ quotes -- so a
    measurement typed by hand and since changed fails."""
    pages = [ROOT / "README.md"] + sorted(p for p in (ROOT / "docs").rglob("*.md")
                                          if p.parent.name not in ("_generated", "bench"))
    assert len(pages) > 20
    sources = "\n".join([number_sources()] + [p.read_text() for p in sorted(
        [*RESULTS.glob("*.md"), *(ROOT / "tests").rglob("*.py"),
         *(ROOT / "survey").rglob("*.py")])])
    for page in pages:
        missing = unsourced(page.read_text().split(HISTORY)[0], sources)
        assert not missing, f"{page.relative_to(ROOT)}: {missing}"


def test_the_number_source_test_can_fail():
    """A measured number typed into the prose is found; placeholders and code are not."""
    assert typed_numbers("an FTLE of 0.34 where {{cell a | ftle | delta=0}} says `x_0.2` "
                         "(Sander & Meiss 2025)") == ["0.34"]
    assert "0.34" not in re.findall(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?", number_sources())


@pytest.mark.parametrize("archive", [a for a in ARCHIVES if check_variant(a)],
                         ids=lambda a: a.stem)
def test_every_check_run_moves_the_orbits_not_only_the_ensembles(archive):
    """A [check] run that integrated the same nominal orbits bit for bit could not move the
    Birkhoff digits or the frequencies: in every run they differ at some chaotic cell the
    two runs share."""
    import numpy as np

    from survey.analysis.refine import as_grid
    from survey.catalog.regimes import Regime
    from survey.catalog.variables import V
    own = RESULTS / f"{workflow_of(archive).stem}.nc"
    with xr.open_dataset(own) as a, xr.open_dataset(archive) as b:
        a, b = as_grid(a), as_grid(b)
        (axis,) = a[V.status].dims
        common = np.intersect1d(a[axis].values, b[axis].values)
        a, b = a.sel({axis: common}), b.sel({axis: common})
        chaotic = a[V.regime].values == Regime.CHAOTIC
        assert chaotic.any()
        assert np.any(a[V.birkhoff_digits].values[chaotic] != b[V.birkhoff_digits].values[chaotic])
        assert np.any(np.any(a[V.frequency].values[chaotic] != b[V.frequency].values[chaotic],
                             axis=-1))


def test_a_family_dataset_holds_what_the_catalog_declares():
    """pipeline.archive.family_dataset refuses a variable the catalog does not declare for
    the family, and one it declares that is not given."""
    from survey.pipeline.archive import family_dataset
    names = [v.name for v in FAMILY_VARIABLES["equilibria"]]
    values = {name: [] for name in names}
    values["positions"] = np.zeros((0, 3, 2))
    values["eigenvalue_real"] = values["eigenvalue_imag"] = np.zeros((0, 4))
    ds = family_dataset("equilibria", values, "mass_1", attrs={"config": ""})
    assert list(ds.data_vars) == names and ds.attrs["family"] == "equilibria"
    assert ds["bifurcation_parameter"].attrs["long_name"].startswith("mass_1 where")
    with pytest.raises(ValueError, match="period"):
        family_dataset("equilibria", {**values, "period": []})
    with pytest.raises(ValueError, match="stable"):
        family_dataset("equilibria", {k: v for k, v in values.items() if k != "stable"})


def share_rows(report: str) -> dict:
    """A share report's table rows by their first cell: the cells after it."""
    rows = {}
    for line in (RESULTS / report).read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 9 and cells[3].endswith("%") and re.match(r"[0-9.]+$", cells[0]):
            rows[cells[0]] = cells[1:]
    return rows


def test_the_calibration_prose_holds_for_its_archives():
    """What results/README.md says of the calibration in words: Henon-Heiles at E = 1/12
    agrees with the published share and with their criterion on survey's orbits; at 1/8
    with neither, the criterion's share above the published one and survey's below; at 1/6
    survey's share does not agree and the criterion's does. Toda: no start chaotic or
    sticky; its undetermined starts have no Lyapunov-type vote for chaos and a Birkhoff or
    diffusion vote for it; at T = 20000 every start a torus."""
    import json

    from survey.analysis.classify import evidence_votes
    from survey.catalog.regimes import Regime, Thresholds
    rows = share_rows("henon_heiles_share_report.md")
    agree = {e: (r[5], r[7]) for e, r in rows.items()}
    assert agree == {"0.0833333": ("yes", "yes"), "0.125": ("**no**", "**no**"),
                     "0.166667": ("**no**", "yes")}, agree
    share = {e: float(r[2].rstrip("%")) for e, r in rows.items()}
    criterion = {e: float(r[6].split("%")[0]) for e, r in rows.items()}
    assert share["0.125"] < 70 < criterion["0.125"]
    with xr.open_dataset(RESULTS / "toda_share.nc") as ds:
        regime = ds[V.regime].values
        assert not np.isin(regime, [Regime.CHAOTIC, Regime.STICKY]).any()
        votes = evidence_votes(ds, Thresholds(**json.loads(ds[V.regime].attrs["thresholds"])))
        undecided = regime == Regime.UNDETERMINED
        assert undecided.any()
        for line in ("ftle", "megno", "sali"):
            assert not (votes[line][undecided] == -1).any(), line
        assert np.all((votes["wba"][undecided] == -1) | (votes["diffusion"][undecided] == -1))
    with xr.open_dataset(RESULTS / "toda_share_t20000.nc") as ds:
        assert np.all(ds[V.regime].values == Regime.TORUS)


def test_no_cell_escapes_below_its_dissociation_energy():
    """What results/README.md says of the escapes: in every shipped archive that watches
    for them, each escaped cell's energy is above the dissociation energy its archive
    stores (no bound cell flagged), and the LJAT trimer map has escaped cells to check."""
    import json

    from survey.catalog.status import Status
    seen = {}
    for path in sorted(RESULTS.glob("*.nc")):
        with xr.open_dataset(path) as ds:
            if V.escape_time not in ds:
                continue
            escaped = ds[V.status].values == Status.ESCAPED
            seen[path.stem] = int(escaped.sum())
            threshold = json.loads(ds.attrs.get("dissociation_energy", "null"))
            if threshold is None or not escaped.any():
                continue
            energy = ds[V.energy].broadcast_like(ds[V.status]).values
            assert np.all(energy[escaped] >= threshold), path.stem
    assert seen.get("ljat_trimer_map", 0) > 0 and seen.get("henon_heiles_escape", 0) > 0, seen


def test_the_areal_maps_chaos_prose_holds():
    """What results/README.md says of the areal map in words: its chaotic cells spend most
    of their run in thin triangles (the median thin share above one half), and the FTLE
    falls as the thin share grows (a negative rank correlation)."""
    from survey.catalog.regimes import Regime
    from survey.presentation.report import rank_correlation
    with xr.open_dataset(RESULTS / "delta_energy_map_areal.nc") as ds:
        chaotic = ds[V.regime].values == Regime.CHAOTIC
        thin = ds[V.thin_share].values
        assert np.median(thin[chaotic]) > 0.5
        ftle = ds[V.ftle].values
        drawn = np.isfinite(ftle) & (ftle > 0)
        assert rank_correlation(ftle[drawn], thin[drawn]) < -0.3


@pytest.mark.parametrize("name", ["delta_energy_map_areal", "linear_family", "default",
                                  "ljat_trimer_map"])
def test_the_special_solutions_an_archive_stores_are_what_the_code_computes(name):
    """The report's special solutions (the homographic orbits shot, the equilibria, the
    dissociation energy of a map over a term's parameter) are computed once, when the
    archive is written: computed again from the archive, they are the same text."""
    from survey.pipeline.special import report_attributes
    with xr.open_dataset(RESULTS / f"{name}.nc") as ds:
        fresh = report_attributes(ds.load())
        assert fresh == {k: ds.attrs[k] for k in fresh}
