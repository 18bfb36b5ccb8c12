"""The right-hand side that three bodies in the plane run under a perimetric or areal term is
the general path's arithmetic, bit for bit: random states over twelve decades, unequal
masses, every profile, up to three tangent vectors, and states with exact zeros (collinear,
axis-aligned, at rest) where only the signs of zeros could tell them apart."""
import numpy as np
import pytest

from survey.physics.system import System, _leading_forces, rhs
from survey.physics.terms import TERMS, make_potential

PLANAR = [t for t in TERMS if t.kind == "triplet" and t.name.startswith(("perimetric",
                                                                           "areal"))]


def states(rng):
    for trial in range(400):
        n_tan = trial % 4
        y = rng.normal(size=12 * (1 + n_tan)) * 10.0 ** rng.uniform(-6, 6)
        if trial % 5 == 0:          # exact zeros: axis-aligned, some bodies at rest
            y[rng.integers(0, y.size, 5)] = 0.0
        if trial % 7 == 0:          # collinear on the x axis
            y[[1, 3, 5]] = 0.0
        yield n_tan, y


@pytest.mark.parametrize("term", PLANAR, ids=[t.name for t in PLANAR])
def test_the_planar_path_is_the_general_path_bit_for_bit(term):
    rng = np.random.default_rng(7)
    params = {p.name: 1.1 * p.default + 0.05 for p in term.parameters}
    system = System(rng.uniform(0.5, 2.0, 3), 2, make_potential(term.name, params))
    masses, d, measure, prof, par = system.kernel_args
    for n_tan, y in states(rng):
        fast, general = np.full(y.size, np.nan), np.full(y.size, np.nan)
        rhs(0.0, y, fast, masses, d, measure, prof, par, n_tan)
        _leading_forces(y, general, masses, 3, 2, measure, prof, par, n_tan)
        assert fast.tobytes() == general.tobytes(), (n_tan, y)
