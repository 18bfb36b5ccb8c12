"""Figures and reports, asserted on the figure objects (labels with symbols, masked cells
with counts, artists, legends) and on the report's text; every workflow in miniature; the
embedded default ending with its figures and report."""
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from matplotlib.collections import PolyQuadMesh, QuadMesh

from survey.analysis.onset import onset
from survey.catalog.regimes import Regime
from survey.cli import main, orbit_workflow
from survey.pipeline import orbits
from survey.pipeline.config import _to_toml, load_config
from survey.pipeline.sweep import run_survey
from survey.presentation import orbit_plots, plots, report

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def grid2(tmp_path_factory):
    """delta x energy with an energy too low for any start (masked cells)."""
    tmp = tmp_path_factory.mktemp("grid2")
    cfg = {"survey": {"name": "g2", "output": str(tmp / "g2.nc")},
           "initial": {"family": "equilateral", "delta": [0.5, 3.0, 4.5, 6.0],
                       "energy": [40.0, 84.45577136594005, 100.0]},
           "integration": {"t_final": 60.0}, "section": {"coordinate": "phi"}}
    return xr.open_dataset(run_survey(cfg))


@pytest.fixture(scope="module")
def grid1(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("grid1")
    cfg = {"survey": {"name": "g1", "output": str(tmp / "g1.nc")},
           "initial": {"family": "equilateral",
                       "delta": {"start": 3.0, "stop": 5.0, "num": 9}},
           "integration": {"t_final": 300.0}, "section": {"coordinate": "phi"}}
    return xr.open_dataset(run_survey(cfg))


def legend_texts(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_maps_label_axes_with_symbols_and_mask_unfinished_cells(grid2):
    figs = plots.figures(grid2)
    assert {"map_regime", "map_megno", "map_ftle", "map_fli", "map_birkhoff_digits",
            "section", "convergence"} <= set(figs)
    ax = figs["map_megno"].axes[0]
    assert ax.get_xlabel() == r"$\delta$" and ax.get_ylabel() == "$E$"
    colourbar = [a for a in figs["map_megno"].axes if "clipped to [0, 8]" in a.get_ylabel()]
    assert colourbar, "the clipping range is in the colourbar label"
    inaccessible = int((grid2.status.values == 5).sum())
    assert inaccessible == 4 and "inaccessible (4)" in legend_texts(ax)
    assert sum(isinstance(c, (QuadMesh, PolyQuadMesh)) for c in ax.collections) >= 2
    histogram = figs["map_megno"].axes[1]
    assert histogram.get_xlabel() == "cells" and len(histogram.patches) > 0
    regime_ax = figs["map_regime"].axes[0]
    texts = legend_texts(regime_ax)
    assert "inaccessible (4)" in texts and any(t.startswith("torus (") for t in texts)


def test_scan_shades_each_cell_by_regime_with_error_bars(grid1):
    fig = plots.figures(grid1)["scan"]
    axes = fig.axes
    assert [a.get_ylabel() for a in axes][:2] == [r"FTLE $\mu_T$ (1/time)",
                                                  r"MEGNO $\langle Y\rangle$"]
    assert axes[-1].get_xlabel() == r"$\delta$"
    n = grid1.sizes["delta"]
    assert len([p for p in axes[0].patches]) == n                   # one band per cell
    counts = {r.name.lower(): int((grid1.regime.values == r).sum()) for r in Regime}
    assert all(f"{name} ({k})" in legend_texts(axes[0]) for name, k in counts.items() if k)
    assert axes[0].containers                                       # error bars


def test_section_convergence_and_frequency_map(grid1):
    figs = plots.figures(grid1)
    section = figs["section"].axes[0]
    assert section.get_xlabel() == r"$\sigma$" and section.get_ylabel() == r"$p_\sigma$"
    assert all(c.get_rasterized() for c in section.collections)
    assert len(figs["convergence"].axes) == 3
    lines = figs["convergence"].axes[0].get_lines()
    assert len(lines) >= 2 and any("ln t / t" in ln.get_label() or "ln t" in ln.get_label()
                                   for ln in lines)
    fmap = figs["frequency_map"].axes[0]
    assert len(fmap.get_lines()) > 5                  # resonance lines of order <= 5
    assert "rotation" in fmap.get_xlabel()


def test_report_states_what_was_run_regimes_onset_and_thresholds(grid1, tmp_path):
    path = report.write(grid1, tmp_path, "g1")
    text = path.read_text()
    for heading in ("## What was run", "## Regimes", "## Where chaos sets in", "## Tori found",
                    "## Where the indicators agree", "## Thresholds used, and why",
                    "## Conservation and failures", "## Figures"):
        assert heading in text, heading
    assert "family `equilateral`" in text and "t = 300" in text
    assert "## Regimes along delta" in text and "- delta = 3 to " in text
    for name in ("g1_scan.png", "g1_convergence.png"):
        assert (tmp_path / name).exists() and f"({name})" in text
    lo, hi = report.wilson(5, 20)
    assert lo < 0.25 < hi and report.wilson(0, 10)[0] == 0.0


def test_onset_estimate():
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    r = np.array([Regime.TORUS, Regime.TORUS, Regime.CHAOTIC, Regime.TORUS, Regime.CHAOTIC,
                  Regime.CHAOTIC])
    found = onset(x, r)
    assert found["last_regular"] == 2.0 and found["first_irregular"] == 3.0
    assert found["estimate"] == 2.5 and found["error"] == 0.5
    assert found["all_irregular_from"] == 5.0
    assert onset(x, np.full(6, Regime.TORUS)) is None


def orbit_figures(spec):
    runs = orbits.run_orbits(spec)
    text = [line for run in runs for line in orbits.describe(spec, run)]
    return orbit_plots.spec_figures(spec.name, spec.zoom_until, runs), text


def test_single_orbit_figures_show_the_hill_disk_and_near_collisions():
    from matplotlib.patches import Circle
    figs, text = orbit_figures(orbits.OrbitSpec("sides", "sides", t_final=20.0))
    disk = [p for p in figs["paths"].axes[0].patches if isinstance(p, Circle)]
    assert len(disk) == 1 and disk[0].get_radius() == pytest.approx(8.00475 / 3, abs=1e-5)
    assert any("P_max" in line for line in text)
    assert figs["inequities"].axes[0].get_zlabel() == "$i_c$"
    figs, _ = orbit_figures(orbits.OrbitSpec("d45", "equilateral", {"delta": 4.5},
                                             t_final=25.0))
    marks = [ln for ln in figs["sides"].axes[0].get_lines() if ln.get_marker() == "v"
             and len(ln.get_xdata())]
    times = sorted(float(ln.get_xdata()[0]) for ln in marks)
    # the paper: b = 0.0924 at t = 0.498, a = 0.0440 at t = 20.212
    assert times[0] == pytest.approx(0.498, abs=0.01)
    assert any(abs(t - 20.212) < 0.01 for t in times)


def test_default_run_ends_with_figures_and_a_report(tmp_path, capsys):
    assert main(["run", "--output", str(tmp_path / "default.nc"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "report and figures:" in out and str(tmp_path / "default_report.md") in out
    assert (tmp_path / "default_scan.png").exists()


def miniature(path: Path, tmp: Path) -> dict:
    """A workflow's config with a tiny grid and a short run."""
    raw = tomllib.loads(path.read_text())
    raw["survey"]["output"] = str(tmp / f"{path.stem}.nc")
    def shrink(table):     # grid axes: {start, stop, num} or lists of numbers
        for key, value in table.items():
            if isinstance(value, dict):
                value["num"] = min(value["num"], 3)
            elif isinstance(value, list) and all(isinstance(v, (int, float)) for v in value):
                table[key] = value[:3]
    shrink(raw["initial"])
    system = raw.get("system", {})
    for params in [system.get("params", {})] + [t["params"] for t in system.get("interactions", [])]:
        shrink(params)
    raw.setdefault("integration", {})["t_final"] = 20.0
    raw.setdefault("dask", {})["workers"] = 1
    return raw


SURVEYS = [p for p in sorted((ROOT / "workflows").glob("*.toml"))
           if not orbits.is_orbit_workflow(p)]


@pytest.mark.parametrize("path", SURVEYS, ids=[p.stem for p in SURVEYS])
def test_every_survey_workflow_runs_in_miniature(path, tmp_path):
    ds = xr.open_dataset(run_survey(miniature(path, tmp_path)))
    written = report.write(ds, tmp_path, path.stem)
    figures = list(tmp_path.glob(f"{path.stem}_*.png"))
    assert written.exists() and figures
    assert set(np.unique(ds.regime.values)) <= set(Regime)


def test_the_orbit_workflow_runs_in_miniature(tmp_path):
    path = ROOT / "workflows" / "paper_orbits.toml"
    raw = tomllib.loads(path.read_text())
    for table in raw["orbit"]:
        table["t_final"] = 5.0
        table["zoom_until"] = min(table.get("zoom_until", 0.0), 5.0)
    small = tmp_path / "orbits.toml"
    small.write_text("\n".join(_orbit_table(t) for t in raw["orbit"]))
    written = orbit_workflow(small, tmp_path)
    assert {p.name for p in written} >= {"sides_paths.png", "equilateral_set_inequities.png",
                                         "areal_caption_perimeter_area.png"}


def _orbit_table(table: dict) -> str:
    return "[[orbit]]\n" + _to_toml({"x": table}).split("\n", 1)[1]


def test_the_workflows_cover_the_papers_figures():
    text = "\n".join(p.read_text() for p in (ROOT / "workflows").glob("*.toml"))
    for figure in ("SidesPhase", "SidesAreaPerim", "EquilateralPhase", "EquilateralSet",
                   "EquilPertSides", "ArealSidesPhase", "ArealPerimArea", "LyapunovSides",
                   "LyapunovScanEquil", "LinearIC"):
        assert figure in text, figure
    potentials = {load_config(p).tables["system"]["potential"] for p in SURVEYS
                  if len(load_config(p).axes) == 2 and "energy" in
                  {a.name for a in load_config(p).axes}}
    assert {"perimetric_power", "areal_barrier"} <= potentials


def test_the_accessor_classifies_draws_and_reports(grid1, tmp_path):
    from survey.analysis.classify import classify
    regime, confidence = grid1.survey.classify()
    np.testing.assert_array_equal(regime, grid1.regime.values)
    np.testing.assert_array_equal(confidence, classify(grid1)[1])
    assert set(grid1.survey.figures()) == set(plots.figures(grid1))
    written = grid1.survey.figures(tmp_path)
    assert (tmp_path / "g1_scan.png") in written
    path = grid1.survey.report(tmp_path)
    assert path == tmp_path / "g1_report.md" and "## Regimes" in path.read_text()


@pytest.mark.parametrize("energy", ["", "energy = [84.46, 90.0]\n"], ids=["scan", "map"])
def test_a_survey_whose_cells_all_fail_still_ends_with_a_report_that_says_so(energy, tmp_path,
                                                                              capsys):
    """Every cell stops at once (t_final = 1e-300: the step size collapses): the archive,
    its report and the figures that have something to show are written, exit 0."""
    cfg = tmp_path / "fail.toml"
    cfg.write_text(f'[survey]\nname = "fail"\noutput = "{tmp_path / "fail.nc"}"\n'
                   f'[initial]\nfamily = "equilateral"\ndelta = [1.0, 2.0]\n{energy}'
                   '[integration]\nt_final = 1e-300\n[indicators]\nrenorm_interval = 1e-301\n'
                   '[dask]\nworkers = 1\n')
    assert main([str(cfg), "--no-progress"]) == 0, capsys.readouterr().err
    text = (tmp_path / "fail_report.md").read_text()
    assert "**No cell finished**" in text
    figures = sorted(p.name for p in tmp_path.glob("fail_*.png"))
    assert figures == (["fail_map_regime.png"] if energy else ["fail_scan.png"]), figures
