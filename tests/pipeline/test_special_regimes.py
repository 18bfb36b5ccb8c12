"""The regimes of the special solutions, as surveys find them on the default settings:
the figure-eight choreography of three equal masses under Newtonian gravity (Chenciner &
Montgomery 2000; Simo's start, period 6.32591398) is periodic -- its shape lines are
harmonics of one frequency; three Lennard-Jones atoms at rest at their minimum are an
equilibrium (a constant signal never votes chaotic); the rotating equilateral triangle
under P^2/2 is a relative equilibrium."""
import numpy as np
import pytest

from survey import Regime, run

FIGURE_EIGHT = """
[survey]
name = "figure8"
output = "{out}"
[system]
interactions = [{{kind = "pair", potential = "gravity", params = {{G = 1.0}}}}]
[initial]
family = "explicit"
positions = [[0.97000436, -0.24308753], [-0.97000436, 0.24308753], [0.0, 0.0]]
velocities = [[0.466203685, 0.43236573], [0.466203685, 0.43236573],
              [-0.93240737, -0.86473146]]
[integration]
t_final = 632.591398     # 100 periods
[indicators]
perturbations = 2
"""

LJ_AT_REST = """
[survey]
name = "lj"
output = "{out}"
[system]
interactions = [{{kind = "pair", potential = "lennard_jones", params = {{epsilon = 1.0, sigma = 1.0}}}}]
[initial]
family = "equilibrium"
positions = [[0.0, 0.0], [1.12, 0.0], [0.56, 0.97]]
speed = 0.0
[integration]
t_final = 300.0
[indicators]
perturbations = 2
"""

ROTATING = """
[survey]
name = "rotating"
output = "{out}"
[initial]
family = "equilateral"
delta = 0.0
[integration]
t_final = 500.0
[indicators]
perturbations = 2
"""


@pytest.mark.parametrize("text,regime", [(FIGURE_EIGHT, Regime.PERIODIC),
                                         (LJ_AT_REST, Regime.EQUILIBRIUM),
                                         (ROTATING, Regime.EQUILIBRIUM)],
                         ids=["figure-eight", "lj-at-rest", "rotating-triangle"])
def test_special_solutions_get_their_regime(tmp_path, text, regime):
    cfg = tmp_path / "special.toml"
    cfg.write_text(text.format(out=tmp_path / "special.nc"))
    ds = run(cfg, workers=1, progress=False)
    assert Regime(int(ds.regime.values.ravel()[0])) == regime
    assert float(ds.regime_confidence.values.ravel()[0]) == 1.0
    assert int(ds.regime_stable.values.ravel()[0]) == 1
    if regime == Regime.EQUILIBRIUM:
        assert int(ds.moving_shapes.values.ravel()[0]) == 0
    else:        # the figure-eight's shape frequencies: 2 and 3 times 1 / period
        nu = np.abs(ds.frequency.values.ravel())
        shape = np.sort(nu[np.isfinite(nu)][:-1])
        np.testing.assert_allclose(shape, [2 / 6.32591398, 3 / 6.32591398], rtol=1e-6)


def test_the_report_sets_the_equilibrium_beside_the_family(tmp_path):
    """A scan from delta = 0: the report solves the equilibrium cell again as a relative
    equilibrium -- stable, the closed-form modes -- and quotes the nearest regular cell's
    shape frequencies beside them (they agree to ~1e-4 at delta = 0.1)."""
    from survey.pipeline.special import equilibrium_cells
    from survey.presentation import report
    cfg = tmp_path / "scan.toml"
    cfg.write_text(ROTATING.format(out=tmp_path / "scan.nc").replace(
        "delta = 0.0", "delta = [0.0, 0.1]"))
    ds = run(cfg, workers=1, progress=False)
    special = equilibrium_cells(ds)
    assert [s["cell"] for s in special] == ["delta=0"] and special[0]["stable"]
    modes = 3.0 * np.array([1 - 2 ** -0.5, 1 + 2 ** -0.5, 2.0]) / (2 * np.pi)
    np.testing.assert_allclose(special[0]["frequencies"], modes, rtol=1e-10)
    assert plots_stored(ds)[0] == [{**s, "index": tuple(s["index"])} for s in special]
    text = report.markdown(ds)          # what the archive stores, solved with the survey
    assert "## Special solutions in this family" in text
    assert "delta=0: rotating at Omega = 3, linearly stable; normal modes 0.139846 (-)" in text
    assert "The nearest regular cell, delta = 0.1, has shape frequencies 0.1398" in text
    from survey.presentation import plots
    legend = [t.get_text() for t in plots.figures(ds)["scan"].legends[0].texts]
    assert "relative equilibrium, linearly stable (1)" in legend
    # the command and the Dataset's accessor write the same report
    import xarray as xr

    from survey.cli import main
    assert main(["report", str(tmp_path / "scan.nc"), "--out", str(tmp_path / "cli")]) == 0
    with xr.open_dataset(tmp_path / "scan.nc") as opened:
        written = opened.survey.report(tmp_path / "api")
    assert report.without_provenance(written.read_text()) == \
        report.without_provenance((tmp_path / "cli" / "scan_report.md").read_text())


def plots_stored(ds):
    from survey.presentation.plots import stored_special
    return stored_special(ds)


def test_the_report_sets_the_homographic_orbit_beside_the_ftle_it_causes(tmp_path):
    """The areal barrier's equilateral family at delta = 0 breathes while it turns (a
    homographic start); the report shoots it as a relative periodic orbit and sets its
    instability rate beside the cell's FTLE. The delta = 0.5 cell is not homographic."""
    import math

    from survey.numerics.periodic import periodic_orbit
    from survey.physics.families import initial_state
    from survey.physics.system import System
    from survey.pipeline.special import homographic_period, special_cells
    from survey.presentation import report
    cfg = tmp_path / "areal.toml"
    cfg.write_text(f"""
[survey]
output = "{tmp_path / 'areal.nc'}"
[system]
potential = "areal_barrier"
[initial]
family = "equilateral"
side = 1.7320508075688772
delta = [0.0, 0.5]
energy = 8.0
[integration]
t_final = 100.0
[indicators]
perturbations = 2
""")
    ds = run(cfg, workers=1, progress=False)
    special = special_cells(ds)
    assert [(s["kind"], s["cell"]) for s in special] == [("periodic", "delta=0")]
    system = System.create(potential="areal_barrier")
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), delta=0.0, energy=8.0)
    orbit = periodic_orbit(system, y0, homographic_period(system, y0, 100.0), rotating=True)
    assert special[0]["period"] == pytest.approx(orbit.period, rel=1e-10)
    assert special[0]["rates"][0] == pytest.approx(orbit.rates[0], rel=1e-8)
    assert special[0]["orbit_kind"] == "complex unstable"
    text = report.markdown(ds, special=special)
    assert (f"- delta=0: period {orbit.period:.6g}, turning {orbit.rotation:.6g} rad, complex "
            f"unstable: nearby orbits leave at {orbit.rates[0]:.4g}") in text
    from survey.presentation import plots
    legend = [t.get_text() for t in plots.figures(ds, special=special)["scan"].legends[0].texts]
    assert "homographic periodic orbit, complex unstable (1)" in legend
    assert homographic_period(system, initial_state(system, "equilateral", side=math.sqrt(3),
                                                    delta=0.5, energy=8.0), 100.0) is None
