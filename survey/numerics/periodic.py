"""Periodic orbits by Newton shooting, and their Floquet multipliers.

A periodic orbit y(T) = y(0) -- or a relative periodic orbit, which returns rotated by an
angle theta (periodic in a rotating frame; three bodies breathing while they turn) -- is
found from a guess by Newton's method on the return map, with the degeneracies of a
Hamiltonian system with symmetries pinned rather than left to least squares: the phase
along the orbit (the correction is orthogonal to the flow), the energy (held at the
guess's or a given value), the angular momentum of a relative periodic orbit (the
guess's; a periodic one's is its own: another J turns it), the centre of mass and total
momentum (zero), and the orientation (no correction along a rotation). The Jacobian is the monodromy matrix from
the variational equations -- the orbit with its full tangent block, every vector in the
error control -- so the iteration converges quadratically.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..physics.equilibria import nontrivial_subspace
from ..physics.system import System, rhs
from .integrate import integrate

UNIT_CIRCLE = 1e-6          # ||mu| - 1| below which a multiplier is on the unit circle


class PeriodicOrbit(NamedTuple):
    state: np.ndarray         # y(0) (n,), centre of mass at rest at the origin
    period: float
    rotation: float           # angle the orbit returns rotated by (0: periodic)
    energy: float
    angular_momentum: float
    return_error: float       # |y(T) - R y(0)| / |y(0)| with the final state (or the
    #                           pinned energy's and J's relative miss, if larger)
    residuals: np.ndarray     # the same before each Newton step, then after the last
    multipliers: np.ndarray   # non-trivial Floquet multipliers (complex), by angle
    monodromy: np.ndarray     # R^-1 dy(T)/dy(0) (n, n)

    @property
    def stable(self) -> bool:
        """Linearly stable: every non-trivial multiplier on the unit circle."""
        return bool(np.all(np.abs(np.abs(self.multipliers) - 1.0) <= UNIT_CIRCLE))

    @property
    def kind(self) -> str:
        """elliptic (all on the unit circle), hyperbolic (a real pair off it, mu > 0),
        inverse hyperbolic (mu < 0) or complex unstable (a quartet off it)."""
        mu = self.multipliers
        off = np.abs(np.abs(mu) - 1.0) > UNIT_CIRCLE
        if not off.any():
            return "elliptic"
        if np.any(off & (np.abs(mu.imag) > UNIT_CIRCLE * np.abs(mu))):
            return "complex unstable"
        return "inverse hyperbolic" if np.any(off & (mu.real < 0)) else "hyperbolic"

    @property
    def rates(self) -> np.ndarray:
        """ln |mu| / T of the multipliers off the circle, largest first: how fast nearby
        orbits leave it."""
        mu = self.multipliers
        return np.sort(np.log(np.abs(mu[np.abs(mu) > 1.0 + UNIT_CIRCLE])))[::-1] / self.period


def _rotation(system: System, theta: float) -> np.ndarray:
    """The state-space matrix rotating every position and momentum by theta (the plane)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.kron(np.eye(2 * system.n_bodies), np.array([[c, -s], [s, c]]))


def _generator(system: System) -> np.ndarray:
    return np.kron(np.eye(2 * system.n_bodies), np.array([[0.0, -1.0], [1.0, 0.0]]))


def _flow(system: System, y) -> np.ndarray:
    out = np.zeros(system.n)
    rhs(0.0, np.ascontiguousarray(y, dtype=float), out, *system.kernel_args, 0)
    return out


def _gradients(system: System, y):
    """Gradients of the energy and (in the plane) the angular momentum, from the flow:
    dH/dq = -p', dH/dp = q'; dL/dq = (p_y, -p_x), dL/dp = (-q_y, q_x)."""
    nq = system.n // 2
    f = _flow(system, y)
    grad_h = np.concatenate([-f[nq:], f[:nq]])
    if system.dim != 2:
        return grad_h, None
    G = np.kron(np.eye(system.n_bodies), np.array([[0.0, -1.0], [1.0, 0.0]]))
    q, p = y[:nq], y[nq:]
    return grad_h, np.concatenate([-G @ p, G @ q])


def _monodromy(system: System, y, period, tol):
    """(y(T), dy(T)/dy(0)) from the orbit with its full tangent block."""
    out = integrate(system, y, period, tangents=np.eye(system.n), rtol=tol, atol=tol,
                    control_tangents=True, renorm_interval=2.0 * abs(period) + 1.0)
    if not out.ok:
        raise ValueError(f"the orbit from the guess did not reach t = {period:g} "
                         f"({out.status.name.lower()})")
    return out.y, out.deviations.T


def periodic_orbit(system: System, guess, period: float, rotating: bool = False,
                   energy: float | None = None, tol: float = 1e-13,
                   max_iter: int = 25) -> PeriodicOrbit:
    """The periodic orbit (relative periodic with `rotating`, planar systems, at the
    guess's angular momentum) near the state `guess` with period near `period`, by Newton
    shooting at the guess's energy (or `energy`), its centre of mass at rest at the origin.
    Stops when the return error -- and the miss of the pinned energy (and J) -- is at the
    integrator's tolerance and no longer falls; raises ValueError if it does not get
    there."""
    if rotating and system.dim != 2:
        raise ValueError("relative periodic orbits are found in the plane (dim = 2)")
    n, d = system.n, system.dim
    nq = n // 2
    m = np.repeat(system.masses, d)
    y = np.array(guess, dtype=float)
    q, p = y[:nq].reshape(-1, d), y[nq:].reshape(-1, d)
    q = q - np.sum(system.masses[:, None] * q, axis=0) / system.masses.sum()
    p = p - system.masses[:, None] * np.sum(p, axis=0) / system.masses.sum()
    y = np.concatenate([q.ravel(), p.ravel()])
    energy = float(system.energy(y)) if energy is None else float(energy)
    spin = float(system.angular_momentum(y)) if d == 2 else 0.0   # pinned if rotating
    T, theta = float(period), 0.0
    # the centre of mass and the total momentum, held at zero
    centre = np.zeros((2 * d, n))
    for k in range(d):
        centre[k, k:nq:d] = m[k::d] / m.sum()
        centre[d + k, nq + k::d] = 1.0
    residuals = []
    best = np.inf
    if rotating:    # the angle that best turns the guess's return onto its start
        yT = _monodromy(system, y, T, tol)[0]
        z0, zT = y[0::2] + 1j * y[1::2], yT[0::2] + 1j * yT[1::2]
        theta = float(np.angle(np.sum(np.conj(z0) * zT)))
    for _ in range(max_iter):
        yT, phi = _monodromy(system, y, T, tol)
        R = _rotation(system, theta) if rotating else np.eye(n)
        r = yT - R @ y
        # the return error, and the pinned energy's (and a rotating orbit's J's) miss
        pinned = abs(float(system.energy(y)) - energy) / max(abs(energy), 1.0)
        if rotating:
            pinned = max(pinned, abs(float(system.angular_momentum(y)) - spin)
                         / max(abs(spin), 1.0))
        error = max(float(np.linalg.norm(r) / np.linalg.norm(y)), pinned)
        residuals.append(error)
        if error <= 10 * tol or (error >= 0.5 * best and best <= 1e3 * tol):
            break
        best = min(best, error)
        f0, fT = _flow(system, y), _flow(system, yT)
        grad_h, grad_l = _gradients(system, y)
        cols = [phi - R, fT[:, None]]
        if rotating:
            cols.append((-_generator(system) @ R @ y)[:, None])
        top = np.hstack(cols)
        extra = top.shape[1] - n
        rows = [np.hstack([f0, np.zeros(extra)]),                  # phase
                np.hstack([grad_h, np.zeros(extra)])]              # energy
        rhs_extra = [0.0, energy - float(system.energy(y))]
        if d == 2:      # a periodic orbit's J is its own; a rotating one's is pinned
            rows.append(np.hstack([_generator(system) @ y, np.zeros(extra)]))  # orientation
            rhs_extra.append(0.0)
            if rotating:
                rows.append(np.hstack([grad_l, np.zeros(extra)]))  # angular momentum
                rhs_extra.append(spin - float(system.angular_momentum(y)))
        rows += [np.hstack([c, np.zeros(extra)]) for c in centre]
        rhs_extra += [0.0] * len(centre)
        A = np.vstack([top, np.array(rows)])
        b = np.concatenate([-r, rhs_extra])
        step = np.linalg.lstsq(A, b, rcond=1e-14)[0]
        step *= min(1.0, 0.2 * T / max(abs(step[n]), 1e-300))   # T moves by 20% at most
        y = y + step[:n]
        T += step[n]
        if rotating:
            theta += step[n + 1]
    else:
        raise ValueError(f"Newton shooting did not converge in {max_iter} steps (return "
                         f"error {residuals[-1]:.1e})")
    if residuals[-1] > 1e4 * tol:
        raise ValueError(f"no periodic orbit near the guess: Newton shooting stalled at a "
                         f"return error of {residuals[-1]:.1e}")
    R = _rotation(system, theta) if rotating else np.eye(n)
    M = R.T @ phi
    # the motions of the centre of mass are a symplectic pair of invariant planes; their
    # complement, where the centre stays at rest at the origin, is `internal`
    internal = np.linalg.svd(centre)[2][2 * d:].T
    J = np.block([[np.zeros((nq, nq)), np.eye(nq)], [-np.eye(nq), np.zeros((nq, nq))]])
    known = [internal.T @ _flow(system, y)]
    if d == 2:
        known.append(internal.T @ _generator(system) @ y)
    Mi = internal.T @ M @ internal
    W = nontrivial_subspace(Mi - np.eye(Mi.shape[0]), known, internal.T @ J @ internal)
    mu = np.linalg.eigvals(W.T @ Mi @ W)
    mu = mu[np.lexsort((np.abs(mu), np.angle(mu)))]
    return PeriodicOrbit(y, T, theta, energy,
                         float(system.angular_momentum(y)) if d == 2 else 0.0, residuals[-1],
                         np.array(residuals), mu, M)

