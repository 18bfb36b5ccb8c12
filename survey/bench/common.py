"""What every part of the bench shares: the cases it times, best-of timing, and a command
run as a user runs it, with its phases."""
from __future__ import annotations

import math
import time
from typing import NamedTuple

CASES = [("chaotic 'sides'", "sides", {}),
         ("regular equilateral d=3", "equilateral", {"delta": 3.0})]


def best_time(fn, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


# The command line run as `python -m survey` runs it, its phases recorded: wall-clock times
# (comparable across processes) at its first line, after its imports, and at its end, with
# run_survey's own timings; printed as JSON on the last line.
_CLI_PHASES = """
import json, sys, time
start = time.time()
from survey import cli
from survey.pipeline import sweep
imported = time.time()
timings, run = {}, sweep.run_survey
sweep.run_survey = lambda *a, **kw: run(*a, timings=timings, **kw)
code = cli.main(sys.argv[1:])
timings.pop("tasks", None)
print(json.dumps(dict(start=start, imported=imported, end=time.time(), code=code, **timings)))
"""


def user_env(**extra) -> dict:
    """The environment of a timed command: this one, but Python writing bytecode as it does
    by default (a development environment may set PYTHONDONTWRITEBYTECODE; survey's own
    modules, compiled from source on every start, then cost a command 0.05-0.1 s)."""
    import os
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, **extra}


def checked(args, env=None) -> str:
    """Run a command to its end; its stdout. One that fails raises with its exit code and
    the end of its stderr -- what a CI log must show to say why (a bare
    CalledProcessError names the command only)."""
    import subprocess
    done = subprocess.run(args, capture_output=True, text=True, env=env or user_env())
    if done.returncode:
        tail = "\n".join(done.stderr.splitlines()[-40:])
        raise RuntimeError(f"{' '.join(map(str, args))} exited with {done.returncode}; "
                           f"its stderr ended with:\n{tail}")
    return done.stdout


def command_phases(argv) -> dict:
    """Seconds of a `python -m survey` command by phase: the interpreter's start, survey's
    imports, run_survey's phases (prepare -- the kernels loaded --, cluster, compute,
    shutdown, archive), and the rest (the regime summary; the exit without teardown is not
    run here)."""
    import json
    import sys
    launched = time.time()
    r = json.loads(checked([sys.executable, "-c", _CLI_PHASES, *argv]).strip().splitlines()[-1])
    phases = {"interpreter": r["start"] - launched, "imports": r["imported"] - r["start"]}
    phases.update({k: r[k] for k in ("prepare", "cluster", "compute", "shutdown", "archive")})
    phases["rest"] = r["end"] - r["imported"] - r["total"]
    return phases


class Timed(NamedTuple):
    """A command run on a terminal: seconds to its first word, to its end, and the longest
    it said nothing (from the start, between words, or before the end)."""

    first: float
    total: float
    silence: float


def timed_command(args, env=None, cwd=None) -> Timed:
    """A command run with a terminal (120 columns, as a user's) for its stdout and stderr
    -- the command line speaks to terminals only -- timed word by word: when it first
    writes, when it ends, and its longest silence. A command that fails raises."""
    import fcntl
    import os
    import pty
    import struct
    import subprocess
    import termios
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    start = time.perf_counter()
    proc = subprocess.Popen(args, stdout=slave, stderr=slave, env=env, cwd=cwd)
    os.close(slave)
    first, last, silence, said = math.nan, 0.0, 0.0, bytearray()
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:         # the command closed its end
            break
        if not chunk:
            break
        said += chunk
        now = time.perf_counter() - start
        silence, last = max(silence, now - last), now
        if math.isnan(first):
            first = now
    proc.wait()
    total = time.perf_counter() - start
    os.close(master)
    if proc.returncode:
        tail = "\n".join(said.decode(errors="replace").splitlines()[-40:])
        raise RuntimeError(f"{' '.join(map(str, args))} exited with {proc.returncode}; "
                           f"it ended with:\n{tail}")
    return Timed(first, total, max(silence, total - last))
