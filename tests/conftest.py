import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))  # tests/reference.py, tests/foreign.py

import foreign  # noqa: E402
from survey.cli import main  # noqa: E402
from survey.physics.system import System, rhs  # noqa: E402


def pytest_collection_modifyitems(items):
    """The modules of tests marked `foreign` run last: the other machine's run (below)
    then has the rest of the suite's time to compile."""
    later = {item.module for item in items if item.get_closest_marker("foreign")}
    items.sort(key=lambda item: item.module in later)


def pytest_collection_finish(session):
    """Start the run on the other machine (tests/foreign.py) in the background once a test
    that needs it is collected: it compiles for minutes on the core the suite leaves idle."""
    if not session.config.option.collectonly and any(
            item.get_closest_marker("foreign") for item in session.items):
        session.config.stash[foreign.RUN] = foreign.ForeignRun()


def pytest_unconfigure(config):
    run = config.stash.get(foreign.RUN, None)
    if run is not None:
        run.close()


@pytest.fixture(scope="session")
def paper_system():
    """The paper's system: three unit masses in the plane, U = P^2 / 2."""
    return System.create()


def area_rate_form(system, triplet=(0, 1, 2)):
    """Matrix Q with y^T Q y = dA/dt of a 2-D triplet (bilinear in positions and momenta)."""
    n, nq = system.n, system.n // 2

    def rate(y):
        q, p = system.split(y)
        v = p / system.masses[:, None]
        (u, vv, w), (du, dv, dw) = (q[list(triplet)], v[list(triplet)])
        cr = lambda a, b: a[0] * b[1] - a[1] * b[0]
        return 0.5 * (cr(dv - du, w - u) + cr(vv - u, dw - du))

    Q = np.zeros((n, n))
    for a in range(nq):
        for b in range(nq):
            y = np.zeros(n)
            y[a], y[nq + b] = 1.0, 1.0
            Q[a, nq + b] = Q[nq + b, a] = 0.5 * rate(y)
    return Q


def full_rhs(system, y, n_tan=0):
    """The compiled right-hand side at state y (orbit, then n_tan tangent vectors)."""
    dy = np.zeros_like(y)
    rhs(0.0, y, dy, system.model, n_tan)
    return dy


def derivative(f, h=1e-5):
    """d f(s)/ds at s = 0 by the 4th-order central difference."""
    return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h)


def energy_gradient(system, y, h=1e-5):
    """dH/dq at state y, coordinate by coordinate."""
    unit = np.eye(system.n)
    return np.array([derivative(lambda s: system.energy(y + s * unit[a]), h)
                     for a in range(system.n // 2)])


def spread_state(system, rng):
    """A state whose bodies are no closer than 0.6 (so that the r^-12 and r^-9 terms keep
    4th-order differences accurate), with random momenta."""
    N, d = system.n_bodies, system.dim
    while True:
        q = rng.uniform(-1.0, 1.0, (N, d)) * N ** (1 / d)
        dist = np.linalg.norm(q[:, None] - q[None], axis=-1) + np.eye(N) * 9
        if dist.min() > 0.6:
            return system.state(q, rng.normal(size=(N, d)))


def assert_forces_are_minus_the_gradient(system, y):
    """Forces = -dU/dq by 4th-order differences of H (momenta zeroed, so H = U rounds at
    the scale of U alone), and they conserve momentum."""
    nq = system.n // 2
    y = np.concatenate([y[:nq], np.zeros(nq)])
    force = full_rhs(system, y)[nq:]
    grad = energy_gradient(system, y)
    np.testing.assert_allclose(force, -grad, rtol=1e-6, atol=1e-8 * np.abs(grad).max())
    np.testing.assert_allclose(force.reshape(system.n_bodies, system.dim).sum(axis=0), 0.0,
                               atol=1e-13 * np.abs(force).max())


def assert_tangent_forces_are_the_derivative(system, y, rng):
    """The variational equations of two random tangent vectors: d dq/dt = M^-1 dp and
    d dp/dt = the derivative of the forces along dq (4th-order differences)."""
    n, nq = system.n, system.n // 2
    tangents = rng.normal(size=(2, n))
    out = full_rhs(system, np.concatenate([y, tangents.ravel()]), n_tan=2)
    for t in range(2):
        dq = np.concatenate([tangents[t, :nq], np.zeros(nq)])
        fd = derivative(lambda s: full_rhs(system, y + s * dq)[nq:])
        block = out[n * (1 + t):n * (2 + t)]
        np.testing.assert_allclose(block[nq:], fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max())
        np.testing.assert_allclose(block[:nq], tangents[t, nq:] / np.repeat(system.masses,
                                                                             system.dim),
                                   rtol=1e-15)


# the explorer's tests (tests/presentation/test_explore*.py): a family archive of each kind
BREATHING = ('[initial]\nfamily = "equilateral"\ndelta = 0.0\n\n'
             '[periodic]\nmode = 3\nparameter = "energy"\nto = 150.0\nsteps = 3\n')
ROUTH = '''
[system]
masses = [1.0, 0.01, 0.0001]
interactions = [{kind = "pair", potential = "gravity", params = {G = 1.0}}]
[initial]
family = "explicit"
positions = [[1.0, 0.0], [-0.5, 0.8660254037844386], [-0.5, -0.8660254037844386]]
[equilibria]
rotation_rate = 1.0
parameter = "mass_1"
to = 0.06
steps = 5
'''


@pytest.fixture(scope="session")
def families(tmp_path_factory):
    """A periodic family (the homographic breathing orbits in energy) and a family of
    relative equilibria (Lagrange's triangle along a mass), each as --output writes it."""
    folder = tmp_path_factory.mktemp("families")
    out = {}
    for kind, text in (("periodic", BREATHING), ("equilibria", ROUTH)):
        (folder / f"{kind}.toml").write_text(text)
        out[kind] = folder / f"{kind}.nc"
        assert main([kind, str(folder / f"{kind}.toml"), "--output", str(out[kind])]) == 0
    return out
