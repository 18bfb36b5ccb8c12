"""A system of N bodies: its state layout, the arguments every compiled kernel takes, the
right-hand side with its variational equations, and its conserved quantities.

State layout (flat float64 array): positions q (N*d, body-major), momenta p (N*d); then,
for each tangent vector, its (dq, dp) block of the same size n = 2*N*d.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba.extending import overload

from ..catalog import defaults
from .forces import (
    areal_forces,
    atm_energy,
    atm_forces,
    norm,
    pair_forces,
    perimetric_forces,
    profile,
    sub,
    triplet_measure,
    vec,
)
from .geometry import cross
from .jit import helper, kernel, leaf
from .terms import AREA, DISTANCE, NONE, PERIMETER, TRIANGLE, Potential, make_potential


@dataclass(frozen=True, eq=False)
class System:
    """N >= 3 bodies of positive masses in d = 2 or 3 dimensions, whose potential is a sum
    of terms (`Potential`s, or one of them): triplet potentials summed over all triangles
    i < j < k, pair potentials over all pairs i < j."""

    masses: np.ndarray
    dim: int = 2
    terms: tuple[Potential, ...] = field(
        default_factory=lambda: (make_potential(defaults.POTENTIAL),))

    def __post_init__(self):
        m = np.ascontiguousarray(self.masses, dtype=np.float64)
        if m.ndim != 1 or m.size < 3:
            raise ValueError("a triplet system needs masses for N >= 3 bodies")
        if not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise ValueError("masses must be finite and > 0")
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {self.dim!r}")
        terms = (self.terms,) if isinstance(self.terms, Potential) else tuple(self.terms)
        if not terms or not all(isinstance(t, Potential) for t in terms):
            raise ValueError("a system's terms are one or more Potentials (make_potential)")
        m.setflags(write=False)
        object.__setattr__(self, "masses", m)
        object.__setattr__(self, "terms", terms)
        object.__setattr__(self, "_par", _encode(terms))

    @classmethod
    def create(cls, masses=(1.0, 1.0, 1.0), dim=defaults.DIM, potential=defaults.POTENTIAL,
               **params):
        return cls(np.asarray(masses, dtype=np.float64), dim, make_potential(potential, params))

    @property
    def is_paper_kind(self) -> bool:
        """One perimetric or areal triplet term, as in the paper: its closed forms apply."""
        return len(self.terms) == 1 and self.terms[0].measure in (PERIMETER, AREA)

    @property
    def potential(self) -> Potential:
        """The system's one perimetric or areal triplet term, for the features that are
        built on the paper's closed forms (e.g. U'(P) of a rotating solution)."""
        if not self.is_paper_kind:
            raise ValueError("this needs a system of one perimetric or areal triplet "
                             "potential; the system is " + self.describe())
        return self.terms[0]

    def describe(self) -> str:
        return " + ".join(t.describe() for t in self.terms)

    @property
    def n_bodies(self) -> int:
        return self.masses.size

    @property
    def n(self) -> int:
        """Size of the phase-space state (2 N d)."""
        return 2 * self.n_bodies * self.dim

    @property
    def kernel_args(self):
        """The arguments every compiled kernel takes to describe the system: masses, d, the
        measure and profile codes of the leading perimetric or areal term (NONE if there is
        none) and `par` (see _encode). Fresh writable arrays: a read-only array is another
        numba type, which would compile every kernel a second time."""
        lead = self.terms[0]
        codes = (lead.measure, lead.profile) if lead.measure in (PERIMETER, AREA) else (NONE, 0)
        return self.masses.copy(), self.dim, *codes, self._par.copy()

    def state(self, positions, momenta) -> np.ndarray:
        """Flat state from positions and momenta of shape (N, d)."""
        q = np.asarray(positions, dtype=np.float64).reshape(self.n_bodies, self.dim)
        p = np.asarray(momenta, dtype=np.float64).reshape(self.n_bodies, self.dim)
        return np.concatenate([q.ravel(), p.ravel()])

    def split(self, y):
        """Positions and momenta of shape (..., N, d) from states of shape (..., >= n)."""
        y = np.asarray(y, dtype=np.float64)
        nq = self.n // 2
        shape = y.shape[:-1] + (self.n_bodies, self.dim)
        return y[..., :nq].reshape(shape), y[..., nq:2 * nq].reshape(shape)

    # -------------------------------------------------------- conserved quantities
    def energy(self, y):
        """Total energy H = K + U of states (..., n)."""
        return self.kinetic_energy(y) + self.potential_energy(y)

    def potential_energy(self, y):
        """Sum over triplets of U, for states (..., n)."""
        q, _ = self.split(y)
        flat = np.ascontiguousarray(q.reshape(-1, self.n // 2))
        _, d, measure, prof, par = self.kernel_args
        u = _potential_energies(flat, self.n_bodies, d, measure, prof, par)
        return u.reshape(q.shape[:-2])

    def kinetic_energy(self, y):
        _, p = self.split(y)
        return 0.5 * np.sum(np.sum(p * p, axis=-1) / self.masses, axis=-1)

    def momentum(self, y):
        """Total momentum, shape (..., d)."""
        return self.split(y)[1].sum(axis=-2)

    def angular_momentum(self, y):
        """Total angular momentum about the origin: scalar in 2-D, vector in 3-D."""
        q, p = self.split(y)
        return cross(q, p).sum(axis=-1 if self.dim == 2 else -2)

    def centre_of_mass(self, y):
        q, _ = self.split(y)
        return np.einsum("...id,i->...d", q, self.masses) / self.masses.sum()

    def moment_of_inertia(self, y):
        """Moment of inertia about the centre of mass, sum m_i |r_i - R|^2."""
        q, _ = self.split(y)
        r = q - self.centre_of_mass(y)[..., None, :]
        return np.einsum("...id,...id,i->...", r, r, self.masses)

    def triangle(self, y, triplet=(0, 1, 2)):
        """Positions (u, v, w) of one triplet, each of shape (..., d)."""
        q, _ = self.split(y)
        return tuple(q[..., b, :] for b in triplet)


def _encode(terms) -> np.ndarray:
    """The kernels' `par`. A single perimetric or areal term (the paper's systems): its two
    parameters, a 1-D array. Otherwise a 2-D array: row 0 the two parameters of the leading
    perimetric or areal term (zeros if there is none), then one row (measure, profile, p0,
    p1) per further term. The kernels are compiled separately for the two array types, so
    the paper's systems run code in which the further terms do not exist."""
    lead = terms[0] if terms[0].measure in (PERIMETER, AREA) else None
    if lead is not None and len(terms) == 1:
        return lead.par
    rows = [list(lead.par) + [0.0, 0.0] if lead is not None else [0.0] * 4]
    for term in terms[1:] if lead is not None else terms:
        p = term.par
        rows.append([term.measure, term.profile, p[0], p[1] if p.size > 1 else 0.0])
    return np.array(rows, dtype=np.float64)


def lead_params(par):
    """The two parameters of the leading perimetric or areal term (see _encode)."""


def further_forces(y, dy, N, d, n, n_tan, par):
    """Forces of the terms after the leading one (see _encode)."""


def further_energy(q, N, d, par):
    """Energy of the terms after the leading one (see _encode)."""


# typed at compile time on par's dimension: for a 1-D par the further terms compile to
# nothing (a call to a kernel that is never taken still cost the paper's systems 8%)
@overload(lead_params, jit_options=dict(error_model="numpy"), inline="always")
def _lead_params(par):
    # a pair of floats, not a view: a kernel without reference counting (jit.leaf) may
    # not return an array it did not receive
    if par.ndim == 1:
        return lambda par: (par[0], par[1])
    return lambda par: (par[0, 0], par[0, 1])


@overload(further_forces, jit_options=dict(error_model="numpy"), inline="always")
def _further_forces(y, dy, N, d, n, n_tan, par):
    if par.ndim == 1:
        return lambda y, dy, N, d, n, n_tan, par: None
    return _rows_forces


@overload(further_energy, jit_options=dict(error_model="numpy"), inline="always")
def _further_energy(q, N, d, par):
    if par.ndim == 1:
        return lambda q, N, d, par: 0.0
    return _rows_energy


@kernel
def _potential_energies(qs, N, d, measure, prof, par):
    out = np.empty(qs.shape[0])
    for s in range(qs.shape[0]):
        out[s] = potential_energy(qs[s], N, d, measure, prof, par)
    return out


@leaf
def potential_energy(q, N, d, measure, prof, par):
    """Sum over the terms of U summed over triplets i < j < k or pairs i < j."""
    total = further_energy(q, N, d, par)
    if measure != NONE:
        total += _triplet_energy(q, N, d, measure, prof, lead_params(par))
    return total


def _rows_energy(q, N, d, par):
    total = 0.0
    for row in range(1, par.shape[0]):
        kind, code, p = int(par[row, 0]), int(par[row, 1]), par[row, 2:]
        if kind == DISTANCE:
            for i in range(N - 1):
                for j in range(i + 1, N):
                    total += profile(code, p, norm(sub(vec(q, j * d, d), vec(q, i * d, d))))[0]
        elif kind == TRIANGLE:
            for i in range(N - 2):
                for j in range(i + 1, N - 1):
                    for k in range(j + 1, N):
                        total += atm_energy(vec(q, i * d, d), vec(q, j * d, d),
                                            vec(q, k * d, d), p[0])
        else:
            total += _triplet_energy(q, N, d, kind, code, p)
    return total


@leaf
def _triplet_energy(q, N, d, measure, prof, par):
    total = 0.0
    for i in range(N - 2):
        for j in range(i + 1, N - 1):
            for k in range(j + 1, N):
                total += profile(prof, par, triplet_measure(q, i, j, k, d, measure))[0]
    return total


@leaf
def rhs(t, y, dy, masses, d, measure, prof, par, n_tan):
    """Hamilton's equations and the variational equations of n_tan tangent vectors
    (d dq/dt = M^-1 dp, d dp/dt = -Hess U dq)."""
    N = masses.size
    lead = lead_params(par)
    # three bodies in the plane (every workflow, most of the paper) under a perimetric or
    # areal term run code written for them: the general path's operations on the same
    # values in the same order, without its loops, zero z components and accumulations
    # (bit for bit the same, 2.3x faster; tests/physics/test_system.py)
    if N == 3 and d == 2 and measure == PERIMETER:
        _planar_perimetric(y, dy, masses, prof, lead, n_tan)
    elif N == 3 and d == 2 and measure == AREA:
        _planar_areal(y, dy, masses, prof, lead, n_tan)
    else:
        _leading_forces(y, dy, masses, N, d, measure, prof, lead, n_tan)
    further_forces(y, dy, N, d, 2 * N * d, n_tan, par)


@helper
def _planar_velocities(y, dy, masses, n_tan):
    """dq/dt = p/m of the orbit and d dq/dt = dp/m of each tangent vector, three bodies in
    the plane."""
    i0, i1, i2 = 1.0 / masses[0], 1.0 / masses[1], 1.0 / masses[2]
    for t in range(1 + n_tan):
        b = 12 * t
        dy[b], dy[b + 1] = y[b + 6] * i0, y[b + 7] * i0
        dy[b + 2], dy[b + 3] = y[b + 8] * i1, y[b + 9] * i1
        dy[b + 4], dy[b + 5] = y[b + 10] * i2, y[b + 11] * i2


@helper
def _planar_perimetric(y, dy, masses, prof, par, n_tan):
    """forces.perimetric_forces of bodies (0, 1, 2) in the plane, and the velocities. The
    leading `0.0 +` of each force keeps the general path's zero signs (it adds into
    zeros)."""
    _planar_velocities(y, dy, masses, n_tan)
    ax, ay = y[2] - y[0], y[3] - y[1]          # side vectors v - u, w - v, u - w
    bx, by = y[4] - y[2], y[5] - y[3]
    cx, cy = y[0] - y[4], y[1] - y[5]
    L1 = math.sqrt(ax * ax + ay * ay)
    L2 = math.sqrt(bx * bx + by * by)
    L3 = math.sqrt(cx * cx + cy * cy)
    r1, r2, r3 = 1.0 / L1, 1.0 / L2, 1.0 / L3
    e1x, e1y = ax * r1, ay * r1
    e2x, e2y = bx * r2, by * r2
    e3x, e3y = cx * r3, cy * r3
    _, U1, U2 = profile(prof, par, L1 + L2 + L3)
    dy[6] = 0.0 + U1 * (e1x - e3x)
    dy[7] = 0.0 + U1 * (e1y - e3y)
    dy[8] = 0.0 + U1 * (e2x - e1x)
    dy[9] = 0.0 + U1 * (e2y - e1y)
    dy[10] = 0.0 + U1 * (e3x - e2x)
    dy[11] = 0.0 + U1 * (e3y - e2y)
    s1, s2, s3 = U1 / L1, U1 / L2, U1 / L3
    for t in range(n_tan):
        b = 12 * (1 + t)
        p1x, p1y = y[b + 2] - y[b], y[b + 3] - y[b + 1]
        p2x, p2y = y[b + 4] - y[b + 2], y[b + 5] - y[b + 3]
        p3x, p3y = y[b] - y[b + 4], y[b + 1] - y[b + 5]
        d1 = e1x * p1x + e1y * p1y
        d2 = e2x * p2x + e2y * p2y
        d3 = e3x * p3x + e3y * p3y
        dP = d1 + d2 + d3
        c1, c2, c3 = U2 * dP - s1 * d1, U2 * dP - s2 * d2, U2 * dP - s3 * d3
        g1x, g1y = c1 * e1x + s1 * p1x, c1 * e1y + s1 * p1y
        g2x, g2y = c2 * e2x + s2 * p2x, c2 * e2y + s2 * p2y
        g3x, g3y = c3 * e3x + s3 * p3x, c3 * e3y + s3 * p3y
        dy[b + 6] = 0.0 + (g1x - g3x)
        dy[b + 7] = 0.0 + (g1y - g3y)
        dy[b + 8] = 0.0 + (g2x - g1x)
        dy[b + 9] = 0.0 + (g2y - g1y)
        dy[b + 10] = 0.0 + (g3x - g2x)
        dy[b + 11] = 0.0 + (g3y - g2y)


@helper
def _planar_areal(y, dy, masses, prof, par, n_tan):
    """forces.areal_forces of bodies (0, 1, 2) in the plane, and the velocities: the area
    vector and its unit vector have only z components there."""
    _planar_velocities(y, dy, masses, n_tan)
    ax, ay = y[2] - y[0], y[3] - y[1]          # v - u
    bx, by = y[4] - y[0], y[5] - y[1]          # w - u
    Az = 0.5 * (ax * by - ay * bx)
    absA = math.sqrt(Az * Az)
    inv = 1.0 / absA if absA > 0.0 else 0.0
    hz = Az * inv
    _, U1, U2 = profile(prof, par, absA)
    svx, svy = y[2] - y[4], y[3] - y[5]        # v - w, w - u, u - v
    swx, swy = y[4] - y[0], y[5] - y[1]
    sux, suy = y[0] - y[2], y[1] - y[3]
    Gux, Guy = svy * hz, -(svx * hz)           # (v - w) x Ahat: twice grad_u |A|
    Gvx, Gvy = swy * hz, -(swx * hz)
    Gwx, Gwy = suy * hz, -(sux * hz)
    f = -0.5 * U1
    dy[6], dy[7] = 0.0 + f * Gux, 0.0 + f * Guy
    dy[8], dy[9] = 0.0 + f * Gvx, 0.0 + f * Gvy
    dy[10], dy[11] = 0.0 + f * Gwx, 0.0 + f * Gwy
    for t in range(n_tan):
        o = 12 * (1 + t)
        dux, duy = y[o], y[o + 1]
        dvx, dvy = y[o + 2], y[o + 3]
        dwx, dwy = y[o + 4], y[o + 5]
        dAz = 0.5 * ((dux * svy - duy * svx) + (dvx * swy - dvy * swx)
                     + (dwx * suy - dwy * sux))
        dabs = hz * dAz
        dhz = (-dabs * inv) * hz + dAz * inv
        a = -0.5 * U2 * dabs
        dy[o + 6] = (0.0 + a * Gux) + f * ((dvy - dwy) * hz + svy * dhz)
        dy[o + 7] = (0.0 + a * Guy) + f * (-((dvx - dwx) * hz) + -(svx * dhz))
        dy[o + 8] = (0.0 + a * Gvx) + f * ((dwy - duy) * hz + swy * dhz)
        dy[o + 9] = (0.0 + a * Gvy) + f * (-((dwx - dux) * hz) + -(swx * dhz))
        dy[o + 10] = (0.0 + a * Gwx) + f * ((duy - dvy) * hz + suy * dhz)
        dy[o + 11] = (0.0 + a * Gwy) + f * (-((dux - dvx) * hz) + -(sux * dhz))


@helper
def _leading_forces(y, dy, masses, N, d, measure, prof, lead, n_tan):
    """Velocities, and the forces of the leading perimetric or areal term. The measure is
    chosen outside the triplet loop: one branch per call, not per triplet, keeps the loop
    body small enough for the compiler (2.6x faster)."""
    nq = N * d
    n = 2 * nq
    for t_ in range(1 + n_tan):
        base = n * t_
        for b in range(N):
            inv = 1.0 / masses[b]
            for c in range(base + b * d, base + b * d + d):
                dy[c] = y[nq + c] * inv
        for c in range(base + nq, base + n):
            dy[c] = 0.0
    if measure == PERIMETER:
        for i in range(N - 2):
            for j in range(i + 1, N - 1):
                for k in range(j + 1, N):
                    perimetric_forces(y, dy, i, j, k, d, n, n_tan, prof, lead)
    elif measure == AREA:
        for i in range(N - 2):
            for j in range(i + 1, N - 1):
                for k in range(j + 1, N):
                    areal_forces(y, dy, i, j, k, d, n, n_tan, prof, lead)


def _rows_forces(y, dy, N, d, n, n_tan, par):
    for row in range(1, par.shape[0]):
        kind, code, p = int(par[row, 0]), int(par[row, 1]), par[row, 2:]
        if kind == DISTANCE:
            for i in range(N - 1):
                for j in range(i + 1, N):
                    pair_forces(y, dy, i, j, d, n, n_tan, code, p)
        elif kind == TRIANGLE:
            for i in range(N - 2):
                for j in range(i + 1, N - 1):
                    for k in range(j + 1, N):
                        atm_forces(y, dy, i, j, k, d, n, n_tan, p)
        elif kind == PERIMETER:
            for i in range(N - 2):
                for j in range(i + 1, N - 1):
                    for k in range(j + 1, N):
                        perimetric_forces(y, dy, i, j, k, d, n, n_tan, code, p)
        else:
            for i in range(N - 2):
                for j in range(i + 1, N - 1):
                    for k in range(j + 1, N):
                        areal_forces(y, dy, i, j, k, d, n, n_tan, code, p)
