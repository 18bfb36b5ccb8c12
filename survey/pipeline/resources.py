"""What a survey needs from the machine, checked before any work: memory for its grid, a
writable output path the file system can hold, a well-formed scheduler address."""
from __future__ import annotations

import os
from pathlib import Path

from ..catalog import defaults
from ..catalog.errors import ConfigError
from ..catalog.variables import horizon_factors

# the archive is written a group of variables at a time, each group at most this large
# in memory: one pass over the checkpoint files per group, not per variable
GROUP_BYTES = 256 * 2 ** 20


def check_address(address: str):
    """A dask scheduler address, checked for form (the connection is tried later, bounded by
    connect_timeout)."""
    from distributed.comm.addressing import parse_address, parse_host_port
    fix = "write it like tcp://host:8786 (the scheduler's port, not the dashboard's 8787)"
    try:
        scheme, location = parse_address(address, strict=True)
        if scheme not in ("tcp", "tls", "ws", "wss", "ucx"):
            raise ValueError(f"unknown scheme {scheme!r}")
        host, port = parse_host_port(location)
        if not host or not 0 < int(port) < 65536:
            raise ValueError("no host or a port outside 1..65535")
    except (ValueError, TypeError) as exc:
        raise ConfigError("[dask].scheduler", f"{address!r} is not a scheduler address "
                                              f"({exc}); {fix}") from None


def memory_needed(n_cells, n, deviations, crossings, store_state, history, chunk,
                  workers, samples=0) -> int:
    """Bytes a survey holds at its peak: the driver keeps every cell's start and, writing
    the archive, a group of variables over all cells (GROUP_BYTES, or one variable if
    larger); each worker a chunk of result rows and one integration's buffers (stages,
    crossing states, history samples of the orbit and its tangents, the orbit samples of
    the torus analysis)."""
    full = n * (1 + deviations) + 2
    row = n + 40 + 4 * history + crossings * (7 + (n if store_state else 0))
    integration = 27 * full + crossings * (n + 2) + history * (full + deviations) + \
        samples * (n + 8)
    starts = n_cells * (n + 1)
    variable = n_cells * max(n, history, crossings * (n if store_state else 1))
    return 8 * (starts + workers * (chunk * row + integration)) + max(GROUP_BYTES, 8 * variable)


def check_memory(settings, n_cells: int):
    """Refuse, before anything is allocated, a survey that cannot fit in this machine's
    memory, naming the setting whose reduction would help most (settings: a validated
    config's records.Settings)."""
    s, sec, ind, dsk = settings.system, settings.section, settings.indicators, settings.dask
    tori, t_final = settings.tori, settings.integration.t_final
    # an extended cell runs to the longest horizon, and the histories span it
    longest = int(horizon_factors(tori.extend, tori.extend_rounds)[-1])
    size = dict(n_cells=n_cells, n=2 * s.bodies * s.dim, deviations=ind.deviations,
                crossings=sec.max_crossings if settings.section_enabled else 0,
                store_state=sec.store_state, history=ind.history_points * longest,
                chunk=dsk.chunk_size or 256, workers=dsk.workers,
                samples=int(longest * t_final / tori.sample_interval) if tori.analyse else 0)
    total = memory_needed(**size)
    if total <= 0.8 * machine_memory():
        return
    smaller = {"[initial] (the grid)": dict(n_cells=1),
               "[integration].t_final": dict(samples=size["samples"] * min(
                   1.0, defaults.T_FINAL / t_final), history=ind.history_points * longest),
               "[system].bodies": dict(n=6),
               "[section].max_crossings": dict(crossings=1),
               "[indicators].history_points": dict(history=2),
               "[tori].extend": dict(history=ind.history_points,
                                     samples=size["samples"] // longest),
               "[indicators].deviations": dict(deviations=1),
               "[tori].sample_interval": dict(samples=0),
               "[dask].chunk_size": dict(chunk=1), "[dask].workers": dict(workers=1)}
    # the first setting (in this order) whose reduction alone makes it fit, else the one
    # that helps most
    key = next((k for k in smaller if memory_needed(**{**size, **smaller[k]})
                <= 0.8 * machine_memory()),
               min(smaller, key=lambda k: memory_needed(**{**size, **smaller[k]})))
    what = f"{n_cells:,} cells" if key.startswith("[initial]") else "this survey"
    check_bytes(total, key.split()[0], what, f"reduce {key}, or split the survey")


def machine_memory() -> int:
    import psutil
    return psutil.virtual_memory().total


def check_bytes(total: float, key: str, what: str, fix: str):
    """The one memory check of every command: ConfigError naming `key` where `what` would
    need more than 80% of this machine's memory, before anything is allocated."""
    machine = machine_memory()
    if total > 0.8 * machine:
        raise ConfigError(key, f"{what} would need about {_bytes(total)} of memory, more "
                               f"than this machine's {_bytes(machine)}: {fix}")


def _bytes(x: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if x < 1024 or unit == "PiB":
            return f"{x:.3g} {unit}"
        x /= 1024


def ensure_writable(path: Path, key: str = "[survey].output", inputs=()):
    """Refuse an output the survey could not write, or should not: one of the run's
    `inputs` (the config it reads), names the file system cannot hold (with the temporary,
    lock and checkpoint names derived from them), a folder, a device, pipe or socket, a
    symbolic link (the archive is renamed into place, which would replace the link, not
    write through it), an unwritable folder. `key` names the setting in the message."""
    path = Path(path)
    for source in inputs:
        if same_file(path, source):
            raise ConfigError(key, f"{path} is this run's input {source}: writing the "
                                   "output there would replace it; give another file")
    if "\0" in str(path):
        raise ConfigError(key, "contains a NUL character")
    if path.name in ("", ".", ".."):
        raise ConfigError(key, f"{str(path)!r} names no file; give a file name like "
                               "results/map.nc")
    folder = path.parent if str(path.parent) else Path(".")
    here = folder.absolute()
    existing = next(p for p in (here, *here.parents) if _exists(p))
    try:
        name_max = os.pathconf(existing, "PC_NAME_MAX")
        path_max = os.pathconf(existing, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    longest = max(len(os.fsencode(part)) for part in path.parts)
    derived = len(os.fsencode(path.name)) + NAME_EXTRA
    if max(longest, derived) > name_max:
        raise ConfigError(key, f"a name in it is too long for the file system ({name_max} "
                               f"bytes, and survey adds up to {NAME_EXTRA} to the file "
                               "name); shorten it")
    if len(os.fsencode(os.path.abspath(path))) + CHECKPOINT_PATH_EXTRA > path_max:
        raise ConfigError(key, f"the path is too long for the file system ({path_max} bytes "
                               "with the checkpoint names survey adds); shorten it")
    if path.is_symlink():
        raise ConfigError(key, f"{path} is a symbolic link; give the path of the file itself")
    if path.exists() and not path.is_file():
        kind = "a folder; give a file name" if path.is_dir() else \
            "not a regular file (a device, pipe or socket); give a file path"
        raise ConfigError(key, f"{path} is {kind}")
    ensure_folder(folder, key)


def same_file(a, b) -> bool:
    """Whether two paths name the same file (the same inode where both exist; else the
    same absolute path, links resolved)."""
    try:
        if Path(a).exists() and Path(b).exists():
            return os.path.samefile(a, b)
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, ValueError):
        return False


def ensure_folder(path, key: str) -> Path:
    """A folder to write figures or reports into, made if missing; ConfigError naming
    `key` where it is a file or cannot be made or written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(key, f"{path} is a file; give a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".survey-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(key, f"cannot write to {path} ({exc.strerror or exc}); choose a "
                               "writable folder") from None
    return path


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError:       # a name too long to even look up
        return False


# what survey adds to an output's name and path: the archive's temporary file is
# .NAME.partial-PID (PIDs have up to 7 digits; archive.partial_path), a checkpoint is
# NAME.checkpoints/KEY/.chunk-FIRST-LAST-COUNT.npz.PID.tmp (checkpoints.save_chunk)
NAME_EXTRA = 17


CHECKPOINT_PATH_EXTRA = 120
