"""Periodic orbits by Newton shooting, their Floquet multipliers, and their families.

A periodic orbit y(T) = y(0) -- or a relative periodic orbit, which returns rotated by an
angle theta (periodic in a rotating frame; three bodies breathing while they turn) -- is
found from a guess by Newton's method on the return map, with the degeneracies of a
Hamiltonian system with symmetries pinned rather than left to least squares: the phase
along the orbit (the correction is orthogonal to the flow), the energy (held at the
guess's or a given value), the angular momentum of a relative periodic orbit (the
guess's; a periodic one's is its own: another J turns it), the centre of mass and total
momentum (zero), and the orientation (no correction along a rotation). The Jacobian is the
monodromy matrix from the variational equations -- the orbit with its full tangent block,
every vector in the error control -- so the iteration converges quadratically.

A family is followed by pseudo-arclength continuation in the energy or a parameter of the
system, the same equations bordered by the parameter's column and the arclength; where the
parameter turns (a fold) or multipliers leave or join the unit circle (through +1, -1 or
in a Krein collision), the point is bisected along the arclength. A Lyapunov family starts
from a normal mode of an elliptic relative equilibrium.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..catalog.defaults import EXCURSION, TURNING
from ..machine import linalg, portable
from ..physics.equilibria import (
    Bifurcation,
    RelativeEquilibrium,
    forces,
    nontrivial_subspace,
)
from ..physics.system import System, rhs
from .continuation import NAMED, at_labels, follow, on_row
from .integrate import flow_jacobian, integrate

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
    motion: "Motion"          # how far it leaves its start and how far its velocity turns

    # Where the orbit stands is read from its stability indices b = (mu + 1/mu) / 2, not
    # from |mu|: near a collision of multipliers at +-1 the monodromy's error moves the
    # pair's moduli by its square root (|mu| = 1 - 7e-5 on an elliptic figure-eight 1e-8
    # in mass from its crossing), while b, a smooth function of the pair, stays within
    # 1e-9 -- so a crossing is located, and an orbit classed, to that.

    def _on_circle(self) -> np.ndarray:
        """Per stability index: whether its pair lies on the unit circle (b real, |b| <= 1)."""
        b = self.indices
        return (np.abs(b.imag) <= UNIT_CIRCLE) & (np.abs(b.real) <= 1.0)

    @property
    def polar(self) -> tuple[np.ndarray, np.ndarray]:
        """The multipliers' moduli and angles, with the same bits on every machine."""
        return linalg.modulus(self.multipliers), linalg.argument(self.multipliers)

    @property
    def stable(self) -> bool:
        """Linearly stable: every non-trivial multiplier on the unit circle."""
        return bool(np.all(self._on_circle()))

    @property
    def on_circle(self) -> int:
        """How many non-trivial multipliers lie on the unit circle."""
        return 2 * int(np.sum(self._on_circle()))

    @property
    def kind(self) -> str:
        """elliptic (all on the unit circle), hyperbolic (a real pair off it, mu > 0),
        inverse hyperbolic (mu < 0) or complex unstable (a quartet off it)."""
        b = self.indices
        if np.all(self._on_circle()):
            return "elliptic"
        if np.any(np.abs(b.imag) > UNIT_CIRCLE):
            return "complex unstable"
        return "inverse hyperbolic" if np.any(b.real < -1.0) else "hyperbolic"

    @property
    def rates(self) -> np.ndarray:
        """ln |mu| / T of the multipliers off the circle, largest first: how fast nearby
        orbits leave it (mu = b + sqrt(b^2 - 1), the larger root, for each index off the
        band)."""
        b = self.indices[~self._on_circle()].astype(complex)
        root = np.sqrt(b * b - 1.0)
        mu = np.where(linalg.modulus(b + root) >= linalg.modulus(b - root), b + root, b - root)
        return np.sort(portable.vlog(linalg.modulus(mu)))[::-1] / self.period

    @property
    def index_error(self) -> float:
        """How well the stability indices are known: each comes twice, from mu and from its
        partner 1/mu, equal for an exact monodromy; the largest difference between the two
        (1e-12 on a well-separated pair, 1e-8 where a pair collides at +-1)."""
        b = self._all_indices()
        return float(np.max(linalg.modulus(b[::2] - b[1::2]), initial=0.0))

    def _all_indices(self) -> np.ndarray:
        mu = self.multipliers
        m2 = mu.real * mu.real + mu.imag * mu.imag         # 1/mu = conj(mu) / |mu|^2
        b = (mu.real + mu.real / m2) / 2.0 + 1j * ((mu.imag - mu.imag / m2) / 2.0)
        return b[np.lexsort((np.round(b.imag, 9), np.round(b.real, 9)))]    # pairs adjacent

    @property
    def indices(self) -> np.ndarray:
        """Henon's stability index b = (mu + 1/mu) / 2, one per reciprocal pair (complex
        for a quartet), ascending: |b| <= 1 on the unit circle, b = 1 and b = -1 where a pair
        passes through +1 (tangent, fold or branch) or -1 (period doubling)."""
        return self._all_indices()[::2]

    @property
    def residues(self) -> np.ndarray:
        """Greene's residue R = (2 - mu - 1/mu) / 4 = (1 - b) / 2 per pair: 0 < R < 1
        elliptic, R < 0 hyperbolic, R > 1 inverse hyperbolic. For a two-degree-of-freedom
        subsystem (the isosceles plane) its pair's R is the classical residue."""
        return (1.0 - self.indices) / 2.0


class Motion(NamedTuple):
    """What shows a converged shooting solution is an orbit that goes somewhere and comes
    back, not a start that never left, both measured in the frame turning with the orbit's
    mean rotation theta t / T (a relative periodic orbit closes there)."""

    excursion: float    # max over the period of |q(t) - q(0)| / |q(0)|, q the positions
    turning: float      # the angle the bodies' velocity turns through over a period / 2 pi

    def problem(self, return_error: float, tol: float) -> str:
        """Why this is not a periodic orbit ('' if it is): it must leave its start by far
        more than it misses returning (EXCURSION times the return error, or the
        tolerance), and the velocity of its configuration q(t) must turn through a full
        circle -- a closed curve's total curvature is at least 2 pi (Fenchel's theorem), so
        a velocity that turns less never brings the bodies back."""
        floor = EXCURSION * max(return_error, tol)
        if not self.excursion >= floor:
            return (f"it leaves its start by only {self.excursion:.1e} of its size over the "
                    f"period, less than {EXCURSION:.0e} times its return error "
                    f"({floor:.1e}): the start barely moves in that time (a period below "
                    "the flow's time scale, or a start at rest or in rigid rotation: see "
                    "`python -m survey equilibria`)")
        if not self.turning >= TURNING:
            return (f"its velocity turns through {self.turning:.3f} of a full circle over "
                    "the period; a closed orbit's turns through at least one (Fenchel)")
        return ""


SAMPLES = 4096          # points of the period where both are measured
SHORTEST = 1e3          # a period guess below 1/SHORTEST of the flow's time scale is refused


def motion(system: System, y, period: float, rotation: float, tol: float) -> Motion:
    """The Motion of the orbit from y over `period`, in the frame turning by `rotation`
    over it, from SAMPLES points of the dense output; the velocity is the bodies', p / m
    (less the frame's), where it is not zero (a brake orbit's stops: there it reverses).
    Portable arithmetic: the same bits on every machine, as the rest of a family archive."""
    times = np.linspace(0.0, period, SAMPLES + 1)
    out = integrate(system, y, period, t_eval=times, rtol=tol, atol=tol)
    if not out.ok:
        return Motion(0.0, 0.0)
    ys = out.samples.copy()
    nq = system.n // 2
    ys[:, nq:] /= np.repeat(system.masses, system.dim)      # velocities
    if rotation:      # into the turning frame: less the frame's velocity, rotated back
        rate = rotation / period
        ys[:, nq:] -= rate * linalg.dot(ys[:, :nq], _generator(system)[:nq, :nq].T)
        s, c = portable.vsincos(-rate * times)
        x, z = ys[:, 0::2].copy(), ys[:, 1::2].copy()
        ys[:, 0::2] = c[:, None] * x - s[:, None] * z
        ys[:, 1::2] = s[:, None] * x + c[:, None] * z
    q, v = ys[:, :nq], ys[:, nq:]
    excursion = float(np.max(portable.vnorm(q - q[0]))) / linalg.norm(y[:nq])
    v = v[portable.vnorm(v) > 0]
    if len(v) < 2:
        return Motion(excursion, 0.0)
    u = v / portable.vnorm(v)[:, None]
    # the angle between consecutive directions, 2 atan(|u - v| / |u + v|): exact near 0 and pi
    angles = 2.0 * portable.vatan2(portable.vnorm(u[1:] - u[:-1]),
                                   portable.vnorm(u[1:] + u[:-1]))
    return Motion(excursion, float(portable.vdot(angles, np.ones(angles.size))) / (2 * np.pi))


def rotation(system: System, theta: float) -> np.ndarray:
    """The state-space matrix rotating every position and momentum by theta (the plane)."""
    c, s = portable.cos(theta), portable.sin(theta)
    return np.kron(np.eye(2 * system.n_bodies), np.array([[c, -s], [s, c]]))


def _generator(system: System) -> np.ndarray:
    return np.kron(np.eye(2 * system.n_bodies), np.array([[0.0, -1.0], [1.0, 0.0]]))


def _flow(system: System, y) -> np.ndarray:
    out = np.zeros(system.n)
    rhs(0.0, np.ascontiguousarray(y, dtype=float), out, system.model, 0)
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
    return grad_h, np.concatenate([-linalg.dot(G, p), linalg.dot(G, q)])


def _centre(system: System) -> np.ndarray:
    """Rows whose product with a state is its centre of mass and total momentum."""
    n, d = system.n, system.dim
    nq = n // 2
    m = np.repeat(system.masses, d)
    rows = np.zeros((2 * d, n))
    for k in range(d):
        rows[k, k:nq:d] = m[k::d] / m.sum()
        rows[d + k, nq + k::d] = 1.0
    return rows


def flow_map(system, y, period, tol, tangents=True):
    """(y(T), dy(T)/dy(0)) from the orbit with its full tangent block (or y(T) alone)."""
    if tangents:
        out, phi = flow_jacobian(system, y, period, rtol=tol, atol=tol, control_tangents=True,
                                 renorm_interval=2.0 * abs(period) + 1.0)
    else:
        out = integrate(system, y, period, rtol=tol, atol=tol)
    if not out.ok:
        raise ValueError(f"the orbit from the guess did not reach t = {period:g} "
                         f"({out.status.name.lower()})")
    return (out.y, phi) if tangents else out.y


class _Shooting(NamedTuple):
    """What the shooting equations hold fixed: the orbit returns rotated (`rotating`) or
    not; its energy and, rotating, J (None: that one is the continuation parameter)."""

    rotating: bool
    energy: float | None
    spin: float | None
    tol: float

    def equations(self, system: System, y, T, theta, p=None, tangents=True):
        """(F, A, error, Phi): the residuals -- return, phase, energy, orientation, J,
        centre -- their Jacobian in (y, T[, theta]) and the relative error; Phi the
        monodromy. The phase and orientation rows are local (the correction is orthogonal
        to the flow and to a rotation), so their residual is zero."""
        n, d = system.n, system.dim
        energy = p if self.energy is None else self.energy
        R = rotation(system, theta) if self.rotating else np.eye(n)
        if tangents:
            yT, phi = flow_map(system, y, T, self.tol)
        else:
            yT, phi = flow_map(system, y, T, self.tol, tangents=False), None
        r = yT - linalg.dot(R, y)
        e = float(system.energy(y))
        F = [r, [0.0, e - energy]]
        errors = [linalg.norm(r) / linalg.norm(y), abs(e - energy) / max(abs(energy), 1.0)]
        if d == 2:
            F.append([0.0])
            if self.rotating:
                j, spin = float(system.angular_momentum(y)), p if self.spin is None else self.spin
                F.append([j - spin])
                errors.append(abs(j - spin) / max(abs(spin), 1.0))
        C = _centre(system)
        F.append(linalg.dot(C, y))
        F = np.concatenate(F)
        if not tangents:
            return F, None, max(errors), None
        f0, fT = _flow(system, y), _flow(system, yT)
        grad_h, grad_l = _gradients(system, y)
        cols = [phi - R, fT[:, None]]
        if self.rotating:
            cols.append(-linalg.chain(_generator(system), R, y)[:, None])
        top = np.hstack(cols)
        rows = [f0, grad_h]
        if d == 2:
            rows.append(linalg.dot(_generator(system), y))
            if self.rotating:
                rows.append(grad_l)
        rows += list(C)
        pad = np.zeros((len(rows), top.shape[1] - n))
        A = np.vstack([top, np.hstack([np.array(rows), pad])])
        return F, A, max(errors), phi

    def orbit(self, system: System, y, T, theta, phi, residuals) -> PeriodicOrbit:
        """The converged orbit with its non-trivial multipliers: the monodromy restricted
        to the symplectic complement of the trivial pairs (the flow with the energy, a
        rotation with J, the centre of mass with the momentum)."""
        n, d = system.n, system.dim
        nq = n // 2
        R = rotation(system, theta) if self.rotating else np.eye(n)
        M = linalg.dot(R.T, phi)
        internal = linalg.svd(_centre(system))[1][2 * d:].T
        J = np.block([[np.zeros((nq, nq)), np.eye(nq)], [-np.eye(nq), np.zeros((nq, nq))]])
        known = [linalg.dot(internal.T, _flow(system, y))]
        if d == 2:
            known.append(linalg.chain(internal.T, _generator(system), y))
        Mi = linalg.chain(internal.T, M, internal)
        W = nontrivial_subspace(Mi - np.eye(Mi.shape[0]), known,
                                linalg.chain(internal.T, J, internal))
        mu = linalg.eigvals(linalg.chain(W.T, Mi, W))
        # (by angle, then modulus: a quartet's mu and 1/conj(mu) share their angle but for
        # roundoff, which alone would order them)
        mu = mu[np.lexsort((linalg.modulus(mu), np.round(linalg.argument(mu), 9)))]
        moved = motion(system, y, T, theta if self.rotating else 0.0, self.tol)
        problem = moved.problem(residuals[-1], self.tol)
        if problem:
            raise ValueError(f"not a periodic orbit: {problem}")
        return PeriodicOrbit(y, T, theta, float(system.energy(y)),
                             float(system.angular_momentum(y)) if d == 2 else 0.0,
                             residuals[-1], np.array(residuals), mu, M, moved)


class GuessError(ValueError):
    """A period guess (or start) that no periodic orbit can come from."""


def time_scale(system: System, y) -> float:
    """The flow's own time scale at y: |f| / |Df f|, the time its velocity f takes to turn
    (or change) by its own size; inf where it does not change, 0 at an equilibrium. A
    periodic orbit's velocity turns through at least 2 pi over the period, so the period is
    at least 2 pi times the smallest of these along the orbit."""
    f = _flow(system, y)
    size = linalg.norm(f)
    if not size > 0:
        return 0.0
    h = 1e-6 * linalg.norm(y) / size
    change = linalg.norm(_flow(system, y + h * f) - _flow(system, y - h * f)) / (2 * h)
    return size / change if change > 0 else np.inf


def _converged(error, best, tol) -> bool:
    """At the integrator's tolerance, or no longer falling near it."""
    return error <= 10 * tol or (error >= 0.5 * best and best <= 1e3 * tol)


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
    y = np.array(guess, dtype=float)
    q, p = y[:nq].reshape(-1, d), y[nq:].reshape(-1, d)
    q = q - np.sum(system.masses[:, None] * q, axis=0) / system.masses.sum()
    p = p - system.masses[:, None] * np.sum(p, axis=0) / system.masses.sum()
    y = np.concatenate([q.ravel(), p.ravel()])
    tau = time_scale(system, y)
    if not period * SHORTEST >= tau:
        raise GuessError(
            "the guess is at rest (its velocity and forces vanish): no periodic orbit "
            "passes through it" if tau == 0 else
            f"a period of {period:.3g} is below 1/{SHORTEST:g} of the flow's time scale at the "
            f"guess ({tau:.3g}: the time its velocity takes to change by its own size); a "
            "periodic orbit's velocity turns through a full circle in a period")
    energy = float(system.energy(y)) if energy is None else float(energy)
    shooting = _Shooting(rotating, energy, float(system.angular_momentum(y)) if d == 2
                         else 0.0, tol)
    T, theta = float(period), 0.0
    if rotating:    # the angle that best turns the guess's return onto its start
        yT = flow_map(system, y, T, tol, tangents=False)
        # the angle of sum conj(z0) zT over positions and momenta as z = x + i y
        a, b = y.reshape(-1, 2).T, yT.reshape(-1, 2).T
        theta = float(portable.atan2(linalg.dot(a[0], b[1]) - linalg.dot(a[1], b[0]),
                                     linalg.dot(a[0], b[0]) + linalg.dot(a[1], b[1])))
    residuals = []
    best = np.inf
    for _ in range(max_iter):
        F, A, error, phi = shooting.equations(system, y, T, theta)
        residuals.append(error)
        if _converged(error, best, tol):
            break
        best = min(best, error)
        step = linalg.lstsq(A, -F, 1e-14)
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
    return shooting.orbit(system, y, T, theta, phi, residuals)


def lyapunov_start(system: System, eq: RelativeEquilibrium, mode: int,
                   amplitude: float = 1e-3):
    """(state, period) to start the Lyapunov family of normal mode `mode` (1: the lowest
    frequency of eq.frequencies) of an elliptic relative equilibrium: the equilibrium's
    state displaced along the mode's eigenvector by `amplitude` times its size, and the
    mode's period in the rotating frame. The linearisation is that of H - Omega L in the
    frame rotating with it, which coincides with the inertial one at t = 0; the mode is
    symplectically orthogonal to the rotation, so J moves only at second order -- and that
    second order is taken back by a rigid rotation of the velocities (J changes by its rate
    times I, nothing else of the shape's motion does), so the family runs at the
    equilibrium's J exactly, not at a J the amplitude shifted."""
    f = eq.frequencies
    if not 1 <= mode <= f.size:
        raise ValueError(f"mode {mode}: the equilibrium has {f.size} normal modes on the "
                         f"imaginary axis (1 to {f.size})")
    n, d = system.n, system.dim
    nq = n // 2
    q = eq.positions
    hess = forces(system, q, hessian=True)[1]
    B = np.kron(np.eye(system.n_bodies), np.array([[0.0, 1.0], [-1.0, 0.0]])) if d == 2 \
        else np.zeros((nq, nq))
    S = np.block([[hess, -eq.rotation_rate * B],
                  [-eq.rotation_rate * B.T, np.diag(1.0 / np.repeat(system.masses, d))]])
    J = np.block([[np.zeros((nq, nq)), np.eye(nq)], [-np.eye(nq), np.zeros((nq, nq))]])
    lam, vec = linalg.eig(linalg.dot(J, S))
    k = int(np.argmin(linalg.modulus(lam - 2j * np.pi * f[mode - 1])))
    v = vec[:, k]
    c = v[np.argmax(linalg.modulus(v[:nq]))]
    v = v.real * c.real + v.imag * c.imag     # Re(v conj(c)): phased so that c is real
    size = np.max(np.linalg.norm(q - q.mean(axis=0), axis=1))
    v *= amplitude * size / np.max(np.abs(v[:nq]))
    y = eq.state(system) + v
    if d == 2:
        q, p = system.split(y)
        r = q - (system.masses @ q) / system.masses.sum()
        rate = float(system.angular_momentum(eq.state(system)) - system.angular_momentum(y)) \
            / float(np.sum(system.masses * np.sum(r * r, axis=1)))
        y = system.state(q, p + rate * system.masses[:, None] * np.stack([-r[:, 1], r[:, 0]],
                                                                         axis=1))
    return y, 1.0 / f[mode - 1]


class Family(NamedTuple):
    """A family of periodic orbits along a parameter, and where it bifurcates."""

    parameters: np.ndarray            # the parameter per member
    members: list[PeriodicOrbit]
    bifurcations: list[Bifurcation]   # folds and multipliers leaving or joining the circle
    complete: bool                    # reached the end value
    ended: str                        # if not, why it stopped


def periodic_family(systems: Callable[[float], System], orbit: PeriodicOrbit, p0: float,
                    to: float, steps: int = 20, rotating: bool = False,
                    pinned: str | None = None, tol: float = 1e-13,
                    bisect: float = 1e-9, max_members: int = 1000,
                    on_member: Callable | None = None) -> Family:
    """The family of `orbit` (a periodic orbit of systems(p0)) followed by pseudo-arclength
    continuation (numerics.continuation) from p0 to `to`: p the energy or, for a rotating
    orbit, the angular momentum (`pinned` = "energy" or "angular_momentum": the other one
    held, systems ignores p) or a parameter of the system at fixed energy. Unknowns (y, T[,
    theta], p) scaled by |y|, T, 1 and |to - p0|; a step that moves a stability index by
    more than 0.1 is halved. Folds and changes of the number of multipliers on the unit
    circle are bisected along the arclength to `bisect` of |to - p0| and named. Every
    member is an orbit that moves (Motion) and is checked to be at its label: its energy
    and, rotating, its J are the parameter or the start's, to 1e4 tol."""
    n = orbit.state.size
    extra = 2 if rotating else 1
    if pinned == "angular_momentum" and not rotating:
        raise ValueError("only a rotating orbit is continued in J (a periodic one's J is "
                         "its own)")
    shooting = _Shooting(rotating, None if pinned == "energy" else orbit.energy,
                         None if pinned == "angular_momentum" else orbit.angular_momentum, tol)
    span = abs(to - p0)
    if span == 0:
        raise ValueError("the family's end value equals its start")
    scale = np.concatenate([np.full(n, linalg.norm(orbit.state)), [orbit.period],
                            [1.0] * (extra - 1), [span]])

    def pack(o, p):
        return np.concatenate([o.state, [o.period], [o.rotation] * (extra - 1), [p]]) / scale

    def solve(x, t_row, target, max_iter=10):
        """Newton on the bordered equations from scaled x with the extra row
        t_row . x = target; (orbit, x, A) or None."""
        residuals, best = [], np.inf
        for _ in range(max_iter):
            y, T, p = x[:n] * scale[:n], x[n] * scale[n], x[-1] * scale[-1]
            theta = x[n + 1] if rotating else 0.0
            try:
                system = systems(p)
                F, A, error, phi = shooting.equations(system, y, T, theta, p)
                if pinned:      # its row: energy n + 1, J n + 3 (after the orientation)
                    col = np.zeros(F.size)
                    col[n + 1 if pinned == "energy" else n + 3] = -1.0
                else:
                    h = 1e-7 * max(abs(p), 1.0)
                    col = (shooting.equations(systems(p + h), y, T, theta, p,
                                              tangents=False)[0] - F) / h
            except ValueError:
                return None
            residuals.append(error)
            if on_row(t_row, x, target):    # (a start off the row takes a step first)
                if _converged(error, best, tol):
                    if error > 1e4 * tol:
                        return None
                    try:
                        o = shooting.orbit(system, y, T, theta, phi, residuals)
                    except ValueError:      # not an orbit that moves: no member
                        return None
                    return o, x, np.hstack([A, col[:, None]]) * scale
                if error > 10 * best:
                    return None
                best = min(best, error)
            As = np.hstack([A, col[:, None]]) * scale
            full = np.vstack([As, t_row])
            rhs_ = np.concatenate([-F, [target - linalg.dot(t_row, x)]])
            x = x + linalg.lstsq(full, rhs_, 1e-14)
        return None

    tests = {"fold": lambda o, t: bool(t[-1] > 0), "circle": lambda o, t: o.on_circle}
    branch = follow(solve, pack(orbit, p0), to / scale[-1], steps, tests, lambda o: o.indices,
                    bisect, max_members, margin=index_margins, on_member=on_member)

    def held(p, o):
        """What the member labelled p must have: the energy (p, or the start's) and, for a
        rotating orbit, J (p, or the start's)."""
        out = [("E", o.energy, p if pinned == "energy" else orbit.energy)]
        if rotating:
            out.append(("J", o.angular_momentum,
                        p if pinned == "angular_momentum" else orbit.angular_momentum))
        return out
    values, branch = at_labels(branch, scale[-1], to, held, 1e4 * tol)
    where = {id(o): x[-1] * scale[-1] for o, x, _ in branch.members}
    found = [Bifurcation(float(at.x[-1] * scale[-1]), at.test if at.test in NAMED else
                         _crossing(at.before, at.after), float(at.x[n] * scale[n]),
                         _accuracy(at, where, scale[-1]))
             for at in branch.found]
    return Family(values, [o for o, _, _ in branch.members], found, branch.complete,
                  branch.ended)


def index_margins(orbit: PeriodicOrbit) -> np.ndarray:
    """How far each stability index of an orbit lies inside the band |b| <= 1: 1 - |b| for
    a real index (negative outside), NaN for a complex one (a quartet off the circle)."""
    b = orbit.indices
    return np.where(np.abs(b.imag) <= UNIT_CIRCLE, 1.0 - np.abs(b.real), np.nan)


def _accuracy(at, where: dict, scale: float) -> float:
    """How far a located change may lie from where it is printed: the bisection's last
    bracket, and for an index through +1 or -1 how far the bisected point lies from a
    second, independent estimate -- the zero of b -+ 1 interpolated between the members
    either side, where the indices are known to 1e-12, not within the 1e-8 a colliding
    pair leaves them at the crossing, where the bisection reads their sign. Elsewhere
    (a quartet) the indices' own error over their slope. Never below the corrector's
    tolerance, 1e-12 of the parameter."""
    p = at.x[-1] * scale
    bracket = max(at.width * abs(scale), 1e-12 * abs(p))     # the corrector's tolerance
    if at.test in NAMED or id(at.before) not in where or id(at.after) not in where:
        return float(bracket)
    p0, p1 = where[id(at.before)], where[id(at.after)]
    a, b = at.before.indices, at.after.indices
    if a.size == b.size:
        real = (np.abs(a.imag) <= UNIT_CIRCLE) & (np.abs(b.imag) <= UNIT_CIRCLE)
        for edge in (1.0, -1.0):
            cross = real & ((a.real - edge) * (b.real - edge) < 0)
            if cross.any():
                k = int(np.flatnonzero(cross)[0])
                guess = p0 + (edge - a[k].real) * (p1 - p0) / (b[k].real - a[k].real)
                return float(max(bracket, abs(p - guess)))
    slope = float(np.max(np.abs(b - a))) / abs(p1 - p0) if a.size == b.size and p1 != p0 \
        else 0.0
    if at.near is None or slope == 0.0:
        return float(bracket)
    return float(max(bracket, at.near.index_error / slope))


def _crossing(a: PeriodicOrbit, b: PeriodicOrbit) -> str:
    """How multipliers leave (or join) the unit circle between members a and b: the kind
    of stability index off the band |b| <= 1 that one has more of than the other -- a
    complex index (a quartet: a Krein collision), b > 1 (a pair through +1) or b < -1
    (through -1: period doubling). The members, not the bisection's last orbits, decide:
    right at the point the multipliers are a double eigenvalue, known to sqrt(eps)."""
    def counts(o):
        idx = o.indices
        real = np.abs(idx.imag) <= UNIT_CIRCLE
        return np.array([np.sum(~real), np.sum(real & (idx.real > 1)),
                         np.sum(real & (idx.real < -1))])
    more = np.abs(counts(a) - counts(b))
    return ["Krein collision (complex quartet)", "through +1",
            "period doubling (through -1)"][int(np.argmax(more))]
