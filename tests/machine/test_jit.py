"""How survey compiles (machine.jit): numba's disk cache shared by processes that compile
at once, the function passes' aggregates combined first, numba's flags compared without
their dictionaries and each inlined helper's IR built once."""
import collections
import multiprocessing

import numpy as np
from numba import njit
from numba.core.caching import IndexDataCacheFile
from numba.core.codegen import CPUCodeLibrary
from numba.core.compiler import Flags
from numba.core.inline_closurecall import InlineWorker

from survey.machine import jit  # (locks the cache's saves, as any kernel's import)

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


Record = collections.namedtuple("Record", [f"a{i}" for i in range(60)])


@njit(error_model="numpy", _nrt=False)
def _shuffle(record, rounds):
    """Reads and writes fields of a record of 60 arrays in a loop, as the driver does its
    lanes (each `record.aK[i]` a whole load of the record in numba's IR)."""
    for r in range(rounds):
        for i in range(len(record) - 1):
            record[i + 1][r % 3] += 0.5 * record[i][(r + 1) % 3] - r
    return record[len(record) - 1][0]


def test_records_of_many_arrays_compile_through_the_combined_passes():
    """jit.combine_aggregates_first runs LLVM's instruction combiner before numba's function
    passes: installed once, and a kernel over a record of 60 arrays computes exactly what
    plain Python computes."""
    assert CPUCodeLibrary._optimize_functions.combined_first
    jit.combine_aggregates_first()          # a second call must not wrap it twice
    assert CPUCodeLibrary._optimize_functions.__wrapped__.__name__ == "_optimize_functions"
    rng = np.random.default_rng(3)
    start = [rng.standard_normal(3) for _ in range(60)]
    compiled, plain = Record(*[a.copy() for a in start]), Record(*[a.copy() for a in start])
    got = _shuffle(compiled, 7)
    want = _shuffle.py_func(plain, 7)
    assert got == want
    for a, b in zip(compiled, plain):
        np.testing.assert_array_equal(a, b)


def _flags(**set_):
    flags = Flags()
    for name, value in set_.items():
        setattr(flags, name, value)
    return flags


def test_flags_compare_and_hash_as_their_options_do():
    """jit.faster_flags: each flags' values, hash and equality are those of every option
    read through its property (numba's own definition), set or left at the default."""
    cases = [_flags(), _flags(), _flags(nrt=True), _flags(nrt=False),
             _flags(error_model="numpy"), _flags(error_model="python"),
             _flags(nrt=True, error_model="numpy", boundscheck=False),
             Flags(_flags(nrt=True, error_model="numpy"))]
    default = Flags.options["error_model"].default
    cases.append(_flags(error_model=default))     # set to the default: equals unset
    for a in cases:
        want = {name: getattr(a, name) for name in a.options}
        assert a.values() == want
        assert hash(a) == hash(tuple(sorted(want)))
        for b in cases:
            assert (a == b) == (want == {name: getattr(b, name) for name in b.options})
    assert cases[-1] == cases[0] and cases[2] != cases[3]
    jit.faster_flags()                             # a second call changes nothing
    assert Flags.__eq__.fast


@njit(inline="always")
def _twice(x):
    return 2.0 * x + 1.0


@njit(inline="always")
def _nested(x):
    return _twice(x) - _twice(-x)


@njit
def _three_sites(x):
    return _nested(x) + _nested(x + 1.0) * _nested(x - 1.0) + _twice(x)


def test_inlined_helpers_are_built_once_and_compute_as_python():
    """jit.inline_once: a helper inlined at three sites of a kernel (and inlining another at
    two sites of its own) runs numba's frontend once, and the kernel computes what plain
    Python computes."""
    built = collections.Counter()
    original = InlineWorker.run_untyped_passes

    def counted(self, func, *args, **kwargs):
        built[func.__name__] += 1
        return original(self, func, *args, **kwargs)
    InlineWorker.run_untyped_passes = counted
    try:
        got = _three_sites(0.75)
    finally:
        InlineWorker.run_untyped_passes = original
    assert got == 3.0 + 7.0 * -1.0 + 2.5           # 4x + 4(x + 1) 4(x - 1) + 2x + 1, exact
    assert built["_nested"] == 1 and built["_twice"] == 1
    assert InlineWorker.inline_function.once
