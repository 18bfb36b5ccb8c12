"""The explorer's numbers without a browser (survey.explore.CellView): what a
pointer over a cell shows is the archive's, a clicked cell's orbit is what `survey orbit
CONFIG --cell K` prints for it, the exported config starts where the archive's cell started
(bit for bit) and integrates to the same orbit, and bad input says what is wrong before a
server starts. tests/presentation/test_explore_browser.py drives the page itself."""
import re
import socket
from pathlib import Path

import numpy as np
import pytest

from survey.catalog.errors import ArchiveError, SurveyError
from survey.catalog.regimes import Regime
from survey.cli import main
from survey.pipeline.cells import build_starts
from survey.pipeline.config import parse_config
from survey import explore
from survey.presentation.sections import SLAB

RESULTS = Path(__file__).resolve().parents[2] / "results"
MAP = RESULTS / "delta_energy_map_areal.nc"      # 17 x 11 cells, t_final 300
CELL = 61                                        # delta = 1.25, energy = 10: chaotic


@pytest.fixture(scope="module")
def view():
    return explore.CellView.open(MAP)


def _printed(lines):
    """`orbit`'s lines without the wall time, which no two runs share."""
    return [re.sub(r", [0-9.]+ s$", "", line) for line in lines]


def test_the_pointer_shows_the_archives_values(view):
    cols = view.hover_columns()
    ds = view.ds
    i, j = np.unravel_index(CELL, view.shape)
    assert cols["delta"][CELL] == ds["delta"].values[i]
    assert cols["energy"][CELL] == ds["energy"].values[j]
    assert cols["regime"][CELL] == Regime(int(ds["regime"].values[i, j])).name.lower()
    assert cols["megno"][CELL] == ds["megno"].values[i, j]
    assert cols["regime_confidence"][CELL] == ds["regime_confidence"].values[i, j]
    described = view.describe(CELL)
    assert described["delta"] == "1.25" and described["energy"] == "10"
    assert set(view.layers()) >= {"regime", "megno", "ftle", "fli", "birkhoff_digits"}


def test_a_clicked_cell_is_the_orbit_command_on_that_cell(view, tmp_path, capsys):
    """The explorer's orbit of cell K is `python -m survey orbit CONFIG --cell K` on the
    archive's stored config, line for line; its crossings lie on the section phi = pi/2
    (in the paper's reduced coordinates) and its MEGNO grows as a chaotic orbit's does."""
    orbit = view.orbit(CELL)
    config = tmp_path / "stored.toml"
    config.write_text(view.ds.attrs["config"])
    assert main(["orbit", str(config), "--cell", str(CELL)]) == 0
    assert _printed(capsys.readouterr().out.splitlines()) == _printed(orbit.lines)
    sigma, p_sigma, x_name, y_name = orbit.crossings
    assert (x_name, y_name) == ("sigma", "p_sigma") and sigma.size > 3
    assert np.all(sigma > 0)
    assert orbit.t[-1] == pytest.approx(300.0) and orbit.positions.shape[1:] == (3, 2)
    assert orbit.megno[-1] > 8          # a torus's MEGNO tends to 2
    assert view.ds["regime"].values.ravel()[CELL] == Regime.CHAOTIC


def test_the_exported_cell_starts_where_the_archives_did(view, tmp_path, capsys):
    text = view.export(CELL)
    config = parse_config(text, "export", check_output=False)
    assert config.n_cells == 1 and config.tables["initial"]["family"] == "explicit"
    start = build_starts(config, [0])[0]
    assert np.array_equal(start, view.flat_state(CELL))          # bit for bit
    path = tmp_path / "cell.toml"
    path.write_text(text)
    assert main(["orbit", str(path)]) == 0
    exported = _printed(capsys.readouterr().out.splitlines())
    clicked = _printed(view.orbit(CELL).lines)
    # the same orbit: all but the first line (which names the family and its parameters)
    assert exported[1:] == clicked[1:]
    assert f"orbit {config.name}.toml" in view.command(CELL)


def test_velocities_give_the_momenta_back_exactly():
    rng = np.random.default_rng(4)
    masses = np.array([1.0, 0.3, 7.1])
    p = rng.normal(size=(3, 2))
    v = explore._velocities(p, masses)
    assert np.array_equal(masses[:, None] * v, p)


def test_a_scan_and_a_one_shell_section_are_shown():
    scan = explore.CellView.open(RESULTS / "default.nc")
    assert scan.axes == ["delta"] and scan.shell_crossings() is None
    shell = explore.CellView.open(RESULTS / "section_map.nc")
    x, y, regime, cell, names = shell.shell_crossings()
    assert names == ("sigma", "p_sigma") and x.size == y.size == regime.size == cell.size
    stored = shell.ds["crossing_sigma"].values.reshape(shell.config.n_cells, -1)
    assert np.array_equal(np.sort(x), np.sort(stored[np.isfinite(stored)]))
    s, ps, eta, cells, regimes, slab = shell.slice_points()
    p_eta = shell.ds["crossing_p_eta"].values.reshape(shell.config.n_cells, -1)
    width = SLAB * (np.nanmax(p_eta) - np.nanmin(p_eta))     # the report's slice
    assert f"|p_eta| <= {width:.3g}" in slab
    in_slab = np.isfinite(p_eta) & (np.abs(p_eta) <= width)
    assert 100 < s.size == eta.size == in_slab.sum() < np.isfinite(p_eta).sum()


def test_bad_input_is_named_before_a_server_starts(tmp_path):
    text = tmp_path / "notes.nc"
    text.write_text("not NetCDF")
    with pytest.raises(ArchiveError, match="not a readable NetCDF"):
        explore.CellView.open(text)
    with pytest.raises(ArchiveError, match="no such file"):
        explore.CellView.open(tmp_path / "absent.nc")
    with pytest.raises(ArchiveError, match="a manifolds archive; the explorer shows survey"):
        explore.open_view(RESULTS / "isosceles_perimetric_plane.nc")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(SurveyError, match=f"port {port} on 127.0.0.1 is in use"):
            explore.check_port("127.0.0.1", port)
        assert main(["explore", str(MAP), "--port", str(port), "--no-browser"]) == 1


def test_a_cell_without_a_start_is_a_message(view):
    with pytest.raises(ValueError, match="not a cell of the grid"):
        view.orbit(view.config.n_cells)


def test_the_gallery_opens_each_map_in_the_explorer(view):
    """The docs' gallery names the explorer's address of each map figure of an archive,
    with a layer the explorer has."""
    from survey.reference import _explorable, gallery_page
    assert _explorable(MAP) == set(view.layers())
    page = gallery_page(RESULTS, RESULTS.parent / "workflows", "../results/")
    assert "python -m survey explore results/delta_energy_map_areal.nc" in page
    for layer in ("regime", "megno", "birkhoff_digits"):
        assert f"delta_energy_map_areal_map_{layer}.png" in page
        assert f"http://127.0.0.1:5006/?layer={layer}>" in page


def test_a_family_member_is_integrated_and_closes(families):
    """A member of each family integrated with survey's kernels returns to its start (a
    periodic orbit turned by its rotation, an equilibrium after one turn) -- a check of the
    archived member by what would show it wrong -- and its numbers are the archive's."""
    view = explore.open_view(families["periodic"])
    assert isinstance(view, explore.FamilyView) and view.parameter == "energy"
    last = view.values.size - 1
    t, q, error = view.member_orbit(last)
    assert error < 1e-9 and t[-1] == pytest.approx(float(view.ds["period"][last]))
    text = "\n".join(view.describe(last))
    assert f"period {float(view.ds['period'][last]):.10g}" in text and "multipliers" in text
    name, period = view.measure()
    assert name == "period" and np.allclose(period, np.pi / 3, rtol=1e-11)
    routh = explore.open_view(families["equilibria"])
    assert routh.parameter == "mass_1" and routh.measure()[0] == "energy"
    for member in (0, routh.values.size - 1):
        t, q, error = routh.member_orbit(member)
        assert error < 1e-9 and q.shape[1:] == (3, 2)
        # the member's own system: the mass along the family is the member's
        assert routh.system_at(routh.values[member]).masses[1] == routh.values[member]
    assert "reduced eigenvalues" in "\n".join(routh.describe(0))
