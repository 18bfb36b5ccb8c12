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
