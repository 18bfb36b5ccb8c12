"""The attack on the commands beside the survey (issue 66): outputs that are the run's
own input, paths that cannot be written, damaged archives, nested TOML, closed pipes,
sizes past the machine, names that leave their folder, the isosceles plane's triple
collision, the family archives' verify. Each is one line and an exit code, before work
where it is an input error -- never a traceback, a hang, a lost file or a silent wrong
answer."""
import io
import math

import numpy as np
import pytest
import xarray as xr

from survey.catalog.status import Status
from survey.cli import main
from survey.numerics.isosceles import plane_section, plane_start
from survey.numerics.torus import integer_vectors, resonance_count
from survey.physics.system import System

TRIANGLE = '[initial]\nfamily = "equilateral"\ndelta = 0.0\n'


def error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    return err


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    """A two-cell survey whose indicators leave out MEGNO (its report once crashed on the
    missing megno_ensemble)."""
    folder = tmp_path_factory.mktemp("hostile")
    cfg = folder / "ftle.toml"
    cfg.write_text(f'[survey]\nname = "ftle"\noutput = "{folder / "ftle.nc"}"\n'
                   '[initial]\nfamily = "equilateral"\ndelta = [1.0, 4.5]\n'
                   '[integration]\nt_final = 40.0\n'
                   '[indicators]\nwhich = ["ftle"]\ndeviations = 1\nperturbations = 2\n'
                   '[tori]\nsample_interval = 0.25\n[dask]\nworkers = 1\n')
    assert main(["run", str(cfg), "--no-progress"]) == 0
    report = (folder / "ftle_report.md").read_text()
    assert "## Spread over nearby orbits" in report and "median <Y>" not in report
    return folder / "ftle.nc"


@pytest.fixture(scope="module")
def family(tmp_path_factory):
    """A family archive: the rotating triangle along its coupling."""
    folder = tmp_path_factory.mktemp("family")
    cfg = folder / "family.toml"
    cfg.write_text(TRIANGLE + '[equilibria]\nparameter = "perimetric_power_coupling"\n'
                              'to = 0.25\nsteps = 2\n')
    assert main(["equilibria", str(cfg), "--output", str(folder / "family.nc")]) == 0
    return folder / "family.nc"


def test_no_output_replaces_the_config_it_was_read_from(tmp_path, capsys, archive):
    """run --output, [survey] output and a family's --output naming the config file are
    refused before any work, and the config is still there."""
    cfg = tmp_path / "grid.toml"
    text = '[initial]\nfamily = "equilateral"\ndelta = [1.0]\n'
    cfg.write_text(text)
    assert main(["run", str(cfg), "--output", str(cfg)]) == 2
    assert "--output: " in error(capsys) and cfg.read_text() == text
    cfg.write_text(f'[survey]\noutput = "{cfg}"\n' + text)
    assert main(["run", str(cfg)]) == 2
    assert "[survey].output: " in error(capsys)
    for command, table in (("equilibria", "[equilibria]\nparameter = 'angular_momentum'\n"
                                          "to = 40.0\n"),
                           ("periodic", "[periodic]\nmode = 3\nparameter = 'energy'\n"
                                        "to = 150.0\n")):
        cfg.write_text(TRIANGLE + table)
        before = cfg.read_text()
        assert main([command, str(cfg), "--output", str(cfg)]) == 2
        assert "is this run's input" in error(capsys) and cfg.read_text() == before
        for bad in (tmp_path, "/proc/x.nc", tmp_path / ("a" * 300 + ".nc")):
            assert main([command, str(cfg), "--output", str(bad)]) == 2
            assert "--output: " in error(capsys)


def test_a_closed_pipe_ends_the_output_quietly(monkeypatch, capsys, tmp_path):
    """--json into a reader that went away (| head): exit 141, no traceback."""
    class Closed(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")
    cfg = tmp_path / "triangle.toml"
    cfg.write_text(TRIANGLE)
    monkeypatch.setattr("sys.stdout", Closed())
    assert main(["equilibria", str(cfg), "--json"]) == 141
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("text", ["a = " + "[" * 2000 + "]" * 2000,
                                  "a = " + "{b = " * 800 + "1" + "}" * 800])
def test_toml_nested_past_the_reader_is_one_line(tmp_path, capsys, text):
    cfg = tmp_path / "deep.toml"
    cfg.write_text(text + "\n")
    for command in ("run", "equilibria", "periodic", "orbit"):
        assert main([command, str(cfg)] + (["--plot", str(tmp_path)] if command == "orbit"
                                           else [])) == 2
        assert "nests arrays or tables deeper than a config needs" in error(capsys)


def test_numbers_whose_squares_overflow_are_refused(tmp_path, capsys):
    assert main(["orbit", "--masses=1e300,1,1", "--t-final", "1"]) == 2
    assert "--masses: must be <= 1e+100" in error(capsys)
    cfg = tmp_path / "j.toml"
    cfg.write_text(TRIANGLE + "[equilibria]\nangular_momentum = 1e300\n")
    assert main(["equilibria", str(cfg)]) == 2
    assert "[equilibria].angular_momentum: must be <= 1e+100" in error(capsys)


def test_a_family_end_the_parameter_cannot_take_is_refused(tmp_path, capsys):
    cfg = tmp_path / "e.toml"
    cfg.write_text(TRIANGLE + "[equilibria]\nparameter = 'mass_0'\nto = -1.0\n")
    assert main(["equilibria", str(cfg)]) == 2
    assert "[equilibria].to: -1: masses must be finite and > 0" in error(capsys)


def test_damaged_archives_and_bad_folders_are_one_line(tmp_path, capsys, archive):
    """An archive without its regime, with a status survey never writes; --out a file or
    under /proc; --var an unknown variable; a family archive given to plot."""
    with xr.open_dataset(archive) as ds:
        ds = ds.load()
    ds.drop_vars("regime").to_netcdf(tmp_path / "noregime.nc")
    bad = ds.copy(deep=True)
    bad["status"][:] = 9
    bad.to_netcdf(tmp_path / "status.nc")
    for name, words in (("noregime.nc", "without its regime variable"),
                        ("status.nc", "status 9 is no status survey writes")):
        for command in ("report", "plot", "verify"):
            assert main([command, str(tmp_path / name)]) == 2
            assert words in error(capsys)
    (tmp_path / "file").write_text("")
    for command in ("report", "plot"):
        for out in (tmp_path / "file", "/proc/x"):
            assert main([command, str(archive), "--out", str(out)]) == 2
            assert "--out: " in error(capsys)
    for argv in (["--t-final", "1"], [str(archive.parent / "nosuch.toml")]):
        assert main(["orbit", *argv, "--plot", str(tmp_path / "file")]) == 2
        assert "--plot: " in error(capsys)
    assert main(["plot", str(archive), "--var", "bogus"]) == 2
    assert "--var bogus: is not a variable plots draw" in error(capsys)


def test_bad_command_arguments_are_one_line(capsys):
    for argv, words in ((["bench", "--t-final", "-1"], "--t-final: must be > 0"),
                        (["bench", "--repeats", "0"], "--repeats: must be > 0"),
                        (["reproduce", "--only", "nosuch"], "--only nosuch: is not a workflow"),
                        (["reproduce", "--workflows", "/nonexistent"],
                         "--workflows: /nonexistent is not a folder")):
        assert main(argv) == 2
        assert words in error(capsys)


def test_verify_compares_every_variable_and_attribute_of_a_family(tmp_path, capsys, family):
    """A family archive verifies; one whose int8 stability flag, `complete` attribute or a
    bifurcation variable was changed or dropped does not (each named), and none crashes."""
    assert main(["verify", str(family)]) == 0
    capsys.readouterr()
    with xr.open_dataset(family) as ds:
        ds = ds.load()
    ds.encoding = {}        # (the empty bifurcation dimension was written unlimited)
    flipped = ds.copy(deep=True)
    flipped["stable"][0] = 0
    dropped = ds.drop_vars(["bifurcation_parameter", "bifurcation_kind"])
    unfinished = ds.assign_attrs(complete=0)
    for tampered, words in ((flipped, "stable: [0, 1"), (dropped, "bifurcation_parameter: "
                                                                    "missing from the archive"),
                            (unfinished, "attribute complete: '0' stored, '1' computed again")):
        path = tmp_path / "tampered.nc"
        tampered.to_netcdf(path)
        assert main(["verify", str(path)]) == 1
        out = capsys.readouterr()
        assert words in out.out and "Traceback" not in out.err


@pytest.mark.parametrize("table, words", [
    ("crossings = 300000000", "[[plane]] 1.crossings: 300,000,000 crossings of the section "
                              "would need about"),
    ("periodic = [[0.3, 0.0, 100000000000]]", "[[plane]] 1.periodic: 100,000,000,000 "
                                              "crossings"),
    ("name = '../out'", "[[plane]] 1.name: '../out' is not a usable name"),
    ("tol = 1.0", "[[plane]] 1.tol: must be a finite number >= 2.22e-15 and <= 0.001"),
    ("system = {potential = 'areal_barrier'}\npotential = 'perimetric_power'",
     "[[plane]] 1.system: give either system or potential/potential_params, not both"),
])
def test_plane_tables_are_checked_before_any_work(tmp_path, capsys, table, words):
    cfg = tmp_path / "plane.toml"
    keys = {line.split("=")[0].strip() for line in table.split("\n")}
    base = {"name": "'p'", "energy": "1.0", "starts": "[[0.3, 0.0]]", "t_final": "10.0"}
    cfg.write_text("[[plane]]\n" + "".join(f"{k} = {v}\n" for k, v in base.items()
                                           if k not in keys) + table + "\n")
    assert main(["orbit", str(cfg), "--plot", str(tmp_path / "figs")]) == 2
    assert words in error(capsys)


def test_an_orbit_name_that_leaves_the_plot_folder_is_refused(tmp_path, capsys):
    cfg = tmp_path / "orbits.toml"
    cfg.write_text("[[orbit]]\nname = '../../escape'\nfamily = 'sides'\nt_final = 1.0\n")
    assert main(["orbit", str(cfg), "--plot", str(tmp_path / "figs")]) == 2
    assert "[[orbit]] 1.name: '../../escape' is not a usable name" in error(capsys)


def test_the_triple_collision_stops_as_a_collision():
    """From (b, p_b) = (0, 0) at h = 0 all three bodies meet and the orbit slides along the
    pair collision b = 0, passing it ever faster: it stops at once with status
    COLLISION instead of passing it a million times; a start 1e-6 off it still runs."""
    paper = System.create()
    stuck = plane_section(paper, plane_start(paper, 1.0, 0.0, 0.0, 0.0), 100.0, 0.0, 10)
    assert stuck.status == Status.COLLISION and stuck.b.size == 0 and stuck.passages < 200
    near = plane_section(paper, plane_start(paper, 1.0, 0.0, 1e-3, 0.0), 100.0, 0.0, 10)
    assert near.status == Status.OK and near.b.size == 10


def test_the_resonance_vectors_are_enumerated_by_order():
    """The vectors m with 1 <= |m|_1 <= order (first nonzero entry positive), in the order
    the cube's filter gave them, counted by the cross-polytope's formula -- built without
    visiting (2 order + 1)^dim points (11 shape frequencies at order 6: 113,652)."""
    import itertools
    for dim in range(1, 5):
        for order in range(0, 6):
            cube = [m for m in itertools.product(range(-order, order + 1), repeat=dim)
                    if 0 < sum(map(abs, m)) <= order and next(x for x in m if x) > 0]
            cube.sort(key=lambda m: sum(map(abs, m)))
            np.testing.assert_array_equal(integer_vectors(dim, order),
                                          np.array(cube, dtype=np.int64).reshape(-1, dim))
            assert resonance_count(dim, order) == len(cube)
    assert resonance_count(11, 6) == 113652 == len(integer_vectors(11, 6))
    assert math.comb(3, 1) == resonance_count(3, 1)
