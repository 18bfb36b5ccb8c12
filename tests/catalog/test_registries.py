"""Every registered indicator (survey.catalog.indicators.REGISTRY) passes the same battery, so
one that lacks a piece fails here: its archive variables are declared and present exactly
when it is computed; a cell that computes it fills them; its headline has a label; if it
votes, its thresholds exist with their reasons and it votes both ways; if it is mapped, the
figures draw it with its reference lines."""
import numpy as np
import pytest
import xarray as xr

from survey.analysis.classify import Table, evidence_votes
from survey.catalog.indicators import INDICATORS, REGISTRY, TANGENT, TORUS
from survey.catalog.regimes import Thresholds
from survey.catalog.variables import BY_NAME, V, label
from survey.pipeline.archive import variables
from survey.pipeline.cells import CellTask, build_starts, run_cells
from survey.pipeline.config import SCHEMA, load_config
from survey.presentation import plots

IDS = [i.name for i in REGISTRY]


def config_computing(indicator, tmp_path):
    which = [indicator.name] if indicator.source == TANGENT else []
    return load_config({"survey": {"output": str(tmp_path / "one.nc")},
                        "initial": {"family": "equilateral", "delta": 3.0},
                        "integration": {"t_final": 30.0},
                        "indicators": {"which": which, "deviations": indicator.deviations,
                                       "perturbations": 1},
                        "tori": {"analyse": indicator.source == TORUS}})


@pytest.mark.parametrize("indicator", REGISTRY, ids=IDS)
def test_its_variables_are_declared_and_filled_by_a_cell_that_computes_it(indicator,
                                                                          tmp_path):
    assert indicator.source in (TANGENT, TORUS) and indicator.reference
    assert (indicator.name in INDICATORS) == (indicator.source == TANGENT)
    assert SCHEMA["indicators"]["which"].choices == INDICATORS
    assert all(name in BY_NAME for name in indicator.variables)
    assert label(indicator.headline) != indicator.headline
    config = config_computing(indicator, tmp_path)
    held = {v.name for v in variables(config)}
    assert set(indicator.variables) <= held
    others = [i for i in REGISTRY if i.source == TANGENT and i is not indicator]
    assert not any(set(i.variables) & held for i in others)
    result = run_cells(CellTask.of(config), [0], build_starts(config))
    for name in indicator.variables:
        values = np.asarray(result[name], dtype=float)
        assert np.isfinite(values).any(), name


@pytest.mark.parametrize("indicator", [i for i in REGISTRY if i.vote], ids=lambda i: i.name)
def test_its_vote_has_thresholds_and_goes_both_ways(indicator):
    vote = indicator.vote
    assert vote.variable in indicator.variables and vote.sign in (-1, 1)
    th = Thresholds()
    fields = {f.name: f for f in Thresholds.__dataclass_fields__.values()}
    regular, chaotic = (getattr(th, f"{vote.thresholds}_{side}") for side in ("regular",
                                                                              "chaotic"))
    for side in ("regular", "chaotic"):
        assert fields[f"{vote.thresholds}_{side}"].metadata["doc"]
    assert vote.sign * regular > vote.sign * chaotic       # a band where it abstains
    T = np.array([1000.0, 1000.0, 1000.0])
    unit = np.log(T) / T if vote.per_torus_rate else np.ones(3)
    values = np.array([regular + vote.sign, (regular + chaotic) / 2, chaotic - vote.sign]) * unit
    ds = xr.Dataset({vote.variable: ("cell", values), V.t_end: ("cell", T),
                     V.status: ("cell", np.zeros(3, np.int8))})
    np.testing.assert_array_equal(evidence_votes(ds, th)[indicator.name], [1.0, 0.0, -1.0])


@pytest.mark.parametrize("indicator", [i for i in REGISTRY if i.map], ids=lambda i: i.name)
def test_maps_draw_it_and_scans_mark_its_thresholds(indicator):
    name = indicator.headline
    rng = np.random.default_rng(0)
    values = rng.uniform(0.01, 10.0, (3, 4))
    grid = xr.Dataset({name: (("delta", "energy"), values),
                       V.status: (("delta", "energy"), np.zeros((3, 4), np.int8)),
                       V.t_end: (("delta", "energy"), np.full((3, 4), 100.0))},
                      coords={"delta": [1.0, 2.0, 3.0], "energy": [1.0, 2.0, 3.0, 4.0]})
    figs = plots.figures(grid)
    assert f"map_{name}" in figs
    assert label(name) in figs[f"map_{name}"].axes[-1].get_ylabel()
    scan = plots.figures(grid.isel(energy=0))["scan"]
    lines = [ln for ax in scan.axes for ln in ax.get_lines() if ln.get_linestyle() in ("--",
                                                                                      ":")]
    assert bool(lines) == (indicator.vote is not None)


@pytest.mark.parametrize("indicator", [i for i in REGISTRY if i.vote and i.vote.half],
                         ids=lambda i: i.name)
def test_its_vote_at_half_the_horizon_reads_each_cells_half(indicator):
    """The verdict at T/2 reads a history at half each cell's own horizon (cells extended
    to 4T read 2T), or the variable that holds the value at T/2."""
    vote = indicator.vote
    th = Thresholds()
    regular, chaotic = (getattr(th, f"{vote.thresholds}_{side}") for side in ("regular",
                                                                              "chaotic"))
    times = np.linspace(62.5, 4000.0, 64)              # a grid to 4 T, T = 1000
    horizon = np.array([1000.0, 4000.0, 1000.0])
    at = [times.tolist().index(h / 2) for h in horizon]
    unit = np.log(horizon / 2) / (horizon / 2) if vote.per_torus_rate else np.ones(3)
    values = np.array([regular + vote.sign, (regular + chaotic) / 2, chaotic - vote.sign]) * unit
    assert vote.half in indicator.variables
    if BY_NAME[vote.half].extra == ("history_time",):
        column = np.full((3, times.size), np.nan)
        column[np.arange(3), at] = values
    else:
        column = values
    table = Table({vote.half: column, V.regime_horizon: horizon, V.t_end: horizon,
                   V.status: np.zeros(3, np.int8)}, history_time=times)
    np.testing.assert_array_equal(evidence_votes(table, th, half=True)[indicator.name],
                                  [1.0, 0.0, -1.0])
