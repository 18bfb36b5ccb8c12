"""How survey compiles: the two numba decorators every kernel uses, and the invalidation of
numba's disk cache when kernel sources change.

numba's disk cache is keyed by each function's own source file, so a kernel that inlines
code from another module (rhs inlines the forces of forces.py, the driver inlines rhs), or
freezes another module's constants (the status codes), would keep stale machine code after
that module changes.

What this module changes beyond itself happens in one call, `start`, made once as it is
imported (every compiled module imports it first): the cached kernels cleared if their
sources changed, numba's saves to its cache locked against other processes', and LLVM told
the machine's real vector width (process-wide).
"""
from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

from llvmlite import binding as llvm
from numba import njit
from numba.core import compiler, config, cpu, options
from numba.core.registry import cpu_target

PACKAGE = Path(__file__).parents[1]
# the modules whose source compiled code depends on, and the folders that hold kernels
SOURCES = ("catalog/status.py", "machine/*.py", "physics/*.py", "numerics/*.py", "bench/*.py")
KERNEL_FOLDERS = ("bench", "machine", "physics", "numerics")


def cache_folder(source_folder: Path) -> Path:
    """Where numba caches the kernels of a source folder, as its cache locators choose in
    turn: with NUMBA_CACHE_DIR set, <that>/<folder name>_<sha1 of its absolute path>; else
    its __pycache__ where that can be written; else (a read-only install) the same
    subfolder of numba's cache folder in the user's home."""
    path = os.path.abspath(source_folder)
    subfolder = f"{os.path.basename(path)}_{hashlib.sha1(path.encode()).hexdigest()}"
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        return Path(root) / subfolder
    in_tree = source_folder / "__pycache__"
    if _writable(in_tree):
        return in_tree
    from numba.misc.appdirs import AppDirs
    return Path(AppDirs(appname="numba", appauthor=False).user_cache_dir) / subfolder


def _writable(folder: Path) -> bool:
    """Whether a folder can be written, or made and written where it does not exist."""
    while not folder.exists():
        folder = folder.parent
    return os.access(folder, os.W_OK)


def refresh_kernel_cache(package: Path = PACKAGE):
    """Delete the cached kernels when the hash of the kernel sources differs from the one
    recorded beside them (then record it)."""
    files = sorted(f for pattern in SOURCES for f in package.glob(pattern))
    digest = hashlib.sha256(b"".join(f.read_bytes() for f in files)).hexdigest()
    stamp = cache_folder(package) / "kernels.sha256"
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        for folder in KERNEL_FOLDERS:
            for f in cache_folder(package / folder).glob("*.nb[ic]"):
                f.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest)
    except OSError:   # a read-only install: numba then compiles in memory
        pass


def kernels_cached(package: Path = PACKAGE) -> bool:
    """Whether numba's disk cache holds survey's kernels (else the first survey compiles
    them, half a minute to a minute on 2 cores)."""
    return any(cache_folder(package / "numerics").glob("driver._run-*.nbi"))



# The AVX-512 cores known to run a 512-bit operation in full (Zen 5's server parts); Zen 4
# runs it as two 256-bit halves, and LLVM's own tuning keeps Intel's cores at 256 bits.
FULL_512 = ("znver5",)


def vector_width():
    """Have LLVM vectorise for the machine's real vector width, and return it in doubles (4
    or 8): the fewest lanes whose loops run as SIMD instructions (physics.lanes.SIMD_MIN).

    With 512 bits the loop vectoriser puts 8 doubles in a vector, so a loop over SIMD lanes
    runs as SIMD only from 8 lanes and entirely scalar at 4. On AVX-512 cores other than
    FULL_512 (Zen 4, which splits a 512-bit operation; Intel's, where LLVM's tuning does it
    by itself) LLVM is told to prefer 256 bits: there the narrower vectors are faster at 4
    and 8 lanes and no slower at 16; on Zen 5 the full width pays from 8 lanes on (`bench
    --only step` measures both on the machine it runs on). Which instructions run changes,
    never the arithmetic (IEEE operations lane by lane): the same bits.

    numba reads the target's features once, when it makes its code generator (at the first
    function decorated), so this must run before that and makes it at once (numba reloads
    its configuration from the environment when that changes, which would drop the
    setting). It holds for the whole process, so other code numba compiles here after
    survey's import is vectorised this way too; a NUMBA_CPU_NAME or NUMBA_CPU_FEATURES set
    by the user wins."""
    if config.CPU_NAME is not None or config.CPU_FEATURES is not None:
        return 8 if config.CPU_NAME in FULL_512 else 4
    name, features = llvm.get_host_cpu_name(), llvm.get_host_cpu_features()
    if not features.get("avx512f"):
        return 4
    if name in FULL_512:
        return 8
    config.CPU_FEATURES = features.flatten() + ",+prefer-256-bit"
    cpu_target.target_context.codegen()
    return 4


def lock_cache_saves():
    """numba saves a kernel to its disk cache by reading its function's index, adding the
    entry and writing both back. Two processes saving different specialisations of one
    function at once can both number their machine code 1, and the index then names the
    other's: a kernel of the wrong types. A first run's processes compile at once
    (pipeline.sweep), as do two surveys started together on a new machine. Each save
    (and each read of an index and its entry) holds a lock on a file of the cache folder
    (fcntl's, which the system releases if a process dies holding it). Not on POSIX, or
    where the folder cannot be written: unlocked, as numba itself."""
    try:
        import fcntl
    except ImportError:
        return
    from numba.core.caching import IndexDataCacheFile
    if getattr(IndexDataCacheFile.save, "locked", False):
        return

    def locked(method, mode):
        @functools.wraps(method)
        def run(self, *args):
            try:
                lock = open(os.path.join(self._cache_path, "survey.lock"), "a")
            except OSError:
                return method(self, *args)
            with lock:
                fcntl.flock(lock, mode)
                return method(self, *args)
        run.locked = True
        return run
    IndexDataCacheFile.save = locked(IndexDataCacheFile.save, fcntl.LOCK_EX)
    IndexDataCacheFile.load = locked(IndexDataCacheFile.load, fcntl.LOCK_SH)


def combine_aggregates_first():
    """Run LLVM's instruction combiner on each function before numba's function passes.

    numba keeps each variable in its own stack slot, stores the whole value there and
    loads the whole value at each use. For a record of arrays such as the driver's lanes
    (about 450 pointers and integers) that means one whole load for each `ln.h[k]`, and
    one whole copy for each inlined helper that is given the record. The pipeline's first
    scalar-replacement pass (SROA) then splits every such load into one load per field and
    rebuilds the record from them, field by field: the stepping loop's 4.8 MB of IR grew
    to 330 MB before the next pass removed it again. SROA took 2.4 s of its 3.5 s of
    function passes, and correlated-value propagation most of the rest. The combiner
    first turns a field read from a whole load into a load of that field alone. The
    stepping loop's function passes then take 1.5 s. The passes that follow produce the
    same program and IEEE operations, so the results keep every bit (`verify`). A numba
    without this hook, or on llvmlite's legacy pass manager (numba < 0.61), compiles as
    it would by itself: slower, the same code."""
    from numba.core.codegen import CPUCodeLibrary
    original = getattr(CPUCodeLibrary, "_optimize_functions", None)
    if original is None or getattr(original, "combined_first", False) or \
            not hasattr(llvm, "create_new_function_pass_manager"):
        return

    @functools.wraps(original)
    def optimize_functions(self, ll_module):
        try:
            ll_module.data_layout = self._codegen._data_layout
            builder = self._codegen._pass_builder()
            combine = llvm.create_new_function_pass_manager()
            combine.add_instruction_combine_pass()
            for function in ll_module.functions:
                if not function.is_declaration:
                    combine.run(function, builder)
        except (AttributeError, TypeError, ValueError):
            pass            # another numba's codegen: its own passes alone
        original(self, ll_module)
    optimize_functions.combined_first = True
    CPUCodeLibrary._optimize_functions = optimize_functions


def faster_flags():
    """Compare numba's compiler flags without building their dictionaries.

    numba keys each @overload's implementations by the compiler flags in force, and each
    lookup while typing a call hashes them and compares them: both built a dictionary of
    every option through its property (about 50), 9% of a first integration's compiling
    in a sampled profile (py-spy). The hash was that of the sorted option names, the same
    for every flags of a class, so it is kept per class; equal set values make equal
    flags at once, else the full comparison runs. The same answers (tests/machine)."""
    from numba.core.targetconfig import TargetConfig
    if getattr(TargetConfig.__eq__, "fast", False) or not hasattr(TargetConfig, "options"):
        return
    original_eq, defaults, hashes = TargetConfig.__eq__, {}, {}

    def values(self):
        cls = type(self)
        got = defaults.get(cls)
        if got is None:
            got = defaults[cls] = {k: option.default for k, option in cls.options.items()}
        got = dict(got)
        got.update(self._values)
        return got

    def __hash__(self):
        cls = type(self)
        got = hashes.get(cls)
        if got is None:
            got = hashes[cls] = hash(tuple(sorted(cls.options)))
        return got

    def __eq__(self, other):
        if type(self) is type(other) and self._values == other._values:
            return True
        return original_eq(self, other)
    __eq__.fast = True
    TargetConfig.values, TargetConfig.__hash__, TargetConfig.__eq__ = values, __hash__, __eq__


def inline_once():
    """Build each inlined helper's IR once a process, not once per call site.

    numba inlines a function declared inline="always" (jit.helper) by running its
    frontend (bytecode, untyped passes, its own helpers inlined) at every call site, then
    copying the result into the caller: the driver's stepping loop and its kernels inline
    helpers at hundreds of sites. The frontend's result depends on the function and on the
    caller's compiler settings alone (a copy is what gets changed), so it is kept per
    function, pipeline, locals and flags. The programs are the same; their variables are
    numbered differently."""
    from numba.core.inline_closurecall import InlineWorker
    original = getattr(InlineWorker, "inline_function", None)
    if original is None or getattr(original, "once", False) or \
            not hasattr(InlineWorker, "run_untyped_passes"):
        return
    built = {}

    @functools.wraps(original)
    def inline_function(self, caller_ir, block, i, function, arg_typs=None):
        self.flags.enable_ssa = False           # as run_untyped_passes sets them first
        key = (function, type(self.pipeline), tuple(sorted(self.locals.items())),
               type(self.flags)(self.flags))
        callee_ir = built.get(key)
        if callee_ir is None:
            callee_ir = built[key] = self.run_untyped_passes(function)
        return self.inline_ir(caller_ir, block, i, callee_ir, function.__code__.co_freevars,
                              arg_typs=arg_typs)
    inline_function.once = True
    InlineWorker.inline_function = inline_function


def start() -> int:
    """Everything survey changes outside itself before it compiles, in one place: numba's
    disk cache brought in step with the kernel sources (refresh_kernel_cache), its saves
    locked against each other (lock_cache_saves), each function's aggregates combined
    before its passes (combine_aggregates_first), numba's flags compared and helpers'
    IR built once (faster_flags, inline_once), and LLVM's vector width set for the
    machine (vector_width, which holds for the process). Returns the vector width in
    doubles."""
    refresh_kernel_cache()
    lock_cache_saves()
    combine_aggregates_first()
    faster_flags()
    inline_once()
    return vector_width()


VECTOR_DOUBLES = start()

# Every compiled function: cached on disk, and IEEE arithmetic (inf/nan, never a Python
# exception such as ZeroDivisionError from inside a kernel; the integrator turns
# non-finite values into a status).
kernel = njit(cache=True, error_model="numpy")
# A kernel that creates no array runs without numba's reference counting (NRT): the
# incref/decref calls numba places around every array a function passes on or slices (43
# in the right-hand side of three bodies, 58 once a branch keeps numba's pruning pass from
# removing them) cost more than the arithmetic -- 2x on the right-hand side, measured.
# (`_nrt` is numba's own switch for it, used by its test suite.)
leaf = njit(cache=True, error_model="numpy", _nrt=False)
# The loops over SIMD lanes read some arrays and write others. Unless the compiler knows
# that these do not overlap, it checks at run time, and a loop with many streams (the
# tangent forces: 6 written, 16 read, 36 checks) is vectorised only from 24 lanes, where
# the checks cost under a tenth of the loop: with 16 lanes the tangent ran scalar, at about
# four times the cost of its SIMD loop. numba's `noalias` flag (which its parallel backend sets once it
# has proven a gufunc's arguments distinct) declares the arrays a function is given
# disjoint; it is not a decorator option, so it is mapped to one here (a numba without
# the flag compiles them as leaves: slower, the same bits). Only for functions whose
# arguments are distinct arrays (or disjoint rows of one) at every call.
if hasattr(compiler.Flags, "noalias"):
    if not hasattr(cpu.CPUTargetOptions, "noalias"):
        cpu.CPUTargetOptions.noalias = options.TargetOptions.Mapping("noalias")
    lanes = njit(cache=True, error_model="numpy", _nrt=False, noalias=True)
else:
    lanes = leaf
# small helpers are inlined at numba-IR level: calls between separately compiled functions
# otherwise cost more than the arithmetic (3x on the right-hand side). Large bodies called
# once per triplet or evaluation stay `leaf`s: inlining them buys nothing measurable and
# the compile time grows faster than the code (cold start, python -m survey run). So do
# the driver's once-a-job and output-time code (a job's start, samples): inlined into the
# stepping loop they cost a first run 14 s of compiling and no step measurably less.
helper = njit(cache=True, error_model="numpy", inline="always")
