"""What a user at a terminal sees while a phase without a progress bar runs: a line on
stderr once the phase has taken a second (compiling the kernels the first time, starting the
workers, writing the archive), and how long it took -- so that compiling never looks hung,
and a fast phase prints nothing."""
from __future__ import annotations

import contextlib
import sys
import threading
import time

# how long the kernels take to compile on a machine's first run (README: measured), said
# wherever a user waits for it
FIRST_COMPILE = "half a minute to a minute on 2 cores"
COMPILING = ("compiling survey's kernels for this kind of system (the first run only: "
             f"{FIRST_COMPILE}; later runs load them from numba's disk cache)")


@contextlib.contextmanager
def notice(message: str, enabled: bool = True, after: float = 1.0):
    """Print `survey: message ...` on stderr if the block is still running after `after`
    seconds, then `survey: ... done in X s` when it ends."""
    if not enabled:
        yield
        return
    start = time.perf_counter()
    shown = threading.Event()

    def show():
        print(f"survey: {message} ...", file=sys.stderr, flush=True)
        shown.set()

    timer = threading.Timer(after, show)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        timer.join()          # a line being printed is finished first
        if shown.is_set():
            took = time.perf_counter() - start
            print(f"survey: ... done in {took:.{0 if took >= 10 else 1}f} s", file=sys.stderr,
                  flush=True)
