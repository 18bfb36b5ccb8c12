"""Verdicts against a longer horizon, as a survey runs them: a cell whose verdict changed
from T/2 to T, or that not every line of evidence supports, is integrated again to k T
and decided there; its stored evidence is then that run's, bit for bit -- whether it ran
longer in a task of its own (a survey) or in its chunk's (verify)."""
import numpy as np

from survey.analysis.classify import verdict_class
from survey.catalog.variables import BY_NAME, V
from survey.pipeline.sweep import run, verify


def survey(tmp_path, name, t_final, timings=None, **extra):
    return run({"survey": {"name": name, "output": str(tmp_path / f"{name}.nc")},
                "initial": {"family": "equilateral", "delta": [1.0, 4.2, 4.5, 6.0]},
                "integration": {"t_final": t_final},
                "indicators": {"perturbations": 2, **extra.pop("indicators", {})},
                "section": {"coordinate": "phi", "max_crossings": 20},
                "dask": {"workers": 1}, **extra}, timings=timings)


def test_a_verdict_in_doubt_is_decided_again_on_a_run_four_times_longer(tmp_path):
    timings = {}
    ds = survey(tmp_path, "v", 100.0, timings=timings)
    horizon, history = ds[V.regime_horizon].values, ds[V.regime_history].values
    confidence = ds[V.regime_confidence].values
    assert list(ds["horizon_factor"].values) == [0.5, 1.0, 4.0]
    kept, extended = horizon == 100.0, horizon == 400.0
    assert kept.any() and extended.sum() >= 2 and np.all(kept | extended)
    # one task for the chunk, one for its cells in doubt: their orbits lanes of one batch
    assert len(timings["tasks"]) == 2
    # kept at T: the same class at T/2 and T, every line of evidence for it, nothing after
    assert np.all(verdict_class(history[kept, 0]) == verdict_class(history[kept, 1]))
    assert np.all(confidence[kept] == 1.0) and np.all(history[kept, 2] == -1)
    assert np.all(ds[V.regime_stable].values[kept] == 1)
    # the last verdict is the archive's regime; stable where its class is the one before
    assert np.all(history[:, 1:].max(axis=1) >= 0)
    last = np.where(extended, history[:, 2], history[:, 1])
    np.testing.assert_array_equal(last, ds[V.regime].values)
    np.testing.assert_array_equal(
        ds[V.regime_stable].values[extended],
        verdict_class(history[extended, 2]) == verdict_class(history[extended, 1]))
    # an extended cell's evidence is that of the run to 4 T, whatever ran beside it: a
    # survey to 400 with the same history grid and no extension gives the same bits
    longer = survey(tmp_path, "longer", 400.0, indicators={"history_points": 256},
                    tori={"extend": 0})
    assert np.all(longer[V.regime_horizon].values == 400.0)
    np.testing.assert_array_equal(ds["history_time"].values, longer["history_time"].values)
    same = [k for k in ds.data_vars if BY_NAME[k].reproducible and not BY_NAME[k].derived
            and k not in (V.regime_history,)]
    assert V.ftle in same and V.birkhoff_digits in same and V.crossing_phi in same
    for name in same:
        a, b = ds[name].values[extended], longer[name].values[extended]
        assert a.tobytes() == b.tobytes(), name
    np.testing.assert_array_equal(ds[V.regime].values[extended],
                                  longer[V.regime].values[extended])
    # the survey ran the extensions in a task of their own; verify runs them in the cells'
    ok, lines = verify(tmp_path / "v.nc", cells=4)
    assert ok, lines
    # and a survey of one cell a chunk on two workers (its cells in doubt held while
    # chunks wait, then shared out at the end) in other tasks: the same bits
    apart = survey(tmp_path, "apart", 100.0, dask={"workers": 2, "chunk_size": 1})
    for name in (k for k in ds.data_vars if BY_NAME[k].reproducible):
        assert ds[name].values.tobytes() == apart[name].values.tobytes(), name


def test_extend_zero_decides_at_t_only(tmp_path):
    ds = survey(tmp_path, "flat", 100.0, tori={"extend": 0})
    assert list(ds["horizon_factor"].values) == [0.5, 1.0]
    assert np.all(ds[V.regime_horizon].values == 100.0)
    assert ds.sizes["history_time"] == 64
    np.testing.assert_array_equal(ds[V.regime_history].values[:, 1], ds[V.regime].values)


def test_the_onset_cells_that_turn_chaotic_by_4t_are_never_regular_and_stable(tmp_path):
    """The issue's independent runs (two orbits 1e-9 apart per delta, MEGNO to 4e4): delta
    = 4.175 looks a torus at T = 2000 and is chaotic by 1e4; 4.225 stays regular to 4e4.
    With the default horizon checks the first is not claimed regular and stable, the
    second is."""
    ds = run({"survey": {"name": "onset", "output": str(tmp_path / "onset.nc")},
              "initial": {"family": "equilateral", "delta": [4.175, 4.225]},
              "integration": {"t_final": 2000.0}, "indicators": {"perturbations": 1},
              "dask": {"workers": 1}})
    regular = np.isin(ds[V.regime].values, [0, 1, 2])
    steady = ds[V.regime_stable].values == 1
    assert not (regular[0] and steady[0])
    assert ds[V.regime_horizon].values[0] == 8000.0      # it was in doubt at T
    assert regular[1] and steady[1]


def test_the_equilateral_familys_frequencies_are_three_continuous_curves(tmp_path):
    """Along delta in [0.25, 4] the labelled shape frequencies vary continuously (no jump
    between neighbours, no sign) and start at the rotating triangle's linearised normal
    modes 2 Omega, Omega (1 +- 1/sqrt 2) over 2 pi (Omega = 3) -- the closed form, and the
    modes `relative_equilibrium` finds for the delta = 0 start."""
    ds = run({"survey": {"name": "eq", "output": str(tmp_path / "eq.nc")},
              "initial": {"family": "equilateral",
                          "delta": {"start": 0.25, "stop": 4.0, "num": 16}},
              "integration": {"t_final": 500.0}, "indicators": {"perturbations": 1},
              "dask": {"workers": 1}})
    assert np.isin(ds[V.regime].values, [0, 1]).all()
    nu = ds[V.frequency_labelled].values[:, :3]
    assert np.all(nu > 0)
    # no jump between neighbours: a swapped label would move one by 15% or more
    assert np.max(np.abs(np.diff(nu, axis=0)) / nu[1:]) < 0.1
    omega = 3.0
    modes = np.array([2 * omega, omega * (1 + 2 ** -0.5), omega * (1 - 2 ** -0.5)]) / (2 * np.pi)
    np.testing.assert_allclose(nu[0], modes, rtol=2e-3)
    # and to the normal modes survey computes for the relative equilibrium at delta = 0
    from survey.physics.equilibria import relative_equilibrium
    from survey.physics.families import initial_state
    from survey.physics.system import System
    system = System.create()
    start = initial_state(system, "equilateral", delta=0.0)
    eq = relative_equilibrium(system, system.split(start)[0],
                              angular_momentum=float(system.angular_momentum(start)))
    np.testing.assert_allclose(np.sort(nu[0]), eq.frequencies, rtol=2e-3)
    np.testing.assert_allclose(eq.frequencies, np.sort(modes), rtol=1e-10)


def test_check_runs_state_the_claims_at_another_seed_and_budget_the_onset(tmp_path, capsys):
    """`run` with a [check] table runs the survey again once per variant into
    <output>_check_<variant>.nc. The seed run: other deviation vectors and perturbed
    starts (other FTLEs), and the nominal orbits nudged by 1e-13 (other last bits: their
    energy errors and Birkhoff digits move too, where before they were the same bits); the
    tolerance run: other orbits altogether. The report gives the regimes of the seed run
    side by side, says the nominal orbits moved, and lists the onset's uncertainty by
    contribution (the step, each run's shift, the two not run named as not measured);
    `report` finds the check runs again beside the archive."""
    import xarray as xr

    from survey.cli import main
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"""
[survey]
name = "c"
output = "{tmp_path / 'c.nc'}"
[initial]
family = "equilateral"
delta = {{start = 3.5, stop = 5.0, num = 4}}
[integration]
t_final = 200.0
[indicators]
perturbations = 2
[check]
variants = ["seed", "tolerance"]
[dask]
workers = 1
""")
    assert main(["run", str(cfg), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "seed 1 and 8 perturbed orbits" in out and "rtol = 1e-10, atol = 1e-10" in out
    with xr.open_dataset(tmp_path / "c.nc") as a, \
            xr.open_dataset(tmp_path / "c_check_seed.nc") as b, \
            xr.open_dataset(tmp_path / "c_check_tolerance.nc") as c:
        assert np.all(a[V.energy_error].values != b[V.energy_error].values)
        assert np.any(a[V.birkhoff_digits].values != b[V.birkhoff_digits].values)
        np.testing.assert_array_equal(a[V.initial_state].values, b[V.initial_state].values)
        assert np.all(a[V.ftle].values != b[V.ftle].values)
        assert np.all(a[V.energy_error].values != c[V.energy_error].values)
        assert (int(a[V.ensemble_orbits].max()), int(b[V.ensemble_orbits].max())) == (3, 9)
        counts = [(r, int(np.sum(a[V.regime].values == r)), int(np.sum(b[V.regime].values == r)))
                  for r in np.unique(np.r_[a[V.regime].values, b[V.regime].values])]
    assert not (tmp_path / "c_check_rounding.nc").exists()
    report = (tmp_path / "c_report.md").read_text()
    assert "## The same survey with another seed and ensemble" in report
    assert "each cell's nominal orbit started 1e-13 (relative) away" in report
    from survey.catalog.regimes import Regime
    for r, here, there in counts:
        assert f"| {Regime(r).name.lower()} | {here} | {there} |" in report
    if "## Where chaos sets in\n\nAlong delta the orbits are regular up to" in report:
        assert "| seed 1 and 8 perturbed orbits a cell, the nominal starts 1e-13 (relative) " \
            "away |" in report and "| rtol = 1e-10, atol = 1e-10 |" in report
        assert "| half the grid step | — |" in report
        assert "Not measured, so not in this uncertainty: rounding" in report
        assert "horizon (twice t_final)" in report
    (tmp_path / "c_report.md").unlink()
    assert main(["report", str(tmp_path / "c.nc")]) == 0
    again = (tmp_path / "c_report.md").read_text()
    assert "## The same survey with another seed" in again and \
        "| rtol = 1e-10, atol = 1e-10 |" in again