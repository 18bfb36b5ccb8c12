"""Jacobi and reduced polar coordinates of three bodies in the plane (paper Section 4).

Jacobi vectors: s = v - u, h = w - (m1 u + m2 v)/m12, R the centre of mass; polar form
s = sigma e^{i theta}, h = eta e^{i(theta + phi)}. Momenta follow the paper:
p_sigma = mu1 sigma', p_eta = mu2 eta', p_theta = J = s x p_s + h x p_h and
p_phi = mu1 mu2 sigma^2 eta^2 phi' / I, so that
H = p_sigma^2/2mu1 + p_eta^2/2mu2 + J^2/2I + (1/(mu1 sigma^2) + 1/(mu2 eta^2)) p_phi^2/2 + U.
(This p_phi is the kinetic part of the momentum canonically conjugate to phi, h x p_h =
p_phi + mu2 eta^2 J / I; the two agree when J = 0.)
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..machine import portable
from .forces import profile
from ..machine.jit import kernel
from .system import System, weighted_sum
from .terms import PERIMETER


class Reduced(NamedTuple):
    """Reduced coordinates and momenta, each of shape (...)."""

    sigma: np.ndarray
    eta: np.ndarray
    phi: np.ndarray       # in (-pi, pi]: angle from s to h
    theta: np.ndarray     # direction of s
    p_sigma: np.ndarray
    p_eta: np.ndarray
    p_phi: np.ndarray
    J: np.ndarray         # p_theta: angular momentum about the centre of mass


class JacobiMasses(NamedTuple):
    m1: float
    m2: float
    m3: float
    m12: float
    mT: float
    mu1: float
    mu2: float

    @classmethod
    def of(cls, system: System):
        _planar_triplet(system)
        m1, m2, m3 = map(float, system.masses)
        m12, mT = m1 + m2, m1 + m2 + m3
        return cls(m1, m2, m3, m12, mT, m1 * m2 / m12, m12 * m3 / mT)


def _planar_triplet(system: System):
    if system.n_bodies != 3 or system.dim != 2:
        raise ValueError("reduced (Jacobi) coordinates are for three bodies in the plane "
                         f"(N = 3, dim = 2), not N = {system.n_bodies}, dim = {system.dim}")


def jacobi_weights(system: System):
    """Weights (S, H, Ps, Ph) with s = sum S_i x_i, h = sum H_i x_i, p_s = sum Ps_i p_i,
    p_h = sum Ph_i p_i."""
    m = JacobiMasses.of(system)
    S = np.array([-1.0, 1.0, 0.0])
    H = np.array([-m.m1 / m.m12, -m.m2 / m.m12, 1.0])
    Ps = np.array([-m.m2, m.m1, 0.0]) / m.m12
    Ph = np.array([-m.m3, -m.m3, m.m12]) / m.mT
    return S, H, Ps, Ph


def jacobi(system: System, y):
    """(s, h, p_s, p_h), each (..., 2), from Cartesian states (..., n)."""
    q, p = system.split(y)
    S, H, Ps, Ph = jacobi_weights(system)
    return tuple(weighted_sum(w, x) for w, x in ((S, q), (H, q), (Ps, p), (Ph, p)))


def reduced(system: System, y) -> Reduced:
    """Reduced coordinates of Cartesian states (..., n)."""
    m = JacobiMasses.of(system)
    y = np.asarray(y, dtype=np.float64)
    rows = np.ascontiguousarray(y.reshape(-1, y.shape[-1]))
    out = np.empty((len(Reduced._fields), rows.shape[0]))
    _reduced_rows(rows, *jacobi_weights(system), m.mu1, m.mu2, out,
                  np.empty((4, rows.shape[0])))
    shape = y.shape[:-1]
    return Reduced(*(x.reshape(shape) if shape else x[0] for x in out))


@kernel
def _reduced_rows(y, S, H, Ps, Ph, mu1, mu2, out, args):
    """`reduced` of states y (M, 12) into out (8, M): the Jacobi vectors as `jacobi` sums
    them (body by body), then NumPy's operations on them in NumPy's order (a sum over a
    vector's components starts from 0.0), so the bits are those of the same formulas on
    arrays; the angles' atan2 in SIMD loops of their own over the arguments gathered in
    args (4, M): faster than the same formulas on arrays over the torus analysis' samples,
    and the angles faster again."""
    for r in range(y.shape[0]):
        q0x, q0y, q1x, q1y, q2x, q2y = y[r, 0], y[r, 1], y[r, 2], y[r, 3], y[r, 4], y[r, 5]
        p0x, p0y, p1x, p1y, p2x, p2y = y[r, 6], y[r, 7], y[r, 8], y[r, 9], y[r, 10], y[r, 11]
        sx = S[0] * q0x + S[1] * q1x + S[2] * q2x
        sy = S[0] * q0y + S[1] * q1y + S[2] * q2y
        hx = H[0] * q0x + H[1] * q1x + H[2] * q2x
        hy = H[0] * q0y + H[1] * q1y + H[2] * q2y
        psx = Ps[0] * p0x + Ps[1] * p1x + Ps[2] * p2x
        psy = Ps[0] * p0y + Ps[1] * p1y + Ps[2] * p2y
        phx = Ph[0] * p0x + Ph[1] * p1x + Ph[2] * p2x
        phy = Ph[0] * p0y + Ph[1] * p1y + Ph[2] * p2y
        sigma = math.sqrt(0.0 + sx * sx + sy * sy)
        eta = math.sqrt(0.0 + hx * hx + hy * hy)
        Ls = sx * psy - sy * psx
        Lh = hx * phy - hy * phx
        a = mu1 * (sigma * sigma)
        b = mu2 * (eta * eta)
        out[0, r] = sigma
        out[1, r] = eta
        args[0, r], args[1, r] = sx * hy - sy * hx, 0.0 + sx * hx + sy * hy
        args[2, r], args[3, r] = sy, sx
        out[4, r] = (0.0 + psx * sx + psy * sy) / sigma
        out[5, r] = (0.0 + phx * hx + phy * hy) / eta
        out[6, r] = (a * Lh - b * Ls) / (a + b)
        out[7, r] = Ls + Lh
    portable.atan2_into(args[0], args[1], out[2])
    portable.atan2_into(args[2], args[3], out[3])


def reduced_sides(system: System, sigma, eta, phi):
    """Side lengths (a, b, c) from the shape coordinates: c = sigma,
    a = |h - m1/m12 s|, b = |h + m2/m12 s|."""
    m = JacobiMasses.of(system)
    al, be = m.m1 / m.m12, m.m2 / m.m12
    a = np.sqrt(eta ** 2 + (al * sigma) ** 2 - 2 * al * sigma * eta * portable.vcos(phi))
    b = np.sqrt(eta ** 2 + (be * sigma) ** 2 + 2 * be * sigma * eta * portable.vcos(phi))
    return a, b, sigma


def reduced_potential(system: System, sigma, eta, phi):
    """U(sigma, eta, phi): for the paper's systems through P = a + b + c or
    |A| = sigma eta |sin phi| / 2; for any other sum of terms (all are invariant under
    rotations and translations) the potential of the triangle of that shape."""
    if not system.is_paper_kind:
        m = JacobiMasses.of(system)
        sigma, eta, phi = np.broadcast_arrays(*(np.asarray(v, dtype=float)
                                                for v in (sigma, eta, phi)))
        s = np.stack([sigma, np.zeros_like(sigma)], axis=-1)
        h = np.stack([eta * portable.vcos(phi), eta * portable.vsin(phi)], axis=-1)
        q = np.concatenate([-m.m2 / m.m12 * s - m.m3 / m.mT * h,
                            m.m1 / m.m12 * s - m.m3 / m.mT * h, m.m12 / m.mT * h], axis=-1)
        return system.potential_energy(np.concatenate([q, np.zeros_like(q)], axis=-1))
    pot = system.potential
    if pot.measure == PERIMETER:
        x = sum(reduced_sides(system, sigma, eta, phi))
    else:
        x = 0.5 * sigma * eta * np.abs(portable.vsin(phi))
    x = np.asarray(x, dtype=np.float64)
    out = np.empty(x.size)
    _profile_values(pot.profile, pot.pair, np.ascontiguousarray(x).ravel(), out)
    return out.reshape(x.shape)


@kernel
def _profile_values(code, par, x, out):
    """out[i] = U(x[i]) of a profile, compiled: a section's starts evaluate it on grids of
    ~10^4 shapes (one value at a time from Python, seeded starts took seconds each)."""
    for i in range(x.size):
        out[i] = profile(code, par, x[i])[0]


def phi_momentum_coefficient(system: System, sigma, eta):
    """c with kinetic energy c p_phi^2 in the reduced Hamiltonian."""
    m = JacobiMasses.of(system)
    return 0.5 * (1.0 / (m.mu1 * sigma ** 2) + 1.0 / (m.mu2 * eta ** 2))


def reduced_energy(system: System, r: Reduced):
    """The reduced Hamiltonian (ReducedJacobi) at r; equals H in the centre-of-mass frame."""
    m = JacobiMasses.of(system)
    inertia = m.mu1 * r.sigma ** 2 + m.mu2 * r.eta ** 2
    return (r.p_sigma ** 2 / (2 * m.mu1) + r.p_eta ** 2 / (2 * m.mu2)
            + r.J ** 2 / (2 * inertia)
            + phi_momentum_coefficient(system, r.sigma, r.eta) * r.p_phi ** 2
            + reduced_potential(system, r.sigma, r.eta, r.phi))


def to_cartesian(system: System, r: Reduced, centre=(0.0, 0.0), momentum=(0.0, 0.0)):
    """Cartesian states (..., n) from reduced coordinates, with the centre of mass at
    `centre` and total momentum `momentum`."""
    m = JacobiMasses.of(system)
    sig, eta, phi, th = (np.asarray(v, dtype=float) for v in (r.sigma, r.eta, r.phi, r.theta))
    a, b = m.mu1 * sig ** 2, m.mu2 * eta ** 2
    phidot = 2.0 * phi_momentum_coefficient(system, sig, eta) * r.p_phi
    thdot = (r.J - b * phidot) / (a + b)
    es = np.stack([portable.vcos(th), portable.vsin(th)], axis=-1)
    eh = np.stack([portable.vcos(th + phi), portable.vsin(th + phi)], axis=-1)
    perp = lambda e: np.stack([-e[..., 1], e[..., 0]], axis=-1)
    s, h = sig[..., None] * es, eta[..., None] * eh
    sdot = (r.p_sigma / m.mu1)[..., None] * es + (sig * thdot)[..., None] * perp(es)
    hdot = (r.p_eta / m.mu2)[..., None] * eh + (eta * (thdot + phidot))[..., None] * perp(eh)
    R = np.asarray(centre, dtype=float)[..., None, :]
    Rdot = np.asarray(momentum, dtype=float)[..., None, :] / m.mT
    weights_s = np.array([-m.m2 / m.m12, m.m1 / m.m12, 0.0])
    weights_h = np.array([-m.m3 / m.mT, -m.m3 / m.mT, m.m12 / m.mT])
    q = R + weights_s[:, None] * s[..., None, :] + weights_h[:, None] * h[..., None, :]
    vel = Rdot + weights_s[:, None] * sdot[..., None, :] + weights_h[:, None] * hdot[..., None, :]
    p = vel * system.masses[:, None]
    shape = q.shape[:-2]
    return np.concatenate([q.reshape(shape + (-1,)), p.reshape(shape + (-1,))], axis=-1)


def position_form(system, A, B, skew=False):
    """Matrix Q on positions with q^T Q q = a . b (or a x b when skew) for a = sum A_i x_i,
    b = sum B_i x_i."""
    d, nq = system.dim, system.n // 2
    Q = np.zeros((nq, nq))
    for i in range(system.n_bodies):
        for j in range(system.n_bodies):
            if skew:
                Q[i * d, j * d + 1] += A[i] * B[j]
                Q[i * d + 1, j * d] -= A[i] * B[j]
            else:
                for c in range(d):
                    Q[i * d + c, j * d + c] += A[i] * B[j]
    return 0.5 * (Q + Q.T)


def phase_form(system, A, B):
    """Matrix Q on the state with y^T Q y = a . b for a = sum A_i x_i, b = sum B_i p_i."""
    d, n, nq = system.dim, system.n, system.n // 2
    Q = np.zeros((n, n))
    for i in range(system.n_bodies):
        for j in range(system.n_bodies):
            for c in range(d):
                Q[i * d + c, nq + j * d + c] += 0.5 * A[i] * B[j]
                Q[nq + j * d + c, i * d + c] += 0.5 * A[i] * B[j]
    return Q
