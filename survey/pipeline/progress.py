"""What a user at a terminal sees while a phase without a progress bar runs: a line on
stderr once the phase has taken a second (compiling the kernels the first time, starting the
workers, writing the archive), and how long it took -- so that compiling never looks hung,
and a fast phase prints nothing. `watch_compiles` does the same for any numba kernel not yet
in the cache, wherever a command first needs it."""
from __future__ import annotations

import contextlib
import sys
import threading
import time

# how long the kernels take to compile on a machine's first run (bench --only fixed
# measures it), said wherever a user waits for it
FIRST_COMPILE = "half a minute to a minute on 2 cores"
COMPILING = ("compiling survey's kernels for this kind of system (the first run only: "
             f"{FIRST_COMPILE}; later runs load them from numba's disk cache)")


# notices of compiling the kernels now open: while one is, compiles say nothing more
_compiling = [0]
# the phase whose "..." line was printed last: a phase that ends after another's line
# names itself in its "done" line
_last = [None]


def _say(text: str, phase) -> None:
    print(f"survey: {text}", file=sys.stderr, flush=True)
    _last[0] = phase


def _done(phase, message: str, seconds: float) -> None:
    took = f"{seconds:.{0 if seconds >= 10 else 1}f} s"
    _say(f"... done in {took}" if _last[0] is phase else f"... {message}: done in {took}",
         None)


@contextlib.contextmanager
def notice(message: str, enabled: bool = True, after: float = 1.0, compiling: bool = False):
    """Print `survey: message ...` on stderr if the block is still running after `after`
    seconds, then `survey: ... done in X s` when it ends. `compiling`: the block is the
    kernels' compilation, announced by this message (watch_compiles stays quiet)."""
    if not enabled:
        yield
        return
    if compiling:
        _compiling[0] += 1
        try:
            with notice(message, True, after):
                yield
        finally:
            _compiling[0] -= 1
        return
    start = time.perf_counter()
    shown = threading.Event()

    def show():
        _say(f"{message} ...", shown)
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
            _done(shown, message, time.perf_counter() - start)


_watching = []


def watch_compiles(after: float = 1.0) -> None:
    """From now on in this process, any numba compilation that takes longer than `after`
    seconds says so on stderr -- which kernel, that it happens once (numba caches it) --
    and how long it took: the kernels a command compiles the first time it needs them
    (the report's solvers, the families' shooting), not only the integrator's. Quiet
    inside a notice(compiling=True), which has said it already, and in the processes
    forked from this one (the local workers: the driver speaks for them). Idempotent."""
    if _watching:
        return
    import os

    from numba.core import event
    here = os.getpid()

    class Compiles(event.Listener):
        def __init__(self):
            self.depth, self.timer, self.start, self.shown = 0, None, 0.0, False

        def on_start(self, ev):
            self.depth += 1
            if self.depth > 1 or _compiling[0] or os.getpid() != here:
                return
            f = ev.data["dispatcher"].py_func
            name = f"{f.__module__.removeprefix('survey.')}.{f.__qualname__}"
            self.start, self.shown = time.perf_counter(), False

            def show():
                self.shown = True
                _say(f"compiling {name} and what it calls (numba; the first time on this "
                     "machine only, cached after) ...", self)
            self.timer = threading.Timer(after, show)
            self.timer.daemon = True
            self.timer.start()

        def on_end(self, ev):
            self.depth -= 1
            if self.depth or self.timer is None:
                return
            self.timer.cancel()
            self.timer.join()
            self.timer = None
            if self.shown:
                _done(self, "compiling", time.perf_counter() - self.start)

    listener = Compiles()
    event.register("numba:compile", listener)
    _watching.append(listener)


@contextlib.contextmanager
def family_bar(what: str, enabled: bool):
    """A progress bar for a continuation on a terminal: the share of the parameter's span
    covered (it moves back where the family folds) and the members found so far. Yields
    the continuation's on_member callback (None when disabled)."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm
    with tqdm(total=100, desc=f"survey: {what}", file=sys.stderr, leave=True,
              bar_format="{desc}: {n:3.0f}% of the span |{bar}| [{elapsed}]") as bar:
        def on_member(count: int, share: float):
            bar.n = min(100.0, max(0.0, 100.0 * share))
            bar.set_description_str(f"survey: {what}, {count} members", refresh=True)
        yield on_member
