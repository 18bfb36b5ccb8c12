"""The survey pipeline against real dask clusters: archive contents and attributes,
bit-identity across chunking and worker counts, checkpoints and resume after SIGKILL, a
killed worker, an external scheduler, verify, atomic writes."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from survey.catalog.errors import SurveyError
from survey.catalog.status import Status
from survey.catalog.variables import BY_NAME
from survey.pipeline.checkpoints import checkpoint_dir
from survey.pipeline.config import load_config
from survey.pipeline.sweep import run, run_survey, verify

CONFIG = """
[survey]
name = "{name}"
output = "{out}"
[initial]
family = "equilateral"
delta = {{start = 0.0, stop = 6.0, num = {num}}}
energy = {energy}
[integration]
t_final = {t_final}
[indicators]
perturbations = 1
history_points = 8
[section]
max_crossings = 20
[dask]
chunk_size = {chunk}
workers = {workers}
"""


def write_config(tmp_path, name="s", num=12, t_final=20.0, chunk=4, workers=2,
                 energy="[84.45577136594005, 40.0]"):
    path = tmp_path / f"{name}.toml"
    path.write_text(CONFIG.format(name=name, out=tmp_path / f"{name}.nc", num=num,
                                  t_final=t_final, chunk=chunk, workers=workers, energy=energy))
    return path


def reproducible_variables(ds: xr.Dataset) -> list[str]:
    return [k for k in ds.data_vars if BY_NAME[k].reproducible]


def assert_same_data(a: xr.Dataset, b: xr.Dataset):
    names = reproducible_variables(a)
    assert names == reproducible_variables(b) and "ftle" in names and "crossing_phi" in names
    for name in names:
        assert a[name].values.tobytes() == b[name].values.tobytes(), name
    for c in a.coords:
        np.testing.assert_array_equal(a[c].values, b[c].values)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ref")
    cfg = write_config(tmp, "ref", chunk=5, workers=2)
    return cfg, run(cfg)


def test_archive_is_labelled_and_self_describing(reference):
    cfg, ds = reference
    assert ds.sizes["delta"] == 12 and ds.sizes["energy"] == 2
    assert list(ds.ftle.dims) == ["delta", "energy"]          # axes in the order written
    assert ds.crossing_time.dims == ("delta", "energy", "crossing")
    for name, var in ds.data_vars.items():
        assert "long_name" in var.attrs, name
        assert "units" in var.attrs or "flag_meanings" in var.attrs, name
    flags = dict(zip(ds.status.attrs["flag_meanings"].split(), ds.status.attrs["flag_values"]))
    assert flags["ok"] == 0 and flags["inaccessible"] == Status.INACCESSIBLE
    for key in ("Conventions", "title", "history", "source", "config", "config_sha256",
                "version_survey", "version_numba", "version_xarray", "git_commit"):
        assert ds.attrs[key], key
    assert ds.attrs["config"] == Path(cfg).read_text()
    # energy target 40 < U(q0) = 54: inaccessible, not an error; the others are ok
    status = ds.status.values
    assert np.all(status[:, 1] == Status.INACCESSIBLE) and np.all(status[:, 0] == Status.OK)
    assert "energy" not in ds.data_vars            # the energy axis holds it
    E = ds.initial_state.values[:, 0]
    from survey.physics.system import System
    np.testing.assert_allclose(System.create().energy(E), 84.45577136594005, rtol=1e-13)
    assert np.all(np.isnan(ds.ftle.values[:, 1]))
    # delta = 3 reproduces the integration of the same orbit outside the survey
    n = ds.n_crossings.values[6, 0]
    assert n > 5 and np.all(np.isnan(ds.crossing_time.values[6, 0, min(n, 20):]))


@pytest.mark.parametrize("chunk,workers", [(1, 2), (7, 2), (64, 2), (5, 1)])
def test_same_archive_whatever_the_chunking_or_worker_count(tmp_path, reference, chunk,
                                                            workers):
    cfg = write_config(tmp_path, "ref", chunk=chunk, workers=workers)
    assert_same_data(run(cfg), reference[1])


@pytest.mark.parametrize("fails", [False, True])
def test_a_first_run_starts_the_workers_first_and_gives_the_same_archive(tmp_path, reference,
                                                                          monkeypatch, fails):
    """On a cold kernel cache the local workers start before the driver compiles, one of
    them compiling the analysis's kernels beside it (warm_beside), and load the integrator
    from the disk cache afterwards: the same archive -- also if that head start fails."""
    import survey.pipeline.cells as cells
    import survey.pipeline.sweep as sweep
    ran = tmp_path / "warm_beside ran"          # in a worker: a file says it ran

    def beside(*args):
        ran.touch()
        if fails:
            raise ValueError("a stand-in the analysis rejects")
        cells.warm_beside(*args)

    monkeypatch.setattr(sweep, "kernels_cached", lambda: False)
    monkeypatch.setattr(sweep, "warm_beside", beside)
    cfg = write_config(tmp_path, "ref", chunk=5, workers=2)
    assert_same_data(run(cfg), reference[1])
    assert ran.exists()


def test_the_workers_build_the_starts_of_their_cells(tmp_path, reference, monkeypatch):
    """A grid's starts are built where its cells are integrated: the driver builds only
    the grid's corners (a bad value at the end of a range stops the survey before any
    work) and its first start (the kernels' warm-up), so that a grid of millions of cells
    starts at once -- and the archive is the same."""
    import survey.pipeline.cells as cells
    built, real = [], cells.build_starts

    def counted(config, ids=None):
        built.extend(ids)
        return real(config, ids)

    monkeypatch.setattr(cells, "build_starts", counted)
    cfg = write_config(tmp_path, "ref", chunk=5, workers=2)
    assert_same_data(run(cfg), reference[1])
    # the corners of 12 x 2 cells, then the first start (found, then warmed up on)
    assert sorted(built) == [0, 0, 0, 1, 22, 23]


def test_orbit_of_a_cell_of_a_million_cell_grid_builds_that_cell_alone(tmp_path, monkeypatch):
    """`orbit grid.toml --cell K` builds the start of cell K, not the grid's million: the
    same start a survey of the grid gives it."""
    import survey.pipeline.orbits as orbits
    from survey.pipeline.cells import build_starts
    built = []

    def counted(config, ids=None):
        built.append(list(ids))
        return build_starts(config, ids)

    monkeypatch.setattr(orbits, "build_starts", counted)
    path = write_config(tmp_path, "big", num=1000, energy="{start = 60.0, stop = 120.0, "
                                                        "num = 1000}")
    spec = orbits.from_survey_config(path, cells=(123456,))
    run, = orbits.run_orbits(spec)
    assert built == [[123456], [123456]]            # checked, then run
    assert run.y0.tobytes() == build_starts(load_config(path), [123456])[0].tobytes()


def test_the_same_start_gives_the_same_numbers_in_any_grid(tmp_path, reference):
    """Seeds follow the start, not the cell index: delta = ref[6] in a grid of one cell is
    the reference's cell (6, 0) bit for bit (its deviation vectors and perturbed start
    included)."""
    _, ref = reference
    delta = float(ref.delta.values[6])
    path = tmp_path / "one.toml"
    path.write_text(CONFIG.format(name="one", out=tmp_path / "one.nc", num=1, t_final=20.0,
                                  chunk=1, workers=1, energy="[84.45577136594005]")
                    .replace("{start = 0.0, stop = 6.0, num = 1}", f"[{delta!r}]"))
    one = run(path)
    assert one.sizes["delta"] == 1
    for name in reproducible_variables(ref):
        assert one[name].values[0, 0].tobytes() == ref[name].values[6, 0].tobytes(), name


def test_resume_after_sigkill_finishes_only_what_is_missing(tmp_path):
    cfg = write_config(tmp_path, "big", num=24, t_final=150.0, chunk=2)
    folder = checkpoint_dir(load_config(cfg))
    proc = subprocess.Popen([sys.executable, "-m", "survey", str(cfg), "--no-progress"],
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    deadline = time.time() + 300
    while time.time() < deadline and len(list(folder.glob("chunk-*.npz"))) < 4:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(1.0)
    files = sorted(folder.glob("chunk-*.npz"))
    assert 4 <= len(files) < 24 and not (tmp_path / "big.nc").exists()
    before = {}
    for f in files:
        with np.load(f) as z:
            before.update(zip(z["cell_ids"].tolist(), z["wall_time"].tolist()))
    resumed = run(cfg)
    wall = resumed.wall_time.values.ravel()
    for cell, seconds in before.items():      # finished cells were reused, not recomputed
        assert wall[cell] == seconds
    assert not folder.exists()
    fresh_cfg = write_config(tmp_path / "..", "big-fresh", num=24, t_final=150.0, chunk=6)
    assert_same_data(resumed, run(fresh_cfg))


# A survey on the command line with every import's finder call recorded by thread; printed
# last: how many modules the prefetch thread imported, and what other threads imported
# between its first and last import.
_IMPORTS_BY_THREAD = """
import json, sys, threading
log = []
class Spy:
    def find_spec(self, name, path=None, target=None):
        log.append((threading.current_thread().name, name))
sys.meta_path.insert(0, Spy())
from survey import cli
code = cli.main(sys.argv[1:])
mine = [i for i, (thread, _) in enumerate(log) if thread == "prefetch"]
print(json.dumps([code, len(mine), [entry for entry in log[mine[0]:mine[-1] + 1]
                                    if entry[0] != "prefetch"] if mine else []]))
"""


def test_nothing_else_imports_while_the_archive_modules_load_beside_the_workers(tmp_path):
    # CPython's imports in two threads at once once failed to find a module that was there
    # (a CI run: the progress bar's "tqdm.version" while the archive's modules loaded)
    cfg = write_config(tmp_path, "imports", num=2, t_final=2.0)
    done = subprocess.run([sys.executable, "-c", _IMPORTS_BY_THREAD, "run", str(cfg),
                           "--no-progress"], capture_output=True, text=True, check=True)
    code, prefetched, beside = json.loads(done.stdout.splitlines()[-1])
    assert code == 0 and prefetched > 100 and beside == []


def test_changed_config_never_reuses_checkpoints(tmp_path):
    a = load_config(write_config(tmp_path, "a"))
    same = load_config(write_config(tmp_path, "a", chunk=3, workers=1))
    other = load_config(write_config(tmp_path, "a", t_final=21.0))
    assert a.result_key() == same.result_key()     # dask settings do not change results
    assert a.result_key() != other.result_key()
    assert checkpoint_dir(a) != checkpoint_dir(other)


def test_a_killed_worker_does_not_lose_cells(tmp_path):
    """SIGKILL one worker process mid-survey: dask reschedules its tasks and the archive
    equals an undisturbed run's. The victim is a worker (forked from the driver, so with
    its command line, or a multiprocessing spawn_main child), never dask's resource
    tracker, killed while most chunks are still to come; its replacement is spawned."""
    import psutil
    cfg = write_config(tmp_path, "killed", num=24, t_final=150.0, chunk=1, workers=2)
    proc = subprocess.Popen([sys.executable, "-m", "survey", str(cfg), "--no-progress"],
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    folder = checkpoint_dir(load_config(cfg))
    victim = None
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None and victim is None:
        workers = []
        driver = psutil.Process(proc.pid)
        for p in driver.children(recursive=True):
            try:
                line = p.cmdline()
                if (line == driver.cmdline() or "spawn_main" in " ".join(line)) and \
                        p.status() != "zombie":
                    workers.append(p)
            except psutil.Error:       # gone or a zombie meanwhile
                pass
        if len(workers) == 2 and len(list(folder.glob("chunk-*.npz"))) >= 2:
            victim = workers[0]
            victim.kill()
        time.sleep(0.02)
    out, err = proc.communicate(timeout=300)
    assert victim is not None and proc.returncode == 0, err.decode()[-2000:]
    other = write_config(tmp_path / "..", "killed-undisturbed", num=24, t_final=150.0,
                         chunk=5, workers=2)
    assert_same_data(xr.open_dataset(tmp_path / "killed.nc"), run(other))


def test_external_scheduler_and_workers(tmp_path, reference):
    """`dask scheduler` and `dask worker` started separately on loopback; --scheduler."""
    sched_file = tmp_path / "scheduler.json"
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    dask = shutil.which("dask") or str(Path(sys.executable).parent / "dask")
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(sched_file)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                 start_new_session=True, env=env)
    try:
        deadline = time.time() + 60
        while not sched_file.exists() and time.time() < deadline:
            time.sleep(0.2)
        import json
        address = json.loads(sched_file.read_text())["address"]
        worker = subprocess.Popen([dask, "worker", "--scheduler-file", str(sched_file),
                                   "--nthreads", "1", "--nworkers", "2", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  start_new_session=True, env=env)
        try:
            cfg = write_config(tmp_path, "ref", chunk=3)
            proc = subprocess.run([sys.executable, "-m", "survey", str(cfg), "--scheduler",
                                   address, "--no-progress"], capture_output=True, text=True,
                                  timeout=600)
            assert proc.returncode == 0, proc.stderr[-2000:]
            assert_same_data(xr.open_dataset(tmp_path / "ref.nc"), reference[1])
        finally:
            os.killpg(worker.pid, signal.SIGTERM)
            worker.wait(timeout=60)
    finally:
        os.killpg(scheduler.pid, signal.SIGTERM)
        scheduler.wait(timeout=60)


def test_verify_recomputes_cells_bit_for_bit_and_catches_tampering(tmp_path, reference):
    cfg, ds = reference
    path = Path(ds.encoding["source"])
    ok, lines = verify(path, cells=6)
    assert ok, lines
    tampered = tmp_path / "tampered.nc"
    with xr.open_dataset(path) as src:
        t = src.load()
    t["ftle"].values[0, 0] = np.nextafter(t["ftle"].values[0, 0], 1.0)
    t.to_netcdf(tampered)
    from survey.cli import main
    assert main(["verify", str(tampered), "--cells", "3"]) == 1


def test_a_crash_while_writing_leaves_no_archive(tmp_path, monkeypatch):
    cfg = write_config(tmp_path, "crash", num=2, t_final=5.0)
    calls = {"n": 0}
    original = xr.Dataset.to_netcdf

    def flaky(self, *args, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError("disk full")
        return original(self, *args, **kw)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", flaky)
    with pytest.raises(SurveyError, match="disk full"):
        run_survey(cfg, workers=1)
    assert not (tmp_path / "crash.nc").exists()
    assert not list(tmp_path.glob(".crash.nc.partial*"))
    monkeypatch.setattr(xr.Dataset, "to_netcdf", original)
    assert run_survey(cfg, workers=1).exists()       # the checkpoints were kept: resumes


def test_progress_bar_shows_cells_rate_and_eta(tmp_path, capsys):
    cfg = write_config(tmp_path, "p", num=2, t_final=5.0, energy="84.45577136594005")
    run_survey(cfg, workers=1, progress=True)
    err = capsys.readouterr().err
    assert "2/2" in err and "cell/s" in err
