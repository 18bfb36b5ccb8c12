"""Every declared interaction term (survey.physics.terms.TERMS) passes the same battery, so a
new term that lacks a piece fails here: its parameters carry a meaning and bounds that
make_potential enforces; its forces are minus the gradient of its energy and its tangent
forces the derivative of its forces (4th-order finite differences; N = 3, 4, 7; d = 2, 3;
unequal masses; parameters off their defaults, so that no special case such as k = 2 hides
a bug); the forces conserve momentum."""
import math

import numpy as np
import pytest
from conftest import (
    assert_forces_are_minus_the_gradient,
    assert_tangent_forces_are_the_derivative,
    spread_state,
)

from survey.physics.system import System
from survey.physics.terms import TERMS, make_potential

CASES = [(t, N, d) for t in TERMS for N in (3, 4, 7) for d in (2, 3)]
IDS = [f"{t.kind}-{t.name}-N{N}-d{d}" for t, N, d in CASES]


def off_default(term) -> dict:
    """Parameters moved off their defaults (and still allowed)."""
    values = {p.name: 1.1 * p.default + 0.05 for p in term.parameters}
    for p in term.parameters:
        assert p.problem(values[p.name]) == "", (term.name, p.name)
    return values


def make_case(term, N, d, seed):
    rng = np.random.default_rng(seed + 10 * N + d)
    system = System(rng.uniform(0.5, 2.0, N), d,
                    make_potential(term.name, off_default(term), term.kind))
    return system, spread_state(system, rng)


@pytest.mark.parametrize("term", TERMS, ids=[f"{t.kind}-{t.name}" for t in TERMS])
def test_parameters_are_declared_and_their_bounds_enforced(term):
    assert term.formula and term.parameters
    defaults = make_potential(term.name, {}, term.kind)
    assert defaults.params == tuple(p.default for p in term.parameters)
    assert all(name in defaults.describe() for name in defaults.param_names)
    for p in term.parameters:
        assert p.doc, p.name
        bad = [math.nan, math.inf, "1"]
        if p.above is not None:
            bad.append(p.above)
        if p.low is not None:
            bad.append(p.low - 1.0)
        if p.nonzero:
            bad.append(0.0)
        for value in bad:
            with pytest.raises(ValueError, match=f"potential parameter '{p.name}' must be"):
                make_potential(term.name, {p.name: value}, term.kind)
    with pytest.raises(ValueError, match="has no parameter 'nonsense'"):
        make_potential(term.name, {"nonsense": 1.0}, term.kind)


@pytest.mark.parametrize("term,N,d", CASES, ids=IDS)
def test_forces_are_minus_the_gradient_of_the_energy(term, N, d):
    assert_forces_are_minus_the_gradient(*make_case(term, N, d, seed=0))


@pytest.mark.parametrize("term,N,d", CASES, ids=IDS)
def test_tangent_forces_are_the_derivative_of_the_forces(term, N, d):
    assert_tangent_forces_are_the_derivative(*make_case(term, N, d, seed=1),
                                             np.random.default_rng(2))


