"""The other machine of the portability tests (tests/pipeline/test_portable_archives.py),
made on this one by switching the code paths a CPU selects, and the run there that they
compare with. It starts in the background as soon as the session has collected a test that
needs it (marked `foreign`; conftest.py runs their modules last): compiling survey's
kernels cold for the generic target takes ~4 minutes of one core, which the test suite --
one process, the second core mostly idle -- waited for in that test alone (230 of its
712 s)."""
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

WORKFLOWS = Path(__file__).parents[1] / "workflows"

FOREIGN = {"NUMBA_CPU_NAME": "generic", "NUMBA_CPU_FEATURES": "+fma",
           "NPY_DISABLE_CPU_FEATURES": "X86_V3,X86_V4,AVX512_ICL,AVX512_SPR",
           "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F",
           "OPENBLAS_CORETYPE": "Prescott"}

# starts whose every bit a chaotic orbit amplifies: the LJAT trimer and 2-D LJ7 from their
# equilibria (seeded velocities, a displacement), a 3-D microcanonical start carrying
# angular momentum, unequal masses; and the reduced coordinates of random states
STARTS = """
import sys
import numpy as np
from survey.physics.families import initial_state
from survey.physics.jacobi import reduced
from survey.physics.system import System
from survey.physics.terms import make_potential
LJ = make_potential("lennard_jones", {}, "pair")
ATM = make_potential("axilrod_teller", dict(strength=0.2))
hexagon = [[0.0, 0.0], [1.12, 0.0], [0.56, 0.97], [-0.56, 0.97], [-1.12, 0.0],
           [-0.56, -0.97], [0.56, -0.97]]
ring = [[1.15, 0.0, 0.02], [0.36, 1.09, 0.0], [-0.93, 0.68, -0.03], [-0.93, -0.68, 0.0],
        [0.36, -1.09, 0.01]]
trimer = System(np.ones(3), 2, (LJ, ATM))
out = dict(
    trimer=initial_state(trimer, "equilibrium", positions=[[0, 0], [1.12, 0], [0.56, 0.97]],
                         displacement=0.01, seed=3, energy=-2.5),
    lj7=initial_state(System(np.ones(7), 2, (LJ, ATM)), "equilibrium", positions=hexagon,
                      seed=1, energy=-11.9),
    micro=initial_state(System(np.linspace(0.7, 1.6, 5), 3, (LJ, ATM)), "microcanonical",
                        positions=ring, energy=-1.0, angular_momentum=0.3, seed=4),
    sides=initial_state(System(np.array([1.0, 0.3, 0.07]), 2, (ATM,)), "sides"),
    reduced=np.array(reduced(System(np.array([1.0, 0.3, 0.07])),
                             np.random.default_rng(5).normal(size=(200, 12)))))
# a formula (its program's exp through the portable functions): a start on the Toda
# section and a stretch of its orbit with a tangent vector, in SIMD lanes
from survey.numerics.integrate import integrate_batch
from survey.physics.terms import make_expression
toda = System(np.ones(1), 2, (make_expression("external", "(exp(2*y + 2*sqrt(3)*x) + "
                                              "exp(2*y - 2*sqrt(3)*x) + exp(-4*y))/24 - 1/8"),))
starts = np.array([initial_state(toda, "field_section_sample", energy=1.0, seed=s)
                   for s in range(16)])
ends = integrate_batch(toda, starts, 20.0, tangents=np.tile(np.eye(4)[:1], (16, 1, 1)),
                       megno=True, lanes=16)
out["toda"] = np.concatenate([starts.ravel()] + [np.concatenate([e.y, e.megno_sums,
                                                                 e.log_growth])
                                                 for e in ends])
# families: a Lyapunov family from a relative equilibrium's normal mode (rotating, in the
# energy), the figure-eight in a mass with its bifurcations bisected, and a family of
# relative equilibria with its Routh bifurcation
from survey.pipeline.families import solve_equilibria, solve_periodic
for name in ("rotating_triangle_breathing", "figure_eight_mass_family"):
    family = solve_periodic(f"{sys.argv[2]}/{name}.toml")[2]
    out[name] = np.concatenate([family.parameters, [b.parameter for b in family.bifurcations]]
                               + [np.concatenate([o.state, [o.period, o.rotation],
                                                  o.multipliers.real, o.multipliers.imag,
                                                  o.motion])
                                  for o in family.members])
routh = solve_equilibria(f"{sys.argv[2]}/lagrange_routh_family.toml")[2]
members, found = routh.members, routh.bifurcations
out["routh"] = np.concatenate([[b.parameter for b in found]] + [
    np.concatenate([[p], e.positions.ravel(), e.eigenvalues.real, e.eigenvalues.imag])
    for p, e in members])
np.savez(sys.argv[1], **out)
"""


class ForeignRun:
    """STARTS under FOREIGN at a low priority, in a folder of its own: numba's cache of the
    foreign kernels (`cache`, which the archive test then reuses), the starts (`result`)
    and the run's stderr."""

    def __init__(self):
        self.folder = Path(tempfile.mkdtemp(prefix="survey-foreign-"))
        self.cache, self.result = self.folder / "numba", self.folder / "there.npz"
        self._stderr = open(self.folder / "stderr.txt", "w+")
        self._proc = subprocess.Popen(
            [sys.executable, "-c", "import os\nos.nice(10)\n" + STARTS, str(self.result),
             str(WORKFLOWS)], stdout=subprocess.DEVNULL, stderr=self._stderr,
            env={**os.environ, **FOREIGN, "NUMBA_CACHE_DIR": str(self.cache)})

    def wait(self, timeout=1200) -> tuple[int, str]:
        """The run's exit code and stderr, once it has ended."""
        code = self._proc.wait(timeout)
        self._stderr.seek(0)
        return code, self._stderr.read()

    def close(self):
        if self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait()
        self._stderr.close()
        shutil.rmtree(self.folder, ignore_errors=True)


# where conftest.py keeps the run it started for the tests marked `foreign`
RUN = pytest.StashKey[ForeignRun]()
