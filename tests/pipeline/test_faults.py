"""A hostile-but-realistic user: edited grids, lost or foreign checkpoints, concurrent runs,
bad scheduler addresses, tampered and foreign archives, bad bytes, giant sizes, full disks,
Ctrl-C, odd Python values. Each ends in a correct archive or one clear line -- never a
silent wrong result, a hang or a traceback."""
import errno
import json
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import survey.pipeline.sweep as sweep
from survey.catalog.errors import ConfigError, SurveyError
from survey.catalog.indicators import IndicatorOptions
from survey.catalog.status import Status
from survey.catalog.variables import BY_NAME
from survey.cli import main
from survey.numerics.indicators import chaos_indicators
from survey.pipeline.build import indicator_options
from survey.pipeline.cells import CellTask
from survey.pipeline.checkpoints import checkpoint_dir, output_lock
from survey.pipeline.config import code_fingerprint, load_config
from survey.pipeline.sweep import run_survey, verify

GRID = """
[survey]
name = "{name}"
output = "{out}"
[system]
[initial]
family = "equilateral"
delta = {delta}
[integration]
t_final = {t_final}
{integration}
[indicators]
perturbations = 1
history_points = 4
[section]
max_crossings = 6
[dask]
chunk_size = 2
workers = 1
{dask}
"""


def grid(tmp_path, name="g", delta="{start = 0.0, stop = 6.0, num = 8}", t_final=5.0,
         integration="", dask="", **extra):
    path = tmp_path / f"{name}.toml"
    text = GRID.format(name=name, out=tmp_path / f"{name}.nc", delta=delta, t_final=t_final,
                       integration=integration, dask=dask)
    for table, lines in extra.items():       # set keys of a table, replacing GRID's
        for line in lines.split("\n"):
            key = line.split("=")[0].strip()
            head = text.index(f"[{table}]\n") + len(f"[{table}]\n")
            body_end = text.find("\n[", head)
            body = text[head:body_end]
            kept = "".join(f"{x}\n" for x in body.split("\n")
                           if x and x.split("=")[0].strip() != key)
            text = text[:head] + f"{line}\n" + kept + text[body_end:]
    path.write_text(text)
    return path


def fresh(tmp_path, cfg: Path) -> xr.Dataset:
    """The archive an uninterrupted run of the same config writes, elsewhere."""
    other = tmp_path / "fresh"
    other.mkdir(exist_ok=True)
    text = cfg.read_text().replace(str(cfg.parent) + "/", str(other) + "/")
    path = other / cfg.name
    path.write_text(text)
    return xr.open_dataset(run_survey(path))


def same_data(a: xr.Dataset, b: xr.Dataset):
    names = [k for k in a.data_vars if BY_NAME[k].reproducible]
    assert names == [k for k in b.data_vars if BY_NAME[k].reproducible]
    for name in names:
        assert a[name].values.tobytes() == b[name].values.tobytes(), name
    for c in a.coords:
        np.testing.assert_array_equal(a[c].values, b[c].values)


def interrupt_after(monkeypatch, chunks: int):
    """Make run_survey stop like Ctrl-C after `chunks` checkpoints were written."""
    original, count = sweep.save_chunk, {"n": 0}

    def save(*args, **kw):
        original(*args, **kw)
        count["n"] += 1
        if count["n"] == chunks:
            raise KeyboardInterrupt
    monkeypatch.setattr(sweep, "save_chunk", save)


# ---------------------------------------------------------------- severe

@pytest.mark.parametrize("edited", ["{start = 0.0, stop = 5.0, num = 8}",      # moved
                                    "{start = 0.0, stop = 6.0, num = 5}",      # shrunk
                                    "[0.0, 0.8571428571428571, 9.0]"])         # relabelled
def test_an_edited_grid_never_reuses_the_old_grids_checkpoints(tmp_path, monkeypatch, edited):
    cfg = grid(tmp_path)
    interrupt_after(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        run_survey(cfg)
    old = checkpoint_dir(load_config(cfg))
    assert len(list(old.glob("chunk-*.npz"))) == 2
    monkeypatch.undo()
    cfg.write_text(cfg.read_text().replace("{start = 0.0, stop = 6.0, num = 8}", edited))
    ds = xr.open_dataset(run_survey(cfg))
    same_data(ds, fresh(tmp_path, cfg))


def test_an_edited_threshold_never_reuses_old_checkpoints(tmp_path, monkeypatch):
    """The [tori] thresholds decide in the workers which cells run again to a longer
    horizon, and their verdicts at T/2 and T are stored: a survey interrupted, its
    megno_chaotic edited and run again computes every cell again (the archive is that of a
    fresh run), not old evidence mixed in."""
    cfg = grid(tmp_path)
    interrupt_after(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        run_survey(cfg)
    monkeypatch.undo()
    before = load_config(cfg).result_key()
    cfg.write_text(cfg.read_text() + "\n[tori]\nmegno_chaotic = 2.5\n")
    assert load_config(cfg).result_key() != before
    ds = xr.open_dataset(run_survey(cfg))
    same_data(ds, fresh(tmp_path, cfg))


def test_the_result_key_covers_the_grid_and_fixed_parameters(tmp_path):
    keys = {load_config(grid(tmp_path, delta=d)).result_key() for d in (
        "{start = 0.0, stop = 6.0, num = 8}", "{start = 0.0, stop = 5.0, num = 8}",
        "{start = 0.0, stop = 6.0, num = 9}", "[0.0, 1.0]", "[0.0, 2.0]", "3.0", "3.5")}
    assert len(keys) == 7
    side = {load_config(grid(tmp_path, initial=f"side = {s}")).result_key() for s in (3.0, 3.1)}
    assert len(side) == 2
    same = {load_config(grid(tmp_path, dask=f"retries = {r}")).result_key() for r in (1, 3)}
    assert len(same) == 1                       # [dask] does not change results


def test_checkpoint_contents_are_checked_against_the_grid(tmp_path, monkeypatch, capsys):
    """A checkpoint of the right key whose starts are another grid's, an empty one, a
    corrupt one and a foreign file are named, recomputed, and the archive is right."""
    cfg = grid(tmp_path)
    interrupt_after(monkeypatch, 3)
    with pytest.raises(KeyboardInterrupt):
        run_survey(cfg)
    monkeypatch.undo()
    folder = checkpoint_dir(load_config(cfg))
    files = sorted(folder.glob("chunk-*.npz"))
    with np.load(files[0]) as z:
        forged = {k: z[k] for k in z.files}
    forged["initial_state"] = forged["initial_state"] + 1e-3    # another grid's starts
    with open(files[0], "wb") as fh:
        np.savez(fh, **forged)
    files[1].write_bytes(b"")                                    # empty
    files[2].write_bytes(files[2].read_bytes()[:200])            # truncated
    (folder / "chunk-000000000007-000000000007-1.npz").write_bytes(os.urandom(300))  # foreign
    ds = xr.open_dataset(run_survey(cfg))
    err = capsys.readouterr().err
    assert "differ from this grid's" in err and err.count("will be computed again") == 4
    same_data(ds, fresh(tmp_path, cfg))


def test_a_checkpoint_lost_before_assembly_is_recomputed(tmp_path, monkeypatch, capsys):
    """Chunks deleted while the survey runs (the folder removed, or a second run of the same
    config cleaning up) are computed again before the archive is written."""
    cfg = grid(tmp_path)
    original, saved = sweep.save_chunk, []

    def save(folder, key, ids, result):
        original(folder, key, ids, result)
        saved.append(folder)
        if len(saved) == 3:
            for f in folder.glob("chunk-*.npz"):
                f.unlink()
            folder.rmdir()
    monkeypatch.setattr(sweep, "save_chunk", save)
    ds = xr.open_dataset(run_survey(cfg))
    assert "finished cells went missing" in capsys.readouterr().err
    assert set(np.unique(ds.status.values)) <= {Status.OK, Status.INACCESSIBLE}
    monkeypatch.undo()
    same_data(ds, fresh(tmp_path, cfg))


def test_cells_that_keep_vanishing_stop_the_survey_and_write_no_archive(tmp_path, monkeypatch):
    cfg = grid(tmp_path, delta="[1.0, 2.0]", t_final=1.0)
    monkeypatch.setattr(sweep, "save_chunk", lambda *args: None)
    with pytest.raises(SurveyError, match="still missing"):
        run_survey(cfg)
    assert not (tmp_path / "g.nc").exists()


def test_a_second_survey_on_the_same_output_refuses(tmp_path):
    cfg = grid(tmp_path, delta="[1.0]")
    config = load_config(cfg)
    with output_lock(config.output):
        with pytest.raises(SurveyError, match="another survey .* is writing"):
            run_survey(cfg)
        assert main([str(cfg), "--no-progress"]) == 1
    assert run_survey(cfg).exists()                      # free again once released
    assert not list(tmp_path.glob(".g.nc.lock"))


class SilentListener:
    """A TCP port that accepts connections and never says a word (like a dashboard)."""

    def __enter__(self):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.held = []
        threading.Thread(target=self._accept, daemon=True).start()
        return f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"

    def _accept(self):
        with self.sock:
            while True:
                try:
                    self.held.append(self.sock.accept()[0])
                except OSError:
                    return

    def __exit__(self, *exc):
        self.sock.close()
        for c in self.held:
            c.close()


def run_cli(*argv, timeout=180, cwd=None):
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).parents[2]))
    proc = subprocess.run([sys.executable, "-m", "survey", *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)
    return proc.returncode, proc.stdout, proc.stderr


def test_a_port_that_never_answers_is_a_clear_error_in_bounded_time(tmp_path):
    cfg = grid(tmp_path, delta="[1.0]", dask="connect_timeout = 2.0")
    with SilentListener() as address:
        code, _, err = run_cli(cfg, "--scheduler", address, "--no-progress")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("error: [dask].scheduler: nothing at") and "within 2 s" in err


@pytest.mark.parametrize("address,message", [
    ("tcp://127.0.0.1", "is not a scheduler address"),
    ("htp://127.0.0.1:8786", "is not a scheduler address"),
    ("tcp://127.0.0.1:99999", "is not a scheduler address"),
    ("localhost:", "is not a scheduler address"),
])
def test_a_malformed_scheduler_address_is_refused_before_any_work(tmp_path, address, message):
    cfg = grid(tmp_path, delta="[1.0]", dask=f"scheduler = {json.dumps(address)}")
    with pytest.raises(ConfigError, match=message):
        load_config(cfg)


def test_an_unreachable_scheduler_is_one_line(tmp_path):
    with socket.socket() as s:              # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = grid(tmp_path, delta="[1.0]", dask=f'scheduler = "tcp://127.0.0.1:{port}"\n'
                                             "connect_timeout = 1.0")
    code, _, err = run_cli(cfg, "--no-progress")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("error: [dask].scheduler:") and "Traceback" not in err


def test_a_scheduler_without_workers_is_one_line_in_bounded_time(tmp_path):
    from dask.distributed import LocalCluster
    cfg = grid(tmp_path, delta="[1.0]", dask="connect_timeout = 1.0")
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None,
                      scheduler_kwargs={"protocol": "tcp", "host": "127.0.0.1"}) as cluster:
        code, _, err = run_cli(cfg, "--scheduler", cluster.scheduler_address,
                               "--no-progress")
    assert code != 0 and err.count("\n") == 1 and "Traceback" not in err
    assert "has no workers after 1 s" in err and "dask worker" in err


# ---------------------------------------------------------------- verify

@pytest.fixture(scope="module")
def archive_path(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("archive")
    return run_survey(grid(tmp, delta="{start = 0.0, stop = 6.0, num = 4}"))


def altered(tmp_path, path, change):
    with xr.open_dataset(path) as ds:
        ds = ds.load()
    change(ds)
    out = tmp_path / "altered.nc"
    ds.to_netcdf(out)
    return out


def _shift(ds):
    ds["delta"] = ds.delta + 100


def _edit_text(ds):
    ds.attrs["config"] = ds.attrs["config"].replace("t_final = 5.0", "t_final = 6.0")


def _non_reproducible(ds):
    ds["ftle"].attrs["reproducible"] = "no: differs between runs"
    ds["ftle"].values[0] = 0.123


@pytest.mark.parametrize("change,message", [
    (_shift, "coordinate delta differs from the grid"),
    (lambda ds: ds.__delitem__("megno"), "variable megno is missing"),
    (_edit_text, "config_sha256 does not match"),
    (_non_reproducible, "variable ftle: attribute reproducible"),
    (lambda ds: ds["crossing_time"].attrs.update(units="s"), "attribute units"),
])
def test_verify_catches_an_archive_that_departs_from_its_config(tmp_path, archive_path,
                                                               change, message):
    ok, lines = verify(altered(tmp_path, archive_path, change), cells=2)
    assert not ok and any(message in line for line in lines), lines


def test_verify_still_passes_the_untouched_archive(archive_path):
    ok, lines = verify(archive_path, cells=3)
    assert ok, lines


def test_verify_answers_files_that_are_not_archives(tmp_path, archive_path):
    text = tmp_path / "notes.nc"
    text.write_text("not netcdf")
    truncated = tmp_path / "truncated.nc"
    truncated.write_bytes(archive_path.read_bytes()[:4000])
    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}).to_netcdf(foreign)
    for path, message in [(tmp_path / "missing.nc", "no such file"),
                          (tmp_path, "not a regular file"),
                          (text, "not a readable NetCDF file"),
                          (truncated, "not a readable NetCDF file"),
                          (foreign, "not a survey archive")]:
        code, out, err = run_cli("verify", path)
        assert code == 2 and err.count("\n") == 1 and message in err, err
        assert "Traceback" not in err


# ---------------------------------------------------------------- one line, not a traceback

BAD_CONFIGS = [
    ("utf-16", lambda text: text.encode("utf-16"), "is UTF-16 text"),
    ("latin-1", lambda text: text.replace('"g"', '"gré"').encode("latin-1"), "is not UTF-8"),
    ("binary", lambda text: b"\x89PNG\r\n\x1a\n" + bytes(range(256)), "is not UTF-8"),
    ("nul", lambda text: text.replace('name = "g"', 'name = "a\\u0000b"').encode(), "NUL"),
]


@pytest.mark.parametrize("what,encode,message", BAD_CONFIGS, ids=[b[0] for b in BAD_CONFIGS])
def test_config_bytes_that_are_not_utf8_toml(tmp_path, what, encode, message):
    cfg = grid(tmp_path)
    cfg.write_bytes(encode(cfg.read_text()))
    code, _, err = run_cli(cfg)
    assert code == 2 and err.count("\n") == 1 and message in err, err


@pytest.mark.parametrize("name,message", [
    ("x" * 300, "[survey].output: a name in it is too long"),
    ("../escape", "[survey].name: '../escape' is not a usable name"),
    ("", "[survey].name: '' is not a usable name"),
    ("a/b", "[survey].name: 'a/b' is not a usable name"),
])
def test_names_that_are_paths_or_too_long(tmp_path, name, message):
    """The name makes the default output results/NAME.nc."""
    cfg = grid(tmp_path)
    cfg.write_text(cfg.read_text().replace('name = "g"', f"name = {json.dumps(name)}")
                   .replace(f'output = "{tmp_path}/g.nc"\n', ""))
    code, _, err = run_cli(cfg, "--no-progress", cwd=tmp_path)
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "results").exists() or not any((tmp_path / "results").iterdir())


LINES = [
    ("integration", "max_steps = 99999999999999999999", "does not fit a 64-bit integer"),
    ("section", "max_crossings = 1000000000000", "[section].max_crossings: this survey would need"),
    ("indicators", "history_points = 1000000000000", "[indicators].history_points: this survey"),
    ("system", "bodies = 2000000000", "[system].bodies: this survey would need"),
    ("initial", 'velocity_u = [nan, 1.0]\nfamily = "linear"', "expected finite numbers"),
    ("initial", "side = inf", "[initial].side: must be finite"),
]


@pytest.mark.parametrize("table,line,message", LINES, ids=[m.split(":")[0] + m[-12:] for *_, m in LINES])
def test_values_that_would_crash_or_exhaust_the_machine(tmp_path, table, line, message):
    cfg = grid(tmp_path, **{table: line})
    if 'family = "linear"' in line:
        cfg.write_text(cfg.read_text().replace('family = "equilateral"\n', ""))
    code, _, err = run_cli(cfg, "--no-progress")
    assert code == 2 and err.count("\n") == 1 and message in err, err


@pytest.mark.parametrize("delta,message", [
    ("{start = 0.0, stop = 1e12, num = 1000000000000}", "[initial]: 1,000,000,000,000 cells"),
    ("{start = 0.0, stop = 1.0, num = 10000000}\nenergy = {start = 90.0, stop = 99.0, num = 10000000}",
     "[initial]: 100,000,000,000,000 cells"),
    ("{start = -1.7e308, stop = 1.7e308, num = 3}", "the grid overflows"),
    ("{start = 1.0, stop = 1.0, num = 3}", "values must be distinct"),
    ("{start = 1.0, stop = 1.0000000000000002, num = 5}", "values must be distinct"),
])
def test_grid_axes_that_cannot_be_built(tmp_path, delta, message):
    code, _, err = run_cli(grid(tmp_path, delta=delta), "--no-progress")
    assert code == 2 and err.count("\n") == 1 and message in err, err


def test_outputs_that_are_not_plain_files(tmp_path):
    link = tmp_path / "link.nc"
    link.symlink_to(tmp_path / "elsewhere.nc")
    for output, message in [("/dev/null", "not a regular file"), (link, "symbolic link"),
                            (tmp_path / ("y" * 250 + ".nc"), "too long"),
                            (str(tmp_path) + "/" + "d/" * 2100 + "x.nc", "too long")]:
        code, _, err = run_cli(grid(tmp_path, delta="[1.0]"), "--output", output)
        assert code == 2 and err.count("\n") == 1 and message in err, err


def test_a_full_disk_names_the_file_and_keeps_the_finished_cells(tmp_path, monkeypatch, capsys):
    cfg = grid(tmp_path)
    original, calls = np.savez, {"n": 0}

    def savez(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return original(*args, **kw)
    monkeypatch.setattr(np, "savez", savez)
    assert main([str(cfg), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no space left on the device writing" in err
    assert "MiB free" in err and "finished cells are kept" in err
    folder = checkpoint_dir(load_config(cfg))
    assert len(list(folder.glob("chunk-*.npz"))) == 2
    assert not list(folder.glob(".*.tmp"))
    monkeypatch.undo()
    same_data(xr.open_dataset(run_survey(cfg)), fresh(tmp_path, cfg))


def test_ctrl_c_says_how_to_resume_and_the_rerun_finishes(tmp_path):
    cfg = grid(tmp_path, delta="{start = 0.0, stop = 6.0, num = 24}", t_final=300.0)
    folder = checkpoint_dir(load_config(cfg))
    # as from a terminal: SIGINT handled. A test run started in the background (nohup,
    # `&`, some CI runners) ignores SIGINT, and a child inherits that: the survey would
    # rightly run on through the Ctrl-C
    terminal = ("import runpy, signal, sys; signal.signal(signal.SIGINT, "
                "signal.default_int_handler); sys.argv[0] = 'survey'; "
                "runpy.run_module('survey', run_name='__main__', alter_sys=True)")
    proc = subprocess.Popen([sys.executable, "-c", terminal, str(cfg), "--no-progress"],
                            start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not list(folder.glob("chunk-*.npz")) and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.02)
    assert proc.poll() is None, "the survey ended before its first checkpoint was seen"
    os.killpg(proc.pid, signal.SIGINT)      # what a terminal's Ctrl-C does: the whole group
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (out, err)
    assert err.strip() == "interrupted -- run the same command to resume", err
    assert 1 <= len(list(folder.glob("chunk-*.npz"))) < 12
    code, out, err = run_cli(cfg, "--no-progress")
    assert code == 0 and "wrote" in out
    same_data(xr.open_dataset(tmp_path / "g.nc"), fresh(tmp_path, cfg))


def test_a_worker_says_nothing_of_the_scheduler_the_driver_stopped():
    """A Ctrl-C stops the driver's scheduler while the workers, which ignore it, still run:
    a heartbeat then failed and printed dask's traceback above the survey's one line (a
    loaded machine, 2026-11-28). Our workers drop that record and keep their other errors."""
    script = ("import logging; from survey.pipeline import sweep; sweep.dask_setup(None); "
              "log = logging.getLogger('distributed.worker'); "
              "log.error('Failed to communicate with scheduler during heartbeat.'); "
              "log.error('Compute Failed')")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == "Compute Failed", done.stderr


def test_a_ctrl_c_before_dask_has_begun_the_call_prints_no_traceback(caplog):
    """distributed's `sync` answers a Ctrl-C by scheduling a cancel on its loop thread,
    which fails with a logged NameError when its call has not begun; the loop busy, that
    is certain. The survey's handler silences the logs before the interrupt is raised, not
    once it has unwound to an `except`, which the cancel can beat."""
    import asyncio
    import logging

    from distributed.utils import LoopRunner, sync
    loggers = {n: logging.getLogger(n).level for n in list(logging.root.manager.loggerDict)}
    handler = signal.signal(signal.SIGINT, signal.default_int_handler)
    runner = LoopRunner(asynchronous=False)
    runner.start()
    try:
        with caplog.at_level(logging.ERROR), pytest.raises(KeyboardInterrupt):
            with sweep._quiet_interrupt():
                runner.loop.add_callback(time.sleep, 1.0)   # the loop busy: no call begun
                threading.Timer(0.1, os.kill, (os.getpid(), signal.SIGINT)).start()
                try:
                    sync(runner.loop, asyncio.sleep, 5)
                finally:        # the unwinding (a client's close) outlasts the busy loop
                    time.sleep(2.0)
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        with caplog.at_level(logging.ERROR):
            sync(runner.loop, asyncio.sleep, 0)         # after the cancel has run
        assert not [r for r in caplog.records if r.name.startswith("tornado")], caplog.text
    finally:
        runner.stop()
        signal.signal(signal.SIGINT, handler)
        for name, level in loggers.items():
            logging.getLogger(name).setLevel(level)


@pytest.mark.parametrize("deletions", [("folder",), ("file", "folder")],
                         ids=["folder", "file-then-folder"])
def test_a_checkpoint_written_while_it_is_deleted(tmp_path, monkeypatch, deletions):
    """A deletion beside the write (a user clearing old checkpoints; what the test below
    can hit): the folder removed between its making and the file's rename, or first the
    temporary file alone while the folder is still there (shutil.rmtree takes the files,
    then the folder). The chunk is written again after each."""
    import shutil

    import survey.pipeline.checkpoints as checkpoints
    folder, fsync, calls = tmp_path / "c" / "key", os.fsync, []

    def deleting(fd):
        fsync(fd)
        calls.append(fd)
        if len(calls) <= len(deletions):
            if deletions[len(calls) - 1] == "file":
                next(folder.glob(".*.tmp")).unlink()
            else:
                shutil.rmtree(folder.parent)
    monkeypatch.setattr(checkpoints.os, "fsync", deleting)
    checkpoints.save_chunk(folder, "k", [3, 5], {"x": np.arange(2.0)})
    assert len(calls) == len(deletions) + 1 and [p.name for p in folder.iterdir()] == \
        [checkpoints.chunk_path(folder, [3, 5]).name]
    with np.load(checkpoints.chunk_path(folder, [3, 5])) as z:
        assert z["x"].tolist() == [0.0, 1.0] and z["cell_ids"].tolist() == [3, 5]


def test_a_checkpoint_deleted_before_the_archive_reads_it(tmp_path, monkeypatch, capsys):
    """Every checkpoint was there when the computing ended, one is gone when the archive
    reads it: its cells are computed again and the archive is whole, not "cannot write"."""
    cfg = grid(tmp_path)
    real, calls = sweep.loader, []

    def deleting(config, files, cells=None):
        calls.append(sorted(files))
        if len(calls) == 1:
            sorted(files)[0].unlink()
        return real(config, files, cells)
    monkeypatch.setattr(sweep, "loader", deleting)
    with xr.open_dataset(run_survey(cfg)) as ds:
        assert len(calls) == 2 and calls[0][0] in calls[1]   # written again, then read
        assert "went missing" in capsys.readouterr().err
        same_data(ds, fresh(tmp_path, cfg))


def test_the_checkpoint_folder_deleted_mid_run(tmp_path):
    import shutil
    cfg = grid(tmp_path, delta="{start = 0.0, stop = 6.0, num = 24}", t_final=200.0)
    folder = checkpoint_dir(load_config(cfg))
    proc = subprocess.Popen([sys.executable, "-m", "survey", str(cfg), "--no-progress"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while len(list(folder.glob("chunk-*.npz"))) < 2 and proc.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None               # deleted while the survey still runs
    shutil.rmtree(folder.parent, ignore_errors=True)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    assert "went missing" in err
    same_data(xr.open_dataset(tmp_path / "g.nc"), fresh(tmp_path, cfg))


@pytest.mark.parametrize("argv,message", [
    (["--param", "delta=nan"], "--param delta=nan: the value must be a finite number"),
    (["--tol", "0"], "--tol: must be >= 2.22e-15"),
    (["--tol", "0.1"], "--tol: must be <= 0.001"),
    (["--t-final", "inf"], "--t-final: must be a finite number > 0"),
    (["--family", "nope"], "--family: 'nope' is not one of 'sides', 'equilateral'"),
    (["--potential", "areal_powr"], "--potential: unknown triplet potential 'areal_powr'"),
    (["--potential-param", "exponent=x"], "--potential-param exponent=x: expected KEY=NUMBER"),
    (["--potential-param", "gama=1"], "--potential-param gama: not a parameter of"),
    (["--param", "delt=1"], "--param delt: not a parameter of family 'sides'"),
    (["--masses", "1,2"], "--masses: a system with a triplet term needs masses for N >= 3 bodies"),
    (["--masses", "1,-2,3"], "--masses: "),
    (["--cell", "3"], "--cell: picks cells of a survey config"),
    (["--zoom-until", "-1"], "--zoom-until: must be >= 0"),
])
def test_orbit_command_arguments(argv, message):
    code, _, err = run_cli("orbit", *argv)
    assert code == 2 and err.count("\n") == 1 and message in err, err


def test_the_python_api_takes_numpy_values_tuples_and_none(tmp_path):
    base = dict(survey={"name": "api", "output": str(tmp_path / "api.nc")},
                initial={"family": "equilateral", "delta": np.linspace(0.0, 6.0, 4),
                         "side": np.float64(3.4641016151377544), "v_rot": None},
                integration={"t_final": np.float32(5.0), "max_steps": np.int64(100000)},
                indicators={"perturbations": np.int32(1), "history_points": 4},
                section={"max_crossings": 6, "triplet": (0, 1, 2)},
                dask={"workers": 1})
    config = load_config(base)
    assert config.shape == (4,) and config.tables["integration"]["max_steps"] == 100000
    assert isinstance(config.tables["section"]["triplet"], list)
    ds = xr.open_dataset(run_survey(base, workers=np.int64(1), progress=np.bool_(False)))
    toml = grid(tmp_path, "api", delta="[0.0, 2.0, 4.0, 6.0]")
    same_data(ds, fresh(tmp_path, toml))


@pytest.mark.parametrize("change,message", [
    (dict(integration={"t_final": object()}), "object is not a config value"),
    (dict(initial={"family": "equilateral", "delta": np.zeros((2, 2, 2))}), "3-D array"),
    (dict(initial={"family": "equilateral", "delta": {1, 2}}), "set is not a config value"),
    (dict(system={1: 2}), "table keys must be strings"),
])
def test_the_python_api_rejects_what_is_not_a_config_value(tmp_path, change, message):
    base = {"survey": {"output": str(tmp_path / "x.nc")}, "initial": {"family": "equilateral"}}
    with pytest.raises(ConfigError, match=message):
        load_config({**base, **change})
    with pytest.raises(ConfigError):
        load_config(42)


@pytest.mark.parametrize("kw", [dict(workers=0), dict(workers=True), dict(workers="2"),
                                dict(scheduler=8786), dict(progress="yes")])
def test_run_survey_checks_its_own_arguments(tmp_path, kw):
    with pytest.raises(ConfigError):
        run_survey(grid(tmp_path, delta="[1.0]"), **kw)


# ---------------------------------------------------------------- accepted silently before

def test_stale_temporary_files_are_removed(tmp_path):
    cfg = grid(tmp_path, delta="[1.0]")
    stale = [tmp_path / ".g.nc.partial-999999",
             checkpoint_dir(load_config(cfg)).parent / "0123" / ".chunk-1.npz.999999.tmp"]
    for f in stale:
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(b"half")
    run_survey(cfg)
    assert not any(f.exists() for f in stale)


def test_truncated_runs_do_not_pass_for_chaos(tmp_path):
    """A run cut short (here by max_steps) has no indicators: its deviation vectors'
    growth up to a near collision would read as strong chaos."""
    ds = xr.open_dataset(run_survey(grid(tmp_path, delta="[1.0, 4.5]",
                                         integration="max_steps = 40")))
    assert np.all(ds.status.values == Status.STEP_LIMIT)
    assert np.all(ds.t_end.values < 5.0) and np.all(ds.n_steps.values > 0)
    for name in ("ftle", "megno", "fli", "sali", "gali2", "ftle_history", "megno_history"):
        assert np.all(np.isnan(ds[name].values)), name
    assert np.all(np.isfinite(ds.energy_error.values))
    assert "except in cells with status ok" in ds.ftle.attrs["comment"]


def test_the_time_budget_bounds_every_orbit_of_a_cell(paper_system):
    """cell_time_limit bounds each orbit of a cell (they run side by side as lanes): with a
    microsecond budget and an orbit that needs 10^5 time units, the driver's clock check
    after its first 256 rounds stops the nominal orbit and its neighbours, and the cell is
    time_limit -- for one lane after another and for SIMD lanes alike."""
    from survey.physics.families import initial_state
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    for lanes in (1, 16):
        ci = chaos_indicators(paper_system, y0, 1e5, IndicatorOptions(perturbations=2),
                              time_limit=1e-6, lanes=lanes)
        assert ci.status == Status.TIME_LIMIT and 0 < ci.t < 1e5
    free = chaos_indicators(paper_system, y0, 1.0, IndicatorOptions(perturbations=2))
    assert free.status == Status.OK


def test_a_task_ships_no_grid_and_no_config_text(tmp_path):
    """What every dask task carries does not grow with the grid."""
    sizes = []
    for num in (10, 20000):
        config = load_config(grid(tmp_path, delta=f"{{start = 0.0, stop = 6.0, num = {num}}}"))
        blob = pickle.dumps(CellTask.of(config))
        assert b"[survey]" not in blob
        sizes.append(len(blob))
    assert sizes[0] == sizes[1] < 4000


def test_no_dashboard_port_warning(tmp_path):
    with socket.socket() as busy:
        try:
            busy.bind(("127.0.0.1", 8787))
            busy.listen(1)
        except OSError:
            pass                        # taken already: the warning would show all the same
        code, _, err = run_cli(grid(tmp_path, delta="[1.0]"), "--no-progress")
    assert code == 0 and "already in use" not in err and err == ""


# ---------------------------------------------------------------- precision and defaults

def test_gali2_has_no_cancellation_floor(paper_system):
    """On the chaotic orbit the two deviation vectors align to ~1e-14; GALI_2 follows SALI
    down instead of stopping near 1e-8 as sqrt(1 - c^2) did."""
    from survey.physics.families import initial_state
    y0 = initial_state(paper_system, "sides")
    ci = chaos_indicators(paper_system, y0, 400.0, IndicatorOptions(perturbations=0))
    assert ci.sali < 1e-10
    assert ci.gali2 == pytest.approx(ci.sali, rel=1e-3)


def test_one_set_of_indicator_defaults(tmp_path):
    config = load_config({"survey": {"output": str(tmp_path / "x.nc")},
                          "initial": {"family": "equilateral"}})
    assert indicator_options(config.settings.indicators) == IndicatorOptions()


def test_the_code_fingerprint_covers_subpackages(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 1\n")
    before = code_fingerprint(tmp_path)
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    changed = code_fingerprint(tmp_path)
    (tmp_path / "sub" / "b.py").rename(tmp_path / "b.py")
    (tmp_path / "b.py").write_text("y = 1\n")
    moved = code_fingerprint(tmp_path)
    assert len({before, changed, moved}) == 3


# ---------------------------------------------------------------- CF

def test_archives_pass_the_cf_compliance_checker(tmp_path, archive_path):
    """The IOOS compliance checker (cf:1.10) finds nothing to fix at any priority, on a 2-D
    survey with a section and on a 3-D one storing crossing states."""
    from compliance_checker.runner import CheckSuite, ComplianceChecker
    three_d = run_survey(grid(tmp_path, "three", delta="[0.0, 1.0]",
                              system="dim = 3",
                              section='coordinate = "perimeter"\nvalue = 6.0\n'
                                      "store_state = true"))
    CheckSuite().load_all_available_checkers()
    for path in (archive_path, three_d):
        report = tmp_path / "cf.json"
        passed, trouble = ComplianceChecker.run_checker(str(path), ["cf:1.10"], 0, "normal",
                                                        output_filename=str(report),
                                                        output_format="json")
        result = json.loads(report.read_text())["cf:1.10"]
        failed = [(item["name"], item["msgs"]) for level in ("high", "medium", "low")
                  for item in result[f"{level}_priorities"]
                  if item["value"][0] < item["value"][1]]
        assert passed and not trouble and not failed, failed


def test_a_full_disk_at_the_archive_write_is_one_line_and_keeps_the_cells(tmp_path, monkeypatch,
                                                                         capsys):
    """netCDF4 reports a disk that fills while the archive is written as a RuntimeError
    ('NetCDF: HDF error'): one line naming the file, the checkpoints kept."""
    cfg = grid(tmp_path)

    def full(self, *args, **kw):
        raise RuntimeError("NetCDF: HDF error")
    monkeypatch.setattr(xr.Dataset, "to_netcdf", full)
    assert main([str(cfg), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write" in err and "is the disk full?" in err, err
    assert "finished cells are kept" in err
    assert list(checkpoint_dir(load_config(cfg)).glob("chunk-*.npz"))


def test_a_name_that_cannot_be_written_is_a_config_error():
    with pytest.raises(ConfigError, match=r"\[survey\]\.name: .*lone surrogate"):
        load_config({"survey": {"name": "bad\udc80"}, "initial": {"family": "equilateral",
                                                                 "delta": [1.0]}})
