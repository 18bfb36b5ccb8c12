"""What a user at a terminal sees while a phase without a progress bar runs: a line on
stderr once the phase has taken half a second (compiling the kernels the first time,
starting the workers, writing the archive), its time ticking every second, and how long it
took -- so that compiling never looks hung, and a fast phase prints nothing. `watch_compiles` does the same for any numba kernel not yet
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
# the phase whose line was printed last (None after a "done" line), and whether that line
# is still open (its time ticking at its end, no newline yet); one writer at a time
_last, _open = [None], [False]
_lock = threading.RLock()


def _say(text: str, phase, open_line: bool = False) -> None:
    """A line of ours on stderr (ending the open one first), or with `open_line` a line
    left open for its ticks."""
    with _lock:
        sys.stderr.write(("\n" if _open[0] else "") + f"survey: {text}" +
                         ("" if open_line else "\n"))
        sys.stderr.flush()
        _last[0], _open[0] = phase, open_line


def _took(seconds: float) -> str:
    return f"{seconds:.{0 if seconds >= 10 else 1}f} s"


class _Phase:
    """A phase on a terminal: nothing if it ends within `after` seconds; else its line,
    with the time since it began ticking at the end of the line every second (on a new
    line if another phase spoke meanwhile), and `done in X s` at its end."""

    def __init__(self, message: str, after: float):
        self.message, self.after = message, after
        self.start, self.shown = time.perf_counter(), False
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._speak, daemon=True)
        self.thread.start()

    def _speak(self):
        if self.stop.wait(self.after):
            return
        _say(f"{self.message} ...", self, open_line=True)
        self.shown = True
        while not self.stop.wait(1.0):
            text = f"{self.message} ... {time.perf_counter() - self.start:.0f} s"
            with _lock:
                if self.stop.is_set():
                    return
                if _last[0] is self and _open[0]:
                    sys.stderr.write(f"\rsurvey: {text}")
                    sys.stderr.flush()
                elif _last[0] is None or _last[0] is self:
                    _say(text, self, open_line=True)

    def end(self):
        self.stop.set()
        self.thread.join()          # a line being written is finished first
        if self.shown:
            took = _took(time.perf_counter() - self.start)
            _say(f"... done in {took}" if _last[0] is self else
                 f"... {self.message}: done in {took}", None)


@contextlib.contextmanager
def notice(message: str, enabled: bool = True, after: float = 0.5, compiling: bool = False):
    """Say `survey: message ...` on stderr if the block is still running after `after`
    seconds, its time every second after that, then `survey: ... done in X s` when it
    ends: no phase of a command is silent for long on a terminal. `compiling`: the block
    is the kernels' compilation, announced by this message (watch_compiles stays quiet)."""
    if not enabled:
        yield
        return
    if compiling:
        _compiling[0] += 1
    phase = _Phase(message, after)
    try:
        yield
    finally:
        phase.end()
        if compiling:
            _compiling[0] -= 1


_watching = []


def watch_compiles(after: float = 0.5) -> None:
    """From now on in this process, any numba compilation that takes longer than `after`
    seconds says so on stderr like a notice -- which kernel, that it happens once (numba
    caches it) -- and how long it took: the kernels a command compiles the first time it
    needs them (the report's solvers, the families' shooting), not only the integrator's.
    Quiet inside a notice(compiling=True), which has said it already, and in the processes
    forked from this one (the local workers: the driver speaks for them). Idempotent."""
    if _watching:
        return
    import os

    from numba.core import event
    here = os.getpid()

    class Compiles(event.Listener):
        def __init__(self):
            self.depth, self.phase = 0, None

        def on_start(self, ev):
            self.depth += 1
            if self.depth > 1 or _compiling[0] or os.getpid() != here:
                return
            f = ev.data["dispatcher"].py_func
            name = f"{f.__module__.removeprefix('survey.')}.{f.__qualname__}"
            self.phase = _Phase(f"compiling {name} and what it calls (numba; the first "
                                "time on this machine only, cached after)", after)

        def on_end(self, ev):
            self.depth -= 1
            if self.depth == 0 and self.phase is not None:
                self.phase.end()
                self.phase = None

    listener = Compiles()
    event.register("numba:compile", listener)
    _watching.append(listener)


@contextlib.contextmanager
def count_bar(what: str, enabled: bool, counted: str = "{n}/{total}"):
    """A progress bar on a terminal; yields update(done, total, note), the total given by
    the work as it starts (None when disabled). `counted`: how the bar shows its count."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm
    with tqdm(total=1, desc=f"survey: {what}", file=sys.stderr, leave=True,
              bar_format="{desc}: " + counted + " |{bar}| [{elapsed}]") as bar:
        def update(done, total, note: str):
            bar.total, bar.n = total, done
            bar.set_description_str(f"survey: {what}, {note}", refresh=True)
        yield update


@contextlib.contextmanager
def family_bar(what: str, enabled: bool):
    """count_bar for a continuation: the share of the parameter's span covered (it moves
    back where the family folds) and the members found so far. Yields the continuation's
    on_member callback (None when disabled)."""
    with count_bar(what, enabled, "{n:3.0f}% of the span") as update:
        yield None if update is None else lambda count, share: update(
            min(100.0, max(0.0, 100.0 * share)), 100, f"{count} members")
