"""Slow, obvious NumPy reference of the triplet dynamics, used only by the tests.

It is written differently from the kernels on purpose: the potential is a function of the
three side lengths (the perimeter a + b + c, or Heron's formula for |A|) and forces come
from the chain rule through the sides, dU/dx_i = sum_s dU/ds ds/dx_i. That formulation is
ill-conditioned near collinear triangles (which is why the kernels do not use it), so the
tests compare at generic configurations.
"""
import itertools

import numpy as np

from survey.physics.terms import AREA, POWER, YUKAWA


def profile_U(code, par, x):
    if code == POWER:
        c, k = par
        return c * np.log(x) if k == 0 else c * x ** k / k
    if code == YUKAWA:
        c, g = par
        return -c * np.exp(-g * x) / x
    a, b = par
    return a / x + b * x * x


def profile_dU(code, par, x, h=1e-30):
    """U'(x) by the complex step Im U(x + ih) / h: exact to rounding, and independent of the
    kernels' closed forms."""
    return np.imag(profile_U(code, par, x + 1j * h)) / h


def _measure_from_sides(measure, a, b, c):
    if measure == AREA:
        s = (a + b + c) * (b + c - a) * (c + a - b) * (a + b - c)
        return 0.25 * np.sqrt(s), 0.25 * 0.5 / np.sqrt(s) * np.array([
            # d s / d a, d s / d b, d s / d c of the Heron product
            _heron_partial(a, b, c), _heron_partial(b, c, a), _heron_partial(c, a, b)])
    return a + b + c, np.ones(3)


def _heron_partial(a, b, c):
    """d/da of (a+b+c)(b+c-a)(c+a-b)(a+b-c) (symmetric in b, c)."""
    P, ia, ib, ic = a + b + c, b + c - a, c + a - b, a + b - c
    return ia * ib * ic - P * ib * ic + P * ia * ic + P * ia * ib


def potential(q, system):
    pot = system.potential
    total = 0.0
    for i, j, k in itertools.combinations(range(system.n_bodies), 3):
        u, v, w = q[i], q[j], q[k]
        a, b, c = np.linalg.norm(w - v), np.linalg.norm(u - w), np.linalg.norm(v - u)
        x, _ = _measure_from_sides(pot.measure, a, b, c)
        total += profile_U(pot.profile, pot.params, x)
    return total


def forces(q, system):
    """-grad U by the chain rule through the side lengths."""
    pot = system.potential
    F = np.zeros_like(q)
    for i, j, k in itertools.combinations(range(system.n_bodies), 3):
        u, v, w = q[i], q[j], q[k]
        a, b, c = np.linalg.norm(w - v), np.linalg.norm(u - w), np.linalg.norm(v - u)
        x, dx_dsides = _measure_from_sides(pot.measure, a, b, c)
        dU = profile_dU(pot.profile, pot.params, x)
        da, db, dc = dU * dx_dsides
        # side a = |w - v| couples j, k; b = |u - w| couples k, i; c = |v - u| couples i, j
        for s, (p1, p2), L in ((da, (j, k), a), (db, (k, i), b), (dc, (i, j), c)):
            e = (q[p2] - q[p1]) / L
            F[p1] += s * e
            F[p2] -= s * e
    return F


def rhs(y, system, n_tangent=0, h=1e-6):
    """Orbit right-hand side; tangent blocks by central differences of `forces`."""
    N, d = system.n_bodies, system.dim
    n = 2 * N * d
    q = y[:N * d].reshape(N, d)
    p = y[N * d:n].reshape(N, d)
    out = [p.ravel() / np.repeat(system.masses, d), forces(q, system).ravel()]
    for t in range(n_tangent):
        dq = y[n * (1 + t):n * (1 + t) + N * d].reshape(N, d)
        dp = y[n * (1 + t) + N * d:n * (2 + t)]
        dF = (forces(q + h * dq, system) - forces(q - h * dq, system)) / (2 * h)
        out += [dp / np.repeat(system.masses, d), dF.ravel()]
    return np.concatenate(out)
