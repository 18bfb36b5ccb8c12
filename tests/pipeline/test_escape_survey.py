"""A survey whose cells escape, end to end: a Lennard-Jones trimer scanned across its
dissociation energy. Cells above it lose an atom (status and regime escaped, the escape's
time and body archived, no indicator); cells below never do; an interrupted run resumes to
the archive an uninterrupted one writes, bit for bit, and `verify` recomputes escaped and
bound cells alike; the report and figures show the escapes and the dissociation energy."""
import json

import numpy as np
import pytest
import xarray as xr

from survey.catalog.regimes import Regime
from survey.catalog.status import Status
from survey.catalog.variables import V
from survey.pipeline.sweep import run_survey, verify
from survey.presentation import plots, report

from test_faults import fresh, interrupt_after, same_data

TRIMER = """
[survey]
name = "lj3"
output = "{out}"
[system]
interactions = [{{kind = "pair", potential = "lennard_jones", params = {{epsilon = 1.0, sigma = 1.0}}}}]
[initial]
family = "equilibrium"
positions = [[0.0, 0.0], [1.12, 0.0], [0.56, 0.97]]
seed = 1
energy = [-2.0, -1.4, -0.9, -0.6, -0.3, 0.3]
[integration]
t_final = 150.0
[indicators]
perturbations = 1
history_points = 4
[tori]
sample_interval = 0.05
[dask]
chunk_size = 2
workers = 1
"""


@pytest.fixture(scope="module")
def trimer(tmp_path_factory):
    folder = tmp_path_factory.mktemp("escape")
    cfg = folder / "lj3.toml"
    cfg.write_text(TRIMER.format(out=folder / "lj3.nc"))
    return cfg


def test_cells_above_dissociation_escape_and_resume_and_verify(trimer, tmp_path,
                                                               monkeypatch):
    cfg = tmp_path / "lj3.toml"
    cfg.write_text(trimer.read_text().replace(str(trimer.parent), str(tmp_path)))
    interrupt_after(monkeypatch, 1)
    with pytest.raises(KeyboardInterrupt):
        run_survey(cfg)
    monkeypatch.undo()
    ds = xr.open_dataset(run_survey(cfg))
    same_data(ds, fresh(tmp_path, cfg))
    status, energy = ds[V.status].values, ds["energy"].values
    escaped = status == Status.ESCAPED
    assert escaped[energy > -1.0].sum() >= 2 and not escaped[energy < -1.0].any()
    assert np.all(ds[V.regime].values[escaped] == Regime.ESCAPED)
    t = ds[V.escape_time].values
    assert np.all((t[escaped] > 0) & (t[escaped] < 150.0)) and np.all(np.isnan(t[~escaped]))
    assert np.array_equal(t[escaped], ds[V.t_end].values[escaped])
    assert set(ds[V.escaped_body].values[escaped]) <= {0, 1, 2}
    assert np.all(ds[V.escaped_body].values[~escaped] == -1)
    assert np.all(np.isnan(ds[V.ftle].values[escaped]))     # no verdict from its way out
    assert ds[V.escape_time].attrs["escape_radius"] > 5.0
    assert json.loads(ds.attrs["dissociation_energy"]) == pytest.approx(-1.0, abs=1e-9)
    pairs = ds[V.closest_approach].values
    assert pairs.shape == (energy.size, 3) and np.all((pairs > 0.8) & (pairs < 1.2))
    assert np.all(ds[V.least_area].values >= 0) and np.all(ds[V.thin_share].values <= 1)
    ok, lines = verify(ds.encoding["source"], cells=energy.size)
    assert ok, lines
    text = report.markdown(ds)
    assert "## Escapes" in text and f"{int(escaped.sum())} of {energy.size} started" in text
    figures = plots.figures(ds)
    assert "approach" in figures and "scan" in figures
    legend = [t.get_text() for leg in figures["scan"].legends for t in leg.get_texts()]
    assert any(s.startswith("dissociation energy -1") for s in legend), legend
