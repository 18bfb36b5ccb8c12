"""Figures and reports, asserted on the figure objects (labels with symbols, masked cells
with counts, artists, legends) and on the report's text; every workflow in miniature; the
embedded default ending with its figures and report."""
import os
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from matplotlib.collections import PolyQuadMesh, QuadMesh

from survey.analysis.onset import onset
from survey.catalog.errors import ConfigError
from survey.catalog.regimes import Regime
from survey.catalog.status import Status
from survey.catalog.variables import V
from survey.cli import main, orbit_workflow
from survey.pipeline import orbits
from survey.pipeline.families import special_table
from survey.pipeline.config import _to_toml, load_config
from survey.pipeline.sweep import run_survey
from survey.presentation import orbit_plots, plots, report, sections

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
           "integration": {"t_final": 300.0}, "section": {"coordinate": "phi"},
           "indicators": {"perturbations": 1}}
    return xr.open_dataset(run_survey(cfg))


def legend_texts(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_maps_label_axes_with_symbols_and_mask_unfinished_cells(grid2):
    figs = plots.figures(grid2)
    assert {"map_regime", "map_megno", "map_ftle", "map_fli", "map_birkhoff_digits",
            "convergence"} <= set(figs)
    # twelve cells on twelve energy shells: no section overlays them, and the report says
    assert "section" not in figs and len(plots.shells(grid2)) > plots.MAX_SHELLS
    assert "No section figure: the cells start on" in report.markdown(grid2, ["x.png"])
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
    hatched = [p for p in axes[0].patches if p.get_hatch()]
    assert len(axes[0].patches) - len(hatched) == n                 # one band per cell
    # and a hatch over each cell whose verdict is not that of the horizon before
    assert len(hatched) == int(plots.unconfirmed(grid1).sum())
    counts = {r.name.lower(): int((grid1.regime.values == r).sum()) for r in Regime}
    regimes = [t.get_text() for t in fig.legends[0].get_texts()]    # the figure's legend
    assert all(f"{name} ({k})" in regimes for name, k in counts.items() if k)
    bars = [c for c in axes[0].collections if c.get_label().startswith("5-95%")]
    assert bars and bars[0].get_label() == "5-95% of 2 orbits (indicative)"   # the ensemble


def test_a_scan_compares_every_cell_at_one_horizon(grid1):
    """A cell run to 4 T is drawn at T from its history on the line of the others, and its
    value at 4 T apart, as a marker the legend names -- not a spike on the same line."""
    longer = grid1.copy(deep=True)
    horizon = longer["regime_horizon"].values
    T = float(horizon.min())
    i = int(np.flatnonzero(horizon == T)[0])
    horizon[i] = 4 * T
    longer["fli"].values[i] = 1e6                        # what the longer run reached
    ax = plots.scan(longer, ["fli"]).axes[0]
    texts = legend_texts(ax)
    assert f"every cell at T = {T:g}" in texts
    assert f"cells run longer, at 4 T ({int(np.sum(horizon > T))})" in texts
    line = next(l for l in ax.get_lines() if l.get_label().startswith("every cell"))
    k = int(np.argmin(np.abs(longer["history_time"].values - T)))
    assert line.get_ydata()[i] == longer["fli_history"].values[i, k] != 1e6
    marker = next(l for l in ax.get_lines() if l.get_label().startswith("cells run longer"))
    assert 1e6 in list(marker.get_ydata())


def test_section_convergence_and_frequency_map(grid1):
    figs = plots.figures(grid1)
    # nine deltas, nine energy shells: one panel each, titled by its shell, never overlaid
    panels = [a for a in figs["section"].axes if a.get_visible()]
    assert len(panels) == 9 == len(plots.shells(grid1))
    energy = grid1.energy.values
    for ax, e in zip(panels, energy):
        assert ax.get_title().startswith(f"E = {e:.6g}, J = ") and "(1 cell)" in ax.get_title()
    section = panels[0]
    assert section.get_xlabel() == r"$\sigma$" and section.get_ylabel() == r"$p_\sigma$"
    assert all(c.get_rasterized() for c in section.collections)
    # it says what it is: a projection of the 4-D section
    note = figs["section"].get_supxlabel() if hasattr(figs["section"], "get_supxlabel") \
        else figs["section"]._supxlabel.get_text()
    assert "every crossing projected onto (sigma, p_sigma)" in note.replace("\n", " ")
    assert len(figs["convergence"].axes) == 3
    lines = figs["convergence"].axes[0].get_lines()
    assert len(lines) >= 2 and any("ln t / t" in ln.get_label() or "ln t" in ln.get_label()
                                   for ln in lines)
    fmap = figs["frequency_map"].axes[0]
    assert len(fmap.get_lines()) > 5                  # resonance lines of order <= 5
    # a shape frequency divides, never the rotation (not a frequency of the reduced flow)
    assert "shape_3" in fmap.get_xlabel() and "rotation" not in fmap.get_xlabel()


def test_report_states_what_was_run_regimes_onset_and_thresholds(grid1, tmp_path):
    path = report.write(grid1, tmp_path, "g1")
    text = path.read_text()
    for heading in ("## What was run", "## Regimes", "## Spread over nearby orbits",
                    "## Where chaos sets in", "## Tori found",
                    "## Where the indicators agree", "## Thresholds used, and why",
                    "## Conservation and failures", "## Figures"):
        assert heading in text, heading
    # grid1 runs one perturbed start: two orbits per cell, said to be indicative only
    assert "an ensemble of 2 orbits per cell" in text and "indicative only" in text
    assert "Wilson" not in text and "95% interval" not in text
    assert "family `equilateral`" in text and "t = 300" in text
    assert "## Regimes along delta" in text and "- delta = 3 to " in text
    for name in ("g1_scan.png", "g1_convergence.png"):
        assert (tmp_path / name).exists() and f"({name})" in text


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
    for params in [system.get("params", {})] + [t.get("params", {})
                                                for t in system.get("interactions", [])]:
        shrink(params)
    if "starts_per_cell" in raw["initial"]:
        raw["initial"]["starts_per_cell"] = min(raw["initial"]["starts_per_cell"], 3)
    if "reference" in raw:       # the published values the shrunk grid still holds
        ref = raw["reference"]
        keep = [i for i, v in enumerate(ref["at"]) if v in raw["initial"][ref["axis"]]]
        ref["at"] = [ref["at"][i] for i in keep]
        ref["regular_share"] = [ref["regular_share"][i] for i in keep]
    raw.setdefault("integration", {})["t_final"] = 20.0
    raw.setdefault("dask", {})["workers"] = 1
    return raw


SURVEYS = [p for p in sorted((ROOT / "workflows").glob("*.toml"))
           if not orbits.is_orbit_workflow(p) and not special_table(p)]


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


def test_figures_drawn_in_two_processes_are_those_drawn_in_one(grid1, tmp_path, monkeypatch):
    one = plots.save(plots.figures(grid1), tmp_path / "one", "g1")
    here, save, marks = os.getpid(), plots._save, tmp_path / "marks"
    marks.mkdir()

    def marked(plan, names, paths, then=None):       # which process drew which figures
        with open(marks / str(os.getpid()), "a") as f:
            f.write(" ".join(names) + "\n")
        if os.getpid() != here and then is not None:
            then()
        save(plan, names, paths)

    def fails():
        raise RuntimeError("the second process fails")

    def hangs():
        time.sleep(600)

    for then, folder in [(None, "two"), (fails, "failed"), (hangs, "hung")]:
        for f in marks.iterdir():
            f.unlink()
        monkeypatch.setattr(plots, "_save", lambda *a, then=then: marked(*a, then))
        monkeypatch.setattr(plots, "PATIENCE", 1.0)
        drawn = plots.draw(grid1, tmp_path / folder, "g1")
        assert [p.name for p in drawn] == [p.name for p in one] and len(one) >= 3
        for a, b in zip(one, drawn):
            assert a.read_bytes() == b.read_bytes(), (folder, a.name)
        by = {f.name == str(here): [line.split() for line in f.read_text().splitlines()]
              for f in marks.iterdir()}
        names = [p.name[3:-4] for p in one]
        assert by[False] == [names[1::2]], folder       # the second process had its share
        # and this one drew it again where that one failed or hung
        assert by[True] == [names[0::2]] + ([names[1::2]] if then else []), folder


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


def test_the_orbit_command_takes_a_survey_config_with_its_system(tmp_path, capsys):
    """`orbit grid.toml --cell K`: the cell's start under the config's [system] (here two
    terms, masses of 2 weighting the pair term by 4), with E, J, the ranges of P, |A|, I and the closest approaches;
    the same numbers as the survey's own start and energy."""
    cfg = tmp_path / "grid.toml"
    cfg.write_text("""
[survey]
name = "mixed"
output = "%s"
[system]
masses = [2.0, 2.0, 2.0]
interactions = [
  {kind = "triplet", potential = "perimetric_power", params = {coupling = 1.0, exponent = 2.0}},
  {kind = "pair", potential = "power", mass_weighted = true, params = {coupling = -1.0, exponent = -1.0}},
]
[initial]
family = "equilateral"
delta = [1.0, 3.0, 4.0]
[integration]
t_final = 30.0
""" % (tmp_path / "mixed.nc"))
    assert main(["orbit", str(cfg), "--cell", "1", "--plot", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    from survey.pipeline.cells import build_starts
    from survey.pipeline.config import load_config
    config = load_config(cfg)
    system = config.system(1)
    y0 = build_starts(config)[1]
    assert f"E = {system.energy(y0):.10g}" in out and "equilateral (delta = 3)" in out
    assert "times m_i m_j" in out and "masses [2.0, 2.0, 2.0]" in out
    assert "P in [" in out and "|A| in [" in out and "I in [" in out
    assert out.count(" at t = ") == 3                      # three pairs
    assert (tmp_path / "mixed_paths.png").exists()
    # all three cells form a set (drawn together in inequity space); a grid too large for
    # one set names --cell
    assert main(["orbit", str(cfg)]) == 0
    assert capsys.readouterr().out.count("E = ") == 3
    big = tmp_path / "big.toml"
    big.write_text(cfg.read_text().replace("[1.0, 3.0, 4.0]", "{start = 0, stop = 4, num = 9}"))
    assert main(["orbit", str(big)]) == 2
    assert "--cell: 9 orbits is too many" in capsys.readouterr().err


def test_closest_approach_and_ranges_match_an_exact_kepler_orbit():
    """The closest approach of a two-body Kepler orbit is its pericentre a (1 - e), at the
    times the period says; the parabolic refinement finds it between samples."""
    import math

    from survey.physics.system import System
    from survey.physics.terms import make_potential
    s = System(np.array([1.0, 0.25]), 2, make_potential("gravity", {}, "pair"))
    a, e, M = 1.0, 0.5, 1.25
    r = a * (1 + e)                                   # start at apocentre
    v = math.sqrt(M * (1 - e) / r)
    mu = 0.25 / M
    y0 = s.state([[-0.25 / M * r, 0.0], [1 / M * r, 0.0]], [[0.0, -mu * v], [0.0, mu * v]])
    from survey import integrate
    period = 2 * math.pi * math.sqrt(a ** 3 / M)
    t = np.linspace(0.0, 1.3 * period, 1001)
    out = integrate(s, y0, t[-1], t_eval=t, rtol=1e-12, atol=1e-12)
    lines = orbits.shape_ranges(s, t, out.samples)
    tk, rk = orbits.closest(t, np.linalg.norm(np.diff(s.split(out.samples)[0], axis=1)[:, 0],
                                              axis=-1))
    assert rk == pytest.approx(a * (1 - e), rel=1e-6)
    assert tk == pytest.approx(period / 2, rel=1e-4)
    assert lines[-1] == f"closest approaches: 0-1: {rk:.4g} at t = {tk:.6g}"


def test_long_orbits_stay_readable_faded_paths_and_bands():
    """At T = 2000 (20001 samples) paths fade with time and time series become min-max bands
    instead of a solid block of lines; zoom_until still draws the paths up to it."""
    from matplotlib.collections import LineCollection, PolyCollection
    spec = orbits.OrbitSpec("long", "equilateral", {"delta": 3.0}, t_final=2000.0)
    figs, _ = orbit_figures(spec)
    paths = figs["paths"].axes[0]
    fading = [c for c in paths.collections if isinstance(c, LineCollection)]
    assert len(fading) == 3 and "fading" in paths.get_title()
    alphas = fading[0].get_colors()[:, 3]
    assert alphas[0] < 0.01 < alphas[-1] == 1.0
    bands = [c for c in figs["perimeter_area"].axes[0].collections
             if isinstance(c, PolyCollection)]
    assert len(bands) == 1 and "band" in figs["perimeter_area"].axes[0].get_title()
    zoomed, _ = orbit_figures(orbits.OrbitSpec("z", "equilateral", {"delta": 3.0},
                                               t_final=2000.0, zoom_until=20.0))
    assert "t = 20" in zoomed["paths"].axes[0].get_title()
    assert not [c for c in zoomed["paths"].axes[0].collections if isinstance(c, LineCollection)]


def test_an_orbit_workflow_takes_a_system_table(tmp_path):
    """[[orbit]] tables take any survey [system] (masses, interactions) instead of
    potential/potential_params; its mistakes are named by the orbit's keys."""
    path = tmp_path / "orbits.toml"
    table = """[[orbit]]
name = "lagrange"
family = "explicit"
params = {positions = [[0.0, 0.5774], [-0.5, -0.2887], [0.5, -0.2887]], velocities = [[-0.5774, 0.0], [0.2887, -0.5], [0.2887, 0.5]]}
system = {masses = [1.0, 1.0, 1.0], interactions = [{kind = "pair", potential = "gravity", params = {G = 1.0}}]}
t_final = 1.0
"""
    path.write_text(table)
    spec, = orbits.load_workflow(path)
    run, = orbits.run_orbits(spec)
    assert run.system.terms[0].name == "gravity" and run.system.terms[0].mass_weighted
    path.write_text(table.replace("masses = [1.0, 1.0, 1.0]", "masses = [1.0, 1.0]"))
    with pytest.raises(ConfigError, match=r"\[\[orbit\]\] 1.system.masses: needs 3 values"):
        orbits.load_workflow(path)
    path.write_text(table + 'potential = "areal_power"\n')
    with pytest.raises(ConfigError, match="either system or potential"):
        orbits.load_workflow(path)


def test_every_survey_figure_says_what_it_is_of_and_labels_its_lines(grid1):
    """Titles name the family, the potential, T and what varies, wrapped to the figure's
    width; threshold lines say which vote they bound and where; a value a log axis cannot
    show is marked at its edge."""
    figs = plots.figures(grid1)
    for name, fig in figs.items():
        lines = fig._suptitle.get_text().split("\n")
        assert max(map(len, lines)) <= 15 * fig.get_figwidth(), name     # never cut off
        title = " ".join(lines)
        assert "g1: equilateral family under perimetric_power, T = 300" in title, name
        assert "delta varied over 9 cells" in title, name
    megno = figs["scan"].axes[1]
    labels = [ln.get_label() for ln in megno.get_lines()]
    assert "regular vote 2.25" in labels and any(t.startswith("chaotic vote") for t in labels)
    ftle = figs["scan"].axes[0]
    assert any("ln T / T" in ln.get_label() for ln in ftle.get_lines())
    shrunk = grid1.copy(deep=True)
    shrunk["ftle"].values[2] = -0.01
    ftle = plots.figures(shrunk)["scan"].axes[0]
    assert ftle.get_yscale() == "log"
    assert any(ln.get_label() == "<= 0, off the log axis (1)" for ln in ftle.get_lines())
    assert figs["convergence"].axes[0].get_yscale() == "symlog"


def test_onsets_only_along_axes_where_they_mean_something():
    """An onset along a section coordinate or a potential's parameter means nothing (the
    cells are other orbits of one shell, or other systems): the report says why instead;
    a map with one meaningful axis gives its onset along that axis."""
    x = np.linspace(0.0, 1.0, 5)
    line = np.array([0, 0, 4, 4, 4])

    def axis(name, long_name):
        return xr.Dataset(coords={name: (name, x, {"long_name": long_name})})
    text = "\n".join(report._onsets(axis("sigma", "initial-condition parameter sigma"),
                                    ["sigma"], line))
    assert "Where chaos sets in" not in text and "coordinate of the starts" in text
    text = "\n".join(report._onsets(axis("delta", "initial-condition parameter delta"),
                                    ["delta"], line))
    assert "Onset delta = 0.375 +- 0.12 (the root sum of squares" in text
    assert "| half the grid step | — | 0.12 |" in text
    assert "Not measured, so not in this uncertainty: seed" in text
    energy = np.array([1.0, 2.0, 3.0])
    ds = xr.Dataset(coords={
        "axilrod_teller_strength": ("axilrod_teller_strength", x, {
            "long_name": "parameter strength of the triplet term axilrod_teller"}),
        "energy": ("energy", energy, {"long_name": "initial-condition parameter energy"})})
    grid = np.tile([0, 0, 4], (5, 1))                    # chaos sets in along the energy
    text = "\n".join(report._onsets(ds, ["axilrod_teller_strength", "energy"], grid))
    assert "along energy, for each axilrod_teller_strength" in text
    assert "No onset is given along axilrod_teller_strength: " in text
    assert text.count("| 2.5 +- 0.5 |") == 5


def test_an_unevenly_spaced_scan_is_drawn_cell_by_cell(grid1):
    """Energies crowding towards a minimum (steps differing by more than 10x) are drawn one
    cell per step with their values as tick labels, not packed on a linear axis."""
    crowded = grid1.assign_coords(delta=3.0 + np.array([0, 1, 2, 4, 8, 16, 32, 64, 128]) / 64)
    ax = plots.scan(crowded, ["ftle"]).axes[-1]
    assert "unevenly spaced" in ax.get_xlabel()
    assert list(ax.get_xticks()) == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]
    assert ax.get_xticklabels()[-1].get_text() == "5"
    even = plots.scan(grid1, ["ftle"]).axes[-1]
    assert "unevenly" not in even.get_xlabel()


def test_a_slice_grid_draws_only_the_crossings_in_its_slab(tmp_path):
    """A grid over (sigma, p_sigma) at eta = 3, p_eta = 0 is a 2-D slice of the 4-D
    section: its MEGNO map's overlay keeps only the crossings within 2.5% of each fixed
    coordinate's range of it, and says so with the counts; the section figure of the one
    shell says it is a projection, and no more."""
    cfg = {"survey": {"name": "slice", "output": str(tmp_path / "slice.nc")},
           "initial": {"family": "section", "energy": 84.45577136594005,
                       "angular_momentum": 24.401923788646684, "sigma": [2.0, 3.0, 4.0],
                       "p_sigma": [-1.0, 1.0], "eta": 3.0, "p_eta": 0.0},
           "integration": {"t_final": 200.0}, "section": {"coordinate": "phi"},
           "indicators": {"perturbations": 0}}
    ds = xr.open_dataset(run_survey(cfg))
    from survey.pipeline.special import section_slice
    slice_at = section_slice(ds)
    assert slice_at == {"eta": 3.0, "p_eta": 0.0}
    figs = plots.figures(ds, slice_at=slice_at)
    ax = figs["map_megno_section"].axes[0]
    keep, _ = sections.slice_slab(ds, slice_at)
    total = int(np.isfinite(ds.crossing_sigma.values).sum())
    assert 0 < keep.sum() < total
    assert len(ax.collections[-1].get_offsets()) == keep.sum()
    for q, q0 in (("eta", 3.0), ("p_eta", 0.0)):
        values = ds[f"crossing_{q}"].values.ravel()
        width = sections.SLAB * (np.nanmax(values) - np.nanmin(values))
        assert np.all(np.abs(values[keep] - q0) <= width)
    assert "the grid is a 2-D slice of the 4-D section" in ax.get_xlabel()
    assert f"{int(keep.sum())} of {total})" in ax.get_xlabel().replace("\n", " ")
    panels = [a for a in figs["section"].axes if a.get_visible()]
    assert len(panels) == 1 and panels[0].get_title().startswith("E = 84.4558, J = 24.4019")


def test_one_shell_is_drawn_as_3d_slices_and_a_projection_coloured_by_the_fourth(tmp_path):
    """Seeded starts filling one (E, J) shell: its 4-D section drawn as the slice
    |p_eta| <= 2.5% of p_eta's range in (sigma, p_sigma, eta) from three sides (exactly the
    crossings in the slab; regular starts coloured by their frequency), the projection of
    every crossing coloured by p_eta, and a caption that states shell, slice and counts.
    A seed axis has no order: no scan and no boundaries along it."""
    cfg = {"survey": {"name": "shell", "output": str(tmp_path / "shell.nc")},
           "initial": {"family": "section_sample", "energy": 84.45577136594005,
                       "angular_momentum": 24.401923788646684, "seed": [0, 1, 2, 3]},
           "integration": {"t_final": 300.0},
           "section": {"coordinate": "phi", "max_crossings": 400},
           "indicators": {"perturbations": 0}}
    ds = xr.open_dataset(run_survey(cfg))
    figs = plots.figures(ds)
    assert "scan" not in figs and "section_slice" in figs
    from survey.analysis.classify import summary
    assert len(summary(ds)) == 1                       # the regime counts, no boundaries
    fig = figs["section_slice"]
    views = [a for a in fig.axes if a.name == "3d"]
    assert len(views) == 3
    p_eta = ds.crossing_p_eta.values
    width = sections.SLAB * (np.nanmax(p_eta) - np.nanmin(p_eta))
    inside = np.abs(p_eta) <= width
    total = int(np.isfinite(p_eta).sum())
    assert 0 < inside.sum() < total
    for ax in views:
        assert sum(len(c.get_offsets()) for c in ax.collections) == inside.sum()
        assert (ax.get_xlabel(), ax.get_ylabel()) == (r"$\sigma$", r"$p_\sigma$")
    assert views[0].get_zlabel() == r"$\eta$"
    regular = np.isin(ds.regime.values, [Regime.TORUS, Regime.RESONANT, Regime.PERIODIC])
    coloured = [c for c in views[0].collections if c.get_array() is not None]
    if regular.any():
        nu = ds.frequency.isel(fundamental=0).values
        np.testing.assert_array_equal(
            np.sort(coloured[0].get_array()),
            np.sort(np.broadcast_to(nu[:, None], p_eta.shape)[inside & regular[:, None]]))
    projection = [a for a in fig.axes if a.name != "3d" and a.get_xlabel() == r"$\sigma$"][0]
    np.testing.assert_array_equal(projection.collections[0].get_array(),
                                  p_eta[np.isfinite(p_eta)])
    caption = fig.get_supxlabel() if hasattr(fig, "get_supxlabel") else fig._supxlabel.get_text()
    caption = caption.replace("\n", " ")
    assert "one energy shell E = 84.45577, J = 24.40192, surface of section phi = 1.5708" \
        in caption
    assert f"({int(inside.sum())} of {total} crossings)" in caption
    # seeded starts are a random sample of the shell: the report gives the regular share
    # with its 95% Wilson interval (scipy's, independently), and no regimes "along" seeds
    from scipy.stats import binomtest
    text = report.markdown(ds, ["shell_section_slice.png"])
    decided = np.isin(ds.regime.values, [0, 1, 2, 3, 4, 8])
    k, n = int(regular.sum()), int(decided.sum())
    ci = binomtest(k, n).proportion_ci(method="wilson")
    assert (f"of the {n} decided, {k} are regular, a regular share of {100 * k / n:.0f}% "
            f"(95% Wilson interval {100 * ci.low:.0f}-{100 * ci.high:.0f}%") in text
    assert "Regimes along seed" not in text and "in no order" in text


def test_starts_per_cell_give_each_point_a_regular_share_with_its_interval(tmp_path):
    """[initial] starts_per_cell = M: M seeded starts per grid point (a last axis `seed`
    from the family's seed), kept one by one in the archive; each point's regular share of
    its decided starts with the 95% Wilson interval (scipy's, independently) in the
    report's table and as the figure's bars; no per-cell maps or onsets over seeds."""
    from scipy.stats import binomtest
    cfg = {"survey": {"name": "ens", "output": str(tmp_path / "ens.nc")},
           "initial": {"family": "section_sample", "energy": [84.45577136594005, 95.0],
                       "angular_momentum": 24.401923788646684, "seed": 5,
                       "starts_per_cell": 5},
           "integration": {"t_final": 200.0}, "indicators": {"perturbations": 0}}
    ds = xr.open_dataset(run_survey(cfg))
    assert ds.regime.dims == ("energy", "seed") and ds.seed.values.tolist() == [5, 6, 7, 8, 9]
    from survey.analysis.classify import regular_share
    share = regular_share(ds)
    text = report.markdown(ds, ["ens_regular_share.png"])
    assert "## Regular share per grid point (5 seeded starts each)" in text
    fig = plots.figures(ds)
    assert "regular_share" in fig and not any(k.startswith(("map", "scan")) for k in fig)
    bars = fig["regular_share"].axes[0].containers[0]
    for i, energy in enumerate(ds.energy.values):
        regime = ds.regime.values[i]
        n = int(np.isin(regime, [0, 1, 2, 3, 4, 8]).sum())
        k = int(np.isin(regime, [0, 1, 2, 8]).sum())
        assert (int(share.decided[i]), int(share.regular[i])) == (n, k)
        ci = binomtest(k, n).proportion_ci(method="wilson")
        assert float(share.share_low[i]) == pytest.approx(ci.low, abs=1e-9)
        assert float(share.share_high[i]) == pytest.approx(ci.high, abs=1e-9)
        assert (f"| {energy:g} | {n} | {k} | {100 * k / n:.0f}% | {100 * ci.low:.0f}-"
                f"{100 * ci.high:.0f}% |") in text
        x, y = bars.lines[0].get_data()
        assert (x[i], y[i]) == pytest.approx((energy, k / n))
    assert "Where chaos sets in" not in text


def test_starts_per_cell_needs_a_family_with_a_seed():
    base = {"survey": {"name": "x", "output": "x.nc"}}
    with pytest.raises(ConfigError, match=r"starts_per_cell.*has no seed"):
        load_config({**base, "initial": {"family": "equilateral", "starts_per_cell": 4}})
    with pytest.raises(ConfigError, match=r"starts_per_cell.*already a grid axis"):
        load_config({**base, "initial": {"family": "section_sample", "seed": [0, 1],
                                         "starts_per_cell": 4}})


def test_starts_per_cell_over_two_axes_draw_a_share_map(tmp_path):
    cfg = {"survey": {"name": "ens2", "output": str(tmp_path / "ens2.nc")},
           "initial": {"family": "section_sample", "energy": [84.45577136594005, 95.0],
                       "angular_momentum": [24.401923788646684, 26.0],
                       "starts_per_cell": 2},
           "integration": {"t_final": 60.0}, "indicators": {"perturbations": 0}}
    ds = xr.open_dataset(run_survey(cfg))
    from survey.analysis.classify import regular_share
    share = regular_share(ds)
    ax = plots.figures(ds)["regular_share"].axes[0]
    mesh = [c for c in ax.collections if isinstance(c, QuadMesh)][0]
    np.testing.assert_array_equal(np.ma.filled(mesh.get_array(), np.nan).ravel(),
                                  share.share.transpose("energy", "angular_momentum")
                                  .values.T.ravel())
    assert (ax.get_xlabel(), ax.get_ylabel()) == (plots.label("energy"),
                                                  plots.label("angular_momentum"))


def test_a_section_panel_of_one_point_is_drawn_as_a_point():
    """An equilibrium's or periodic orbit's crossings agree to roundoff: autoscaled, that
    roundoff would look like a cloud; the panel shows a window of unit size and says so.
    Crossings that differ keep the autoscaled view."""
    from matplotlib.figure import Figure
    rng = np.random.default_rng(0)
    ax = Figure().subplots()
    xs, ys = 3.4641016 + 1e-14 * rng.normal(size=(1, 50)), 1e-14 * rng.normal(size=(1, 50))
    ax.scatter(xs, ys)
    sections._one_point(ax, xs, ys)
    assert np.diff(ax.get_xlim())[0] == pytest.approx(1.0)
    assert "every crossing within" in ax.texts[0].get_text()
    ax = Figure().subplots()
    ax.scatter(xs + 0.1 * rng.normal(size=xs.shape), ys)
    sections._one_point(ax, xs + 0.1 * rng.normal(size=xs.shape), ys)
    assert not ax.texts and np.diff(ax.get_xlim())[0] < 1.0


def _legend_box(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    FigureCanvasAgg(fig).draw()
    return fig.axes[0].get_legend().get_window_extent().bounds


@pytest.mark.parametrize("seed", range(4))
def test_a_legend_goes_where_matplotlibs_best_puts_it_among_points(seed):
    """Points alone (a section's crossings): the place loc="best" finds, without its cost."""
    from matplotlib.figure import Figure
    rng = np.random.default_rng(seed)
    x, y = rng.normal(size=(2, 3000)) * [[1.0], [0.6]] + rng.uniform(-1, 1, size=(2, 1))
    boxes = []
    for place in (False, True):
        fig = Figure(figsize=(5, 4), layout="constrained")
        ax = fig.subplots()
        ax.scatter(x, y, s=1, label="crossings")
        ax.scatter(x[:5], y[:5], s=4, label="first")
        ax.set_xlim(-4, 4)
        ax.legend(fontsize="small")
        boxes.append(_legend_box(plots.place_legends(fig) if place else fig))
    assert boxes[1] == pytest.approx(boxes[0], abs=0.5)      # the layout run twice: roundoff


def test_a_legend_covers_lines_before_it_covers_points():
    """A frequency map: resonance lines cross every place for the legend but the lower
    right, where a cell lies. loc="best" weighs a line crossing like a point and covers the
    cell; the legend is put over lines instead."""
    from matplotlib.figure import Figure
    covered = []
    for place in (False, True):
        fig = Figure(figsize=(5, 4), layout="constrained")
        ax = fig.subplots()
        for c in np.linspace(-0.3, 1.0, 40):            # clear of the lower right only
            ax.plot([0, 1], [c, c + 1.0], color="0.5")
        cell = ax.scatter([0.93], [0.07], label="a cell")
        ax.scatter([0.5], [0.5], label="another")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.legend()
        x0, y0, w, h = _legend_box(plots.place_legends(fig) if place else fig)
        px, py = ax.transData.transform(cell.get_offsets()[0])
        covered.append(x0 <= px <= x0 + w and y0 <= py <= y0 + h)
    assert covered == [True, False]         # matplotlib's "best", then ours


def height_map(u0_of=lambda z, e: -3.0 + 0.5 * z):
    """A (strength, energy) map whose starts sit at each system's minimum U_0(Z) = -3 +
    Z/2: regular within 0.3 above it, chaotic higher, inaccessible below."""
    z, e = np.linspace(0.0, 3.0, 7), np.linspace(-2.9, -1.0, 12)
    u0 = u0_of(z[:, None], e[None, :]) + 0.0 * e
    h = e[None, :] - u0
    regime = np.where(h < 0, Regime.INACCESSIBLE, np.where(h < 0.3, Regime.TORUS,
                                                            Regime.CHAOTIC)).astype("i1")
    dims = ("axilrod_teller_strength", "energy")
    return xr.Dataset({V.status: (dims, np.where(h < 0, Status.INACCESSIBLE, Status.OK)
                                  .astype("i1")),
                       V.regime: (dims, regime),
                       V.start_potential: (dims, np.where(h < 0, np.nan, u0))},
                      coords={dims[0]: z, dims[1]: e})


def test_a_map_over_a_parameter_that_moves_the_minimum_is_drawn_above_it_too():
    """Starts at each system's equilibrium (U_0 one number per parameter value, moving
    with it): a second regime map over E - U_0, each column lowered by its own U_0, so
    the band above the minimum lines up; not where U_0 stays put along the parameter, nor
    where it changes along the energy (starts displaced from the equilibrium)."""
    ds = height_map()
    other, u0 = plots._height_axis(ds)
    assert other == "axilrod_teller_strength"
    np.testing.assert_allclose(u0, -3.0 + 0.5 * ds[other].values)
    figs = plots.figures(ds)
    assert "map_regime_height" in figs and "map_regime" in figs
    ax = figs["map_regime_height"].axes[0]
    low, high = ax.get_ylim()
    assert -0.2 < low < 0.05 and high < 2.2        # heights, not energies
    assert plots._height_axis(height_map(lambda z, e: -3.0 + 0.0 * z)) is None
    assert plots._height_axis(height_map(lambda z, e: -3.0 + 0.5 * z + 0.01 * e)) is None
