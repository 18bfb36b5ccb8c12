import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))  # tests/reference.py

from survey.physics.system import System, rhs  # noqa: E402


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
    rhs(0.0, y, dy, *system.kernel_args, n_tan)
    return dy


def derivative(f, h=1e-5):
    """d f(s)/ds at s = 0 by the 4th-order central difference."""
    return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h)


def energy_gradient(system, y, h=1e-5):
    """dH/dq at state y, coordinate by coordinate."""
    unit = np.eye(system.n)
    return np.array([derivative(lambda s: system.energy(y + s * unit[a]), h)
                     for a in range(system.n // 2)])
