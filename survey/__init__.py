"""survey: order and chaos in Hamiltonian systems of particles interacting in triplets."""
import hashlib
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

try:
    __version__ = version("survey")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0+unknown"


def _refresh_kernel_cache():
    """numba's disk cache is keyed by each function's own source file, so a kernel that
    inlines code from another module (rhs inlines the forces of potentials.py), or freezes
    another module's constants (the status codes), would keep stale machine code after that
    module changes. Clear survey's cached kernels whenever the kernel modules' sources
    change."""
    here = Path(__file__).parent
    digest = hashlib.sha256(b"".join((here / f).read_bytes() for f in
                                     ("status.py", "potentials.py", "dynamics.py",
                                      "integrator.py")))
    cache = here / "__pycache__"
    stamp = cache / "kernels.sha256"
    try:
        if stamp.read_text() == digest.hexdigest():
            return
    except OSError:
        pass
    try:
        cache.mkdir(exist_ok=True)
        for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
            f.unlink(missing_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:   # a read-only install: numba then compiles in memory
        pass


_refresh_kernel_cache()
