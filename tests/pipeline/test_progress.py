"""A phase without a progress bar says what it is doing once it has taken a second, and
nothing if it is quick."""
import io
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


def test_a_cold_kernel_cache_is_recognised(tmp_path):
    """The command line says at once that a first run compiles: it knows from numba's cache
    index of the integrator's kernel whether the kernels are there."""
    from survey.physics.jit import kernels_cached
    cache = tmp_path / "numerics" / "__pycache__"
    cache.mkdir(parents=True)
    assert not kernels_cached(tmp_path)
    (cache / "integrate._run-400.py311.nbi").write_bytes(b"")
    assert kernels_cached(tmp_path)
