"""Finished chunks on disk: written atomically as they arrive, under a key that hashes
everything that determines a cell's result (config tables, grid, code), checked before use
(readable, written under this key, its cells in the grid, its starts equal to this grid's;
one that is not is recomputed); and the lock that lets one survey at a time write an
output."""
from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from ..catalog.errors import SurveyError
from ..catalog.variables import V
from . import archive
from .config import Config


def checkpoint_dir(config: Config) -> Path:
    out = config.output
    return out.with_name(out.name + ".checkpoints") / config.result_key()


def save_chunk(folder: Path, key: str, cell_ids, result: dict):
    """Write one finished chunk atomically (temporary file, fsync, rename), with the key it
    was computed under, at chunk_path. The folder is made again if it was deleted
    meanwhile -- also while the file was being written (a user clearing old checkpoints,
    a race the test of that can hit: the deletion may take the temporary file before the
    folder, or the folder made again): then the write is tried again, up to 5 times."""
    name = chunk_path(folder, cell_ids)
    tmp = folder / f".{name.name}.{os.getpid()}.tmp"
    for attempt in range(1, 6):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with open(tmp, "wb") as fh:
                np.savez(fh, cell_ids=np.asarray(cell_ids, dtype=np.int64), result_key=key,
                         **result)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, name)
            return
        except OSError as exc:
            with contextlib.suppress(OSError):
                tmp.unlink()
            if attempt < 5 and exc.errno == errno.ENOENT:
                continue
            raise write_error(exc, name, folder) from None


def chunk_path(folder: Path, cell_ids) -> Path:
    return folder / f"chunk-{int(cell_ids[0]):012d}-{int(cell_ids[-1]):012d}-{len(cell_ids)}.npz"


def write_error(exc: OSError, path: Path, folder: Path) -> SurveyError:
    kept = f"finished cells are kept in {folder}" if folder.exists() else ""
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        try:
            free = shutil.disk_usage(path.parent if path.parent.exists() else folder).free
            room = f" ({free / 2**20:.1f} MiB free)"
        except OSError:
            room = ""
        return SurveyError(f"no space left on the device writing {path}{room}; free some "
                           f"space and run the same command again" + (f": {kept}" if kept else ""))
    return SurveyError(f"cannot write {path} ({exc.strerror or exc}); fix the folder and run "
                       "the same command again" + (f": {kept}" if kept else ""))


def scan_checkpoints(folder: Path, config: Config, starts, key: str) -> dict[Path, np.ndarray]:
    """The usable checkpoint files and their cells. A file that cannot be read, was written
    under another key, holds cells outside the grid or already held, lacks a variable or has
    one of the wrong shape, or whose starts differ from this grid's, is reported and
    deleted: its cells are computed again. starts: a function giving the starts of given
    cells (only a file's first and last cells are built: a resumed survey of millions
    of cells starts at once, and another grid's results differ there)."""
    slots = archive.layout(config)
    usable, seen = {}, set()
    for path in sorted(folder.glob("chunk-*.npz")):
        try:
            with np.load(path) as z:
                ids = z["cell_ids"]
                problem = _chunk_problem(z, ids, slots, seen, starts, key, config.n_cells)
        except Exception as exc:   # zipfile, pickle and numpy raise many kinds
            problem = f"unreadable ({type(exc).__name__}: {str(exc)[:80]})"
        if problem:
            warn(f"checkpoint {path} {problem}; its cells will be computed again")
            with contextlib.suppress(OSError):
                path.unlink()
            continue
        seen.update(ids.tolist())
        usable[path] = ids
    return usable


def _chunk_problem(z, ids, slots, seen, starts, key, cells) -> str:
    if str(z["result_key"]) != key:
        return "was written for another config or code version"
    if ids.dtype.kind != "i" or ids.ndim != 1 or not ids.size:
        return "has no valid cell list"
    if ids.min() < 0 or ids.max() >= cells or np.unique(ids).size != ids.size:
        return "names cells outside this grid"
    if not seen.isdisjoint(ids.tolist()):
        return "repeats cells another checkpoint holds"
    for s in slots:
        if s.name not in z.files:
            return f"lacks variable {s.name}"
        if z[s.name].shape != (ids.size,) + s.shape or z[s.name].dtype != np.dtype(s.dtype):
            return f"has variable {s.name} of the wrong shape or type"
    ends = [0, ids.size - 1]
    if z[V.initial_state][ends].tobytes() != starts(ids[ends]).tobytes():
        return "holds starts that differ from this grid's (another grid's results)"
    return ""


def warn(message: str):
    print(f"survey: {message}", file=sys.stderr)


@contextlib.contextmanager
def output_lock(output: Path):
    """Hold the output for this process alone: a second survey writing the same output
    refuses at once. The lock (an flock on .NAME.lock) dies with its process, so a killed
    survey never leaves a stale one; the file is removed on the way out."""
    path = output.with_name(f".{output.name}.lock")
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 32).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise SurveyError(f"another survey (process {holder}) is writing {output}; wait "
                              "for it to finish, or choose another [survey].output") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:      # not a file its previous holder unlinked while we waited to open it
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        _remove_stale_temporaries(output)
        yield
    finally:
        with contextlib.suppress(OSError):
            path.unlink()
        os.close(fd)


def _remove_stale_temporaries(output: Path):
    """Temporary files of runs that were killed while writing (we hold the lock, so no
    living survey owns them)."""
    stale = list(output.parent.glob(f".{output.name}.partial-*"))
    stale += list(output.with_name(output.name + ".checkpoints").glob("*/.chunk-*.tmp"))
    for f in stale:
        with contextlib.suppress(OSError):
            f.unlink()


class CheckpointVanished(Exception):
    """A checked checkpoint file was deleted before the archive read it (its path)."""


def loader(config: Config, files: dict[Path, np.ndarray], cells=None):
    """Reads variables over all cells (or over the sorted ids `cells` of a refined survey:
    a checkpoint's other cells are left out) from the checked checkpoint files, opening
    each file once per call."""
    specs = {v.name: v for v in archive.variables(config)}
    count = config.n_cells if cells is None else len(cells)

    def load(names):
        out = {name: np.full((count,) + archive.cell_shape(config, specs[name]),
                             specs[name].fill, specs[name].dtype) for name in names}
        for path, ids in files.items():
            if cells is None:
                keep, rows = slice(None), ids
            else:
                rows = np.searchsorted(cells, ids)
                keep = (rows < len(cells)) & (cells[np.minimum(rows, len(cells) - 1)] == ids)
                rows = rows[keep]
            try:
                z = np.load(path)
            except FileNotFoundError:
                raise CheckpointVanished(path) from None
            with z:
                for name in names:
                    out[name][rows] = z[name][keep]
        return out
    return load
