"""A phase without a progress bar says what it is doing once it has taken half a second,
its time every second after that, and nothing if it is quick; so does any numba compile."""
import io
from pathlib import Path
import time
from contextlib import redirect_stderr

from survey.pipeline.progress import notice


def test_a_slow_phase_is_announced_and_timed_a_quick_one_is_silent():
    err = io.StringIO()
    with redirect_stderr(err):
        with notice("compiling", after=0.01):
            deadline = time.monotonic() + 60
            while "compiling" not in err.getvalue() and time.monotonic() < deadline:
                time.sleep(0.01)
        with notice("quick", after=600):
            pass
        with notice("disabled", enabled=False, after=0):
            time.sleep(0.05)
    lines = err.getvalue().splitlines()
    assert lines[0] == "survey: compiling ..." and lines[1].startswith("survey: ... done in ")
    assert len(lines) == 2


def wait_for(stream, text):
    deadline = time.monotonic() + 60
    while text not in stream.getvalue() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_a_long_phase_ticks_and_a_phase_that_ends_after_another_names_itself():
    err = io.StringIO()
    with redirect_stderr(err):
        with notice("writing", after=0.01):
            wait_for(err, "writing ... 1 s")           # its time, on its own line
            with notice("solving", after=0.01):
                wait_for(err, "survey: solving ...")
            wait_for(err, "done in")
    text = err.getvalue()
    assert "\rsurvey: writing ... 1 s" in text
    lines = text.replace("\r", "\n").splitlines()
    assert lines[-1].startswith("survey: ... writing: done in ")       # not the last line
    assert lines[-3:-1] == ["survey: solving ...", lines[-2]]
    assert lines[-2].startswith("survey: ... done in ")     # solving's, right after its line


def test_any_compile_that_takes_time_says_so_on_a_terminal():
    import numba

    from survey.pipeline import progress
    err = io.StringIO()
    progress._watching.clear()
    progress.watch_compiles(after=0.0)
    try:
        @numba.njit
        def announced(x):
            return x + 1
        with redirect_stderr(err):
            assert announced(1) == 2
    finally:
        from numba.core import event
        event.unregister("numba:compile", progress._watching.pop())
    text = err.getvalue()
    assert "announced and what it calls (numba; the first time" in text
    assert "survey: ... done in " in text


def test_a_cold_kernel_cache_is_recognised(tmp_path):
    """The command line says at once that a first run compiles: it knows from numba's cache
    index of the integrator's kernel whether the kernels are there."""
    from survey.machine.jit import kernels_cached
    cache = tmp_path / "numerics" / "__pycache__"
    cache.mkdir(parents=True)
    assert not kernels_cached(tmp_path)
    (cache / "driver._run-400.py311.nbi").write_bytes(b"")
    assert kernels_cached(tmp_path)


def test_kernel_caches_elsewhere_are_found_and_refreshed(tmp_path, monkeypatch):
    """With NUMBA_CACHE_DIR, numba keeps a folder's kernels in <dir>/<name>_<sha1 of its
    path>: the first-run notice looks there, and a change of the kernel sources deletes
    the stale kernels there."""
    from survey.machine.jit import cache_folder, kernels_cached, refresh_kernel_cache
    package = tmp_path / "survey"
    (package / "numerics").mkdir(parents=True)
    (package / "numerics" / "integrate.py").write_text("# a kernel source\n")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    refresh_kernel_cache(package)
    folder = cache_folder(package / "numerics")
    assert folder.parent == tmp_path / "cache" and folder.name.startswith("numerics_")
    folder.mkdir()
    (folder / "driver._run-400.py311.nbi").write_bytes(b"")
    assert kernels_cached(package)
    refresh_kernel_cache(package)                   # sources unchanged: kept
    assert kernels_cached(package)
    (package / "numerics" / "integrate.py").write_text("# edited\n")
    refresh_kernel_cache(package)
    assert not kernels_cached(package)


def test_a_read_only_install_is_looked_for_in_numbas_cache_in_the_home(tmp_path, monkeypatch):
    """Where a package's __pycache__ cannot be written, numba caches its kernels under its
    cache folder in the user's home: the first-run notice and the refresh of stale kernels
    look there (not at the empty __pycache__, which said "first run" every time)."""
    import survey.machine.jit as jit
    from numba.misc.appdirs import AppDirs
    package = tmp_path / "survey"
    (package / "numerics").mkdir(parents=True)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "home-cache"))
    assert jit.cache_folder(package / "numerics") == package / "numerics" / "__pycache__"
    monkeypatch.setattr(jit.os, "access", lambda path, mode: not str(path).startswith(
        str(package)))
    folder = jit.cache_folder(package / "numerics")
    assert folder.parent == Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)
    assert folder.parent.is_relative_to(tmp_path / "home-cache")
    assert folder.name.startswith("numerics_")
    folder.mkdir(parents=True)
    (folder / "driver._run-400.py311.nbi").write_bytes(b"")
    assert jit.kernels_cached(package)


COVERAGE = r"""
import numpy as np
from numba.core.dispatcher import Dispatcher
from survey.numerics import driver, integrate, torus
from survey.machine import linalg, portable
from survey.physics import system as system_module
from survey.physics.equilibria import relative_equilibrium
from survey.pipeline import cells
from survey.pipeline.config import parse_config

# the stepping round's leaves (driver.round_only)
ROUND = ["spread_steps", "error_norms", "step_factors", "finite_lanes", "take_steps",
         "tangent_norms", "growth_terms", "dense_prepare", "_flush", "stages"]

def signatures():
    kernels = [(m.__name__, k, v) for m in (torus, linalg) for k, v in vars(m).items()
               if isinstance(v, Dispatcher)] + [
        *[("driver", k, getattr(driver, k)) for k in ROUND]] + [
        ("system", "_potential_energies", system_module._potential_energies),
        ("system", "rhs", system_module.rhs),
        ("portable", "_elementwise", portable._elementwise),
        ("portable", "power", portable.power)]
    return {(m, k): set(map(str, v.signatures)) for m, k, v in kernels}

config = parse_config('''
[survey]
name = "coverage"
[initial]
family = "equilateral"
delta = [0.0, 3.0]
[integration]
t_final = 40.0
[indicators]
perturbations = 1
''', "coverage")
task, starts = cells.CellTask.of(config), cells.build_starts(config)
cells.warm_beside(task, np.array([0]), starts[:1])
warm = signatures()
assert sum(map(len, warm.values())) > 10, warm
assert all(warm[k] for k in [("system", "_potential_energies"),
                             ("system", "rhs"),
                             ("portable", "_elementwise"), ("portable", "power")] +
           [("driver", k) for k in ROUND]), warm
res = cells.run_cells(task, np.array([0, 1]), starts)        # real samples, analysed
assert np.isfinite(res["frequency"]).any()
system = config.system()
q, p = system.split(starts[0])                               # delta = 0: the equilibrium
eq = relative_equilibrium(system, q, angular_momentum=float(system.angular_momentum(starts[0])))
assert eq.frequencies.size
new = {k: v - warm[k] for k, v in signatures().items() if v - warm[k]}
print(new)
"""


def test_the_kernels_compiled_beside_the_driver_are_those_a_survey_uses(tmp_path):
    """A first run compiles the integrator's stepping round and the energies', the torus
    analysis's and the linear algebra's kernels in a worker while the
    driver compiles the integrator (cells.warm_beside), on stand-in data and lanes: a
    kernel that a survey's cells and the report's relative equilibria then call with
    arguments of another type -- or one the stand-in never reached -- would compile
    again, in the driver as it compiles the integrator, in the workers, or after the
    survey. Run in a fresh process, where numba's dispatchers list what that process
    compiled or loaded."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", COVERAGE], capture_output=True, text=True,
                         cwd=tmp_path, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == "{}", out.stdout


def test_a_first_run_in_one_process_compiles_beside_it_in_a_second(tmp_path):
    """`verify`, `orbit`, `periodic` and `equilibria` compile beside themselves
    (cells.compiled_beside): the helper runs in another process; one that fails leaves the
    block alone; one still running when the block ends is stopped, not waited for."""
    import os
    import pytest
    from survey.pipeline import cells
    marker = tmp_path / "helper"

    def warm(path, text):       # written whole, then renamed: seen whole or not at all
        path.with_suffix(".part").write_text(f"{os.getpid()} {text}")
        path.with_suffix(".part").replace(path)

    def fail():
        raise RuntimeError("a helper that fails")

    def endless(path):
        warm(path, "endless")
        time.sleep(3600)

    with cells.compiled_beside(warm, marker, "ran"):
        here = os.getpid()
        deadline = time.monotonic() + 60
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
    pid, text = marker.read_text().split()
    assert text == "ran" and int(pid) != here
    with cells.compiled_beside(fail):
        done = True
    assert done
    marker.unlink()
    with cells.compiled_beside(endless, marker):
        deadline = time.monotonic() + 60
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
    with pytest.raises(ProcessLookupError):
        os.kill(int(marker.read_text().split()[0]), 0)


def test_the_helpers_of_first_runs_in_one_process_run_without_error():
    """compiled_beside's helpers swallow their errors (a failed head start only costs a
    first run time), so each runs here, where an error shows: `verify`'s, `orbit`'s and
    the solvers' (with and without the integrator), on the paper's system (kernels the
    suite has compiled already: a pair term's full states would compile their own)."""
    import numpy as np
    from survey.numerics import driver
    from survey.numerics.integrate import integrate
    from survey.physics.families import initial_state
    from survey.physics.system import System
    from survey.pipeline import cells, orbits
    from survey.pipeline.config import parse_config
    config = parse_config('[survey]\nname = "helpers"\n[initial]\nfamily = "equilateral"\n'
                          'delta = [0.0, 3.0]\n[integration]\nt_final = 10.0\n', "helpers")
    task, starts = cells.CellTask.of(config), cells.build_starts(config)
    cells.warm_beside(task, np.array([1]), starts[1:], report=False)
    system = System.create()
    y0 = initial_state(system, "equilateral", delta=3.0)
    cells.warm_solvers(system, y0)
    cells.warm_solvers(system, y0, False)
    orbits._warm(lambda: integrate(system, y0, 1e-3), system, y0)
    assert driver.stages.signatures and driver.error_norms.signatures


def test_a_continuations_bar_shows_the_span_covered_and_the_members_found():
    from survey.pipeline.progress import family_bar
    err = io.StringIO()
    with redirect_stderr(err):
        with family_bar("following", True) as on_member:
            on_member(3, 0.5)
            on_member(4, 1.7)           # past the end: the bar stays at 100%
    text = err.getvalue()
    assert "survey: following, 3 members:  50% of the span" in text
    assert "survey: following, 4 members: 100% of the span" in text
    with family_bar("following", False) as on_member:
        assert on_member is None
