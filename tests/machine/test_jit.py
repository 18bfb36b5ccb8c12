"""numba's disk cache shared by processes that compile at once (machine.jit)."""
import multiprocessing

from numba.core.caching import IndexDataCacheFile

import survey.machine.jit  # noqa: F401  (locks the cache's saves, as any kernel's import)

KEYS = 300


def _save_many(folder, first, go):
    cache = IndexDataCacheFile(folder, "kernel", "stamp")
    go.wait()
    for key in range(first, first + KEYS):
        cache.save(key, f"machine code of {key}")


def test_processes_saving_one_functions_kernels_at_once_keep_every_entry(tmp_path):
    """numba numbers a new kernel's file from the index it reads: unlocked, two processes
    saving at once write files of one number and indexes that drop or misname the other's
    entries (unlocked, this test failed in each of 5 runs)."""
    ctx = multiprocessing.get_context("spawn")
    go = ctx.Event()
    workers = [ctx.Process(target=_save_many, args=(str(tmp_path), first, go))
               for first in (0, KEYS)]
    for w in workers:
        w.start()
    go.set()
    for w in workers:
        w.join(60)
        assert w.exitcode == 0
    cache = IndexDataCacheFile(str(tmp_path), "kernel", "stamp")
    assert [cache.load(key) for key in range(2 * KEYS)] == \
        [f"machine code of {key}" for key in range(2 * KEYS)]
