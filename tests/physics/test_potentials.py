"""Forces and tangent forces of every built-in potential against finite differences and
against the side-length reference, in 2-D and 3-D, N = 3 and 4, unequal masses."""
import numpy as np
import pytest
import reference
from conftest import derivative, energy_gradient, full_rhs

from survey.physics.geometry import perimeter
from survey.physics.system import System
from survey.physics.terms import ATM, POTENTIAL_NAMES, make_potential

PARAMS = {  # non-default parameters, so that no special case (k = 2) hides a bug
    "perimetric_power": dict(coupling=0.7, exponent=3.0),
    "perimetric_yukawa": dict(coupling=2.0, gamma=0.3),
    "perimetric_barrier": dict(alpha=1.5, beta=0.4),
    "areal_power": dict(coupling=1.3, exponent=2.5),
    "areal_yukawa": dict(coupling=1.0, gamma=0.5),
    "areal_barrier": dict(alpha=2.0, beta=1.0),
}
# the perimetric and areal families; axilrod_teller and the pair terms: test_interactions.py
CASES = [(name, N, d) for name in PARAMS for N in (3, 4) for d in (2, 3)]


def make_case(name, N, d, seed=0):
    rng = np.random.default_rng(seed)
    system = System.create(masses=rng.uniform(0.5, 2.0, N), dim=d, potential=name,
                           **PARAMS[name])
    y = rng.normal(size=system.n)
    return system, y


def test_all_named_potentials_are_tested():
    assert set(PARAMS) | {ATM} == set(POTENTIAL_NAMES)


@pytest.mark.parametrize("name,N,d", CASES)
def test_forces_are_minus_gradient_of_energy(name, N, d):
    system, y = make_case(name, N, d)
    nq = system.n // 2
    force = full_rhs(system, y)[nq:]
    grad = energy_gradient(system, y)
    np.testing.assert_allclose(force, -grad, rtol=1e-7, atol=1e-8 * np.abs(grad).max())


@pytest.mark.parametrize("name,N,d", CASES)
def test_tangent_forces_are_derivative_of_forces(name, N, d):
    system, y = make_case(name, N, d, seed=1)
    n, nq = system.n, system.n // 2
    rng = np.random.default_rng(2)
    tangents = rng.normal(size=(2, n))
    out = full_rhs(system, np.concatenate([y, tangents.ravel()]), n_tan=2)
    for t in range(2):
        dq, dp = tangents[t, :nq], tangents[t, nq:]
        step = np.concatenate([dq, np.zeros(nq)])
        fd = derivative(lambda s: full_rhs(system, y + s * step)[nq:])
        block = out[n * (1 + t):n * (2 + t)]
        np.testing.assert_allclose(block[nq:], fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max())
        # d(dq)/dt = M^-1 dp
        np.testing.assert_allclose(block[:nq], dp / np.repeat(system.masses, d), rtol=1e-15)


@pytest.mark.parametrize("name,N,d", CASES)
def test_kernel_agrees_with_numpy_reference(name, N, d):
    system, y = make_case(name, N, d, seed=3)
    rng = np.random.default_rng(4)
    tangent = rng.normal(size=system.n)
    state = np.concatenate([y, tangent])
    ref = reference.rhs(state, system, n_tangent=1)
    np.testing.assert_allclose(full_rhs(system, state, n_tan=1), ref, rtol=1e-6,
                               atol=1e-7 * np.abs(ref).max())
    assert system.energy(y) - system.kinetic_energy(y) == pytest.approx(
        reference.potential(y[:system.n // 2].reshape(N, d), system), rel=1e-12)


def test_forces_stay_finite_and_bisect_near_collinear_triangle():
    """Vector forms keep full accuracy where the side-length chain rule loses it."""
    system = System.create()
    eps = 1e-9
    q = np.array([[-1.0, 0.0], [0.3, eps], [1.0, 0.0]])
    y = system.state(q, np.zeros((3, 2)))
    F = full_rhs(system, y)[6:].reshape(3, 2)
    P = perimeter(*system.triangle(y))
    # middle body: unit vectors to its neighbours nearly cancel, leaving a force of order eps
    assert abs(F[1, 0]) < 1e-8 * P and np.all(np.isfinite(F))
    # end bodies: U'(P) times two nearly parallel unit vectors
    np.testing.assert_allclose(F[0], [2 * P, 0.0], atol=1e-8 * P)


def test_areal_forces_are_parallel_to_altitudes():
    system = System.create(potential="areal_barrier")
    q = np.array([[0.1, -0.4], [1.3, 0.2], [-0.2, 0.9]])
    F = full_rhs(system, system.state(q, np.zeros((3, 2))))[6:].reshape(3, 2)
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        assert abs(np.dot(F[i], q[k] - q[j])) < 1e-13 * np.linalg.norm(F[i])
    np.testing.assert_allclose(F.sum(axis=0), 0.0, atol=1e-14)


@pytest.mark.parametrize("bad,match", [
    (("perimetric_cubic", {}), "unknown triplet potential"),
    (("perimetric_power", {"k": 2}), "no parameter 'k'"),
    (("perimetric_yukawa", {"gamma": -1.0}), "gamma"),
    (("areal_power", {"coupling": "x"}), "finite number"),
])
def test_bad_potential_names_and_parameters(bad, match):
    with pytest.raises(ValueError, match=match):
        make_potential(*bad)
