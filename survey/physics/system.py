"""A system of N bodies: its state layout, the arguments every compiled kernel takes, the
right-hand side of one state with its variational equations (physics.lanes: of many at
once), and its conserved quantities.

State layout (flat float64 array): positions q (N*d, body-major), momenta p (N*d); then,
for each tangent vector, its (dq, dp) block of the same size n = 2*N*d.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numba import types
from numba.extending import overload

from ..catalog import defaults
from .forces import (
    areal_forces,
    atm_energy,
    atm_forces,
    expression_profile,
    external_forces,
    sides_forces,
    norm,
    pair_forces,
    perimetric_forces,
    profile,
    reciprocals,
    sub,
    triplet_measure,
    vec,
)
from .geometry import cross
from ..machine.portable import power, vnorm
from ..machine.jit import helper, kernel, leaf
from .expressions import Programs, output, pack, run_program, term_program
from .terms import (
    AREA,
    DISTANCE,
    EXPRESSION,
    GIVEN,
    NONE,
    PERIMETER,
    POSITION,
    SIDES,
    TRIANGLE,
    Potential,
    make_potential,
)


class Model(NamedTuple):
    """The system as every kernel takes it (`System.model`): masses, dimension, the leading
    perimetric or areal term's measure and profile codes (NONE if there is none), the
    terms' parameters (`_encode`) and the programs of its formulas (their registers the
    kernels' scratch: a Model is one thread's)."""

    masses: np.ndarray
    d: int
    measure: int
    prof: int
    par: np.ndarray
    expr: Programs | None       # the programs of the terms written as formulas (None:
    #                             none, and a type of its own: their code is not compiled)
    areal: bool | None          # True where the leading term is areal, else None: a type
    #                             of its own, so three bodies in the plane compile the
    #                             lanes' loops of their own term alone (_planar_lanes)


@dataclass(frozen=True, eq=False)
class System:
    """N bodies of positive masses in d = 2 or 3 dimensions, whose potential is a sum of
    terms (`Potential`s, or one of them): triplet potentials summed over all triangles
    i < j < k, pair potentials over all pairs i < j (weighted by m_i m_j where the term says
    so). N >= 3, or N >= 2 for pair terms alone (a Kepler problem)."""

    masses: np.ndarray
    dim: int = 2
    terms: tuple[Potential, ...] = field(
        default_factory=lambda: (make_potential(defaults.POTENTIAL),))

    def __post_init__(self):
        m = np.ascontiguousarray(self.masses, dtype=np.float64)
        terms = (self.terms,) if isinstance(self.terms, Potential) else tuple(self.terms)
        if not terms or not all(isinstance(t, Potential) for t in terms):
            raise ValueError("a system's terms are one or more Potentials (make_potential)")
        kinds = {t.kind for t in terms}
        fewest = 3 if "triplet" in kinds else 2 if "pair" in kinds else 1
        if m.ndim != 1 or m.size < fewest:
            raise ValueError("a system " + {3: "with a triplet term ", 2: "of pair terms ",
                                            1: ""}[fewest]
                             + f"needs masses for N >= {fewest} bodies")
        if not np.all(np.isfinite(m)) or np.any(m <= 0):
            raise ValueError("masses must be finite and > 0")
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {self.dim!r}")
        m.setflags(write=False)
        object.__setattr__(self, "masses", m)
        object.__setattr__(self, "terms", terms)
        object.__setattr__(self, "_par", _encode(terms, m.size, self.dim))
        programs = [term_program(t.kind, t.expression, t.variables, t.param_names, t.params)
                    for t in terms if t.profile == EXPRESSION]
        object.__setattr__(self, "_programs", pack(programs) if programs else None)

    @classmethod
    def create(cls, masses=(1.0, 1.0, 1.0), dim=defaults.DIM, potential=defaults.POTENTIAL,
               **params):
        return cls(np.asarray(masses, dtype=np.float64), dim, make_potential(potential, params))

    @property
    def is_paper_kind(self) -> bool:
        """One built-in perimetric or areal triplet term, as in the paper: its closed forms
        apply (a formula's profile is its program's, found by the general path)."""
        return len(self.terms) == 1 and _leads(self.terms[0])

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
    def translation_invariant(self) -> bool:
        """Whether moving every body alike leaves the potential alone (no external field):
        then the centre of mass moves freely, and deviations along it or its momentum
        never grow."""
        return all(t.measure != POSITION for t in self.terms)

    @property
    def n_bodies(self) -> int:
        return self.masses.size

    @property
    def n(self) -> int:
        """Size of the phase-space state (2 N d)."""
        return 2 * self.n_bodies * self.dim

    @property
    def model(self) -> "Model":
        """The system as every compiled kernel takes it (`Model`). Fresh writable arrays: a
        read-only array is another numba type, which would compile every kernel a second
        time."""
        lead = self.terms[0]
        codes = (lead.measure, lead.profile) if _leads(lead) else (NONE, 0)
        X = self._programs
        return Model(masses=self.masses.copy(), d=self.dim, measure=codes[0], prof=codes[1],
                     par=self._par.copy(),
                     expr=None if X is None else X._replace(regs=X.regs.copy()),
                     areal=True if codes[0] == AREA else None)

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
        u = _potential_energies(flat, self.model)
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
        return centre_of_mass(self.masses, self.split(y)[0])

    @property
    def homogeneity(self) -> float | None:
        """The degree k of a potential homogeneous in the positions (every term of the same
        degree), or None."""
        degrees = {t.degree for t in self.terms}
        return degrees.pop() if len(degrees) == 1 else None

    def scale_free_energy(self, y) -> float:
        """E |J|^(-2k/(k+2)) for a potential homogeneous of degree k (k != -2; else NaN, as
        where J = 0): q -> s q, p -> s^(k/2) p, t -> s^(1-k/2) t maps orbits to orbits with
        E -> s^k E and J -> s^(1+k/2) J, so the shapes' dynamics depends on E and J only
        through this combination -- an energy axis at other J is not a new parameter.
        Powers by portable.power: the same bits on every machine."""
        k = self.homogeneity
        J = self.angular_momentum(y)
        J = float(abs(J)) if self.dim == 2 else float(vnorm(np.asarray(J, dtype=float)))
        if k is None or k == -2.0 or not J > 0.0:
            return math.nan
        return float(self.energy(y)) * float(power(J, -2.0 * k / (k + 2.0)))

    def moment_of_inertia(self, y):
        """Moment of inertia about the centre of mass, sum m_i |r_i - R|^2."""
        y = np.asarray(y, dtype=np.float64)
        rows = np.ascontiguousarray(y.reshape(-1, y.shape[-1]))
        out = np.empty(rows.shape[0])
        _inertia_rows(rows, self.masses, self.dim, out)
        return out.reshape(y.shape[:-1]) if y.ndim > 1 else out[0]

    def triangle(self, y, triplet=(0, 1, 2)):
        """Positions (u, v, w) of one triplet, each of shape (..., d)."""
        q, _ = self.split(y)
        return tuple(q[..., b, :] for b in triplet)


def centre_of_mass(masses: np.ndarray, q: np.ndarray) -> np.ndarray:
    """sum m_i q_i / sum m_i of positions (..., N, d)."""
    return weighted_sum(masses, q) / masses.sum()


@kernel
def _inertia_rows(y, masses, d, out):
    """sum m_i |q_i - R|^2 of states y (M, n) into out: R = `centre_of_mass`, and the sums
    over bodies and components in the order and from the start the array formulas have
    (weighted_sum body by body; a sum over components from 0.0), so the same bits."""
    N = masses.size
    total_mass = 0.0
    for i in range(N):
        total_mass += masses[i]
    R = np.empty(d)
    for r in range(y.shape[0]):
        for c in range(d):
            t = masses[0] * y[r, c]
            for i in range(1, N):
                t = t + masses[i] * y[r, i * d + c]
            R[c] = t / total_mass
        total = 0.0
        for i in range(N):
            rr = 0.0
            for c in range(d):
                x = y[r, i * d + c] - R[c]
                rr += x * x
            total = masses[0] * rr if i == 0 else total + masses[i] * rr
        out[r] = total


def weighted_sum(weights: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_i w_i x_i over the body axis of x (..., N, d), summed body by body in order: a
    matrix product or einsum would sum in the order, and with the fused multiply-adds,
    that the CPU's BLAS or SIMD loops choose, and a chaotic orbit amplifies the last bit.
    (Also faster than numpy's reduction over a short middle axis.)"""
    total = weights[0] * x[..., 0, :]
    for i in range(1, len(weights)):
        total = total + weights[i] * x[..., i, :]
    return total


def _leads(term) -> bool:
    """Whether a term can be a system's leading perimetric or areal term (a formula
    never is: its forces run with the further terms')."""
    return term.measure in (PERIMETER, AREA) and term.profile != EXPRESSION


def _encode(terms, N: int, d: int) -> np.ndarray:
    """The kernels' `par`. Three bodies in the plane under a single perimetric or areal
    term (the paper's systems): its two parameters, a 1-D array. Otherwise a 2-D array: row
    0 the two parameters of the leading perimetric or areal term (zeros if there is none),
    then one row (measure, profile, weighted, p0, p1) per further term, weighted 1 for a
    pair term multiplied by m_i m_j. The kernels are compiled separately for the two array
    types, so the paper's systems run -- and a first run compiles -- code in which neither
    the general N-body path nor the further terms exist (a shorter cold start). A term
    written as a formula has the row (measure, EXPRESSION, weighted, its program's index,
    0)."""
    lead = terms[0] if _leads(terms[0]) else None
    if lead is not None and len(terms) == 1 and N == 3 and d == 2:
        return lead.par
    rows = [list(lead.par) + [0.0] * 3 if lead is not None else [0.0] * 5]
    programs = 0
    for term in terms[1:] if lead is not None else terms:
        p = term.par
        if term.profile == EXPRESSION:
            p, programs = np.array([programs, 0.0]), programs + 1
        rows.append([term.measure, term.profile, float(term.mass_weighted), p[0],
                     p[1] if p.size > 1 else 0.0])
    return np.array(rows, dtype=np.float64)


def lead_params(par):
    """The two parameters of the leading perimetric or areal term (see _encode)."""


@helper
def _term_params(par, row):
    """The two parameters of a further term (par's row `row`), a pair of floats as
    lead_params gives the leading term's: the term kernels are compiled once for both (a
    view of the row compiled a second copy of each into a first run of such a system)."""
    return par[row, 3], par[row, 4]


def velocities_and_forces(y, dy, model, n_tan):
    """dq/dt, dp/dt and the tangent blocks of `rhs` (see _encode)."""


def further_energy(q, masses, d, par, X):
    """Energy of the terms after the leading one (see _encode)."""


# typed at compile time on par's dimension: for a 1-D par the general path and the further
# terms compile to nothing (a call to a kernel that is never taken still cost the paper's
# systems 8%), and for a 2-D par the code written for the paper's systems
@overload(lead_params, jit_options=dict(error_model="numpy"), inline="always")
def _lead_params(par):
    # a pair of floats, not a view: a kernel without reference counting (jit.leaf) may
    # not return an array it did not receive
    if par.ndim == 1:
        return lambda par: (par[0], par[1])
    return lambda par: (par[0, 0], par[0, 1])


def par_type(model):
    """The numba type of a Model's par (typed: the kernels' choice of paths)."""
    return model.types[Model._fields.index("par")]


def areal_type(model) -> bool:
    """Whether a Model's type is that of a leading areal term (`Model.areal`)."""
    return not isinstance(model.types[Model._fields.index("areal")], types.NoneType)


@overload(velocities_and_forces, jit_options=dict(error_model="numpy"), inline="always")
def _velocities_and_forces(y, dy, model, n_tan):
    if par_type(model).ndim == 1:
        return lambda y, dy, model, n_tan: _planar_forces(y, dy, model, n_tan)
    return lambda y, dy, model, n_tan: _general_forces(y, dy, model, n_tan)


@overload(further_energy, jit_options=dict(error_model="numpy"), inline="always")
def _further_energy(q, masses, d, par, X):
    if par.ndim == 1:
        return lambda q, masses, d, par, X: 0.0
    return _rows_energy


@kernel
def _potential_energies(qs, model):
    out = np.empty(qs.shape[0])
    for s in range(qs.shape[0]):
        out[s] = potential_energy(qs[s], model)
    return out


@leaf
def potential_energy(q, model):
    """Sum over the terms of U summed over triplets i < j < k or pairs i < j."""
    masses, d, measure, prof, par, X = model.masses, model.d, model.measure, model.prof, \
        model.par, model.expr
    N = masses.size
    total = further_energy(q, masses, d, par, X)
    if measure != NONE:
        total += _triplet_energy(q, N, d, measure, prof, lead_params(par))
    return total


@leaf
def _planar_forces(y, dy, model, n_tan):
    """Three bodies in the plane under one perimetric or areal term (every workflow, most
    of the paper) run code written for them: the general path's operations on the same
    values in the same order, without its loops, zero z components and accumulations (bit
    for bit the same, and faster: `bench --only terms`; tests/physics/test_system.py)."""
    masses, measure, prof, par = model.masses, model.measure, model.prof, model.par
    if measure == PERIMETER:
        _planar_perimetric(y, dy, masses, prof, (par[0], par[1]), n_tan)
    else:
        _planar_areal(y, dy, masses, prof, (par[0], par[1]), n_tan)


@helper
def _general_forces(y, dy, model, n_tan):
    """Any other system: the leading perimetric or areal term, then the further terms."""
    masses, d, measure, prof, par, X = model.masses, model.d, model.measure, model.prof, \
        model.par, model.expr
    N = masses.size
    _leading_forces(y, dy, masses, N, d, measure, prof, (par[0, 0], par[0, 1]), n_tan)
    _rows_forces(y, dy, masses, d, 2 * N * d, n_tan, par, X)


def _rows_energy(q, masses, d, par, X):
    N = masses.size
    total = 0.0
    for row in range(1, par.shape[0]):
        kind, code, weighted = int(par[row, 0]), int(par[row, 1]), par[row, 2]
        p = _term_params(par, row)
        if code == EXPRESSION:
            total += formula_energy(q, masses, d, kind, weighted, X, int(p[0]))
        elif kind == DISTANCE:
            for i in range(N - 1):
                for j in range(i + 1, N):
                    u = profile(code, p, norm(sub(vec(q, j * d, d), vec(q, i * d, d))))[0]
                    total += masses[i] * masses[j] * u if weighted != 0.0 else u
        elif kind == TRIANGLE:
            for i in range(N - 2):
                for j in range(i + 1, N - 1):
                    for k in range(j + 1, N):
                        total += atm_energy(vec(q, i * d, d), vec(q, j * d, d),
                                            vec(q, k * d, d), p[0])
        else:
            total += _triplet_energy(q, N, d, kind, code, p)
    return total


def formula_energy(q, masses, d, kind, weighted, X, t):
    """`_formula_energy`, or 0 where the system has no formulas (X None)."""


def formula_forces(y, dy, masses, d, n, n_tan, kind, weighted, X, t):
    """`_formula_forces`, or nothing where the system has no formulas (X None)."""


# typed on X: a system without formulas (Model.expr None) compiles none of their code (the
# programs' functions cost a general system's cold start some twenty seconds)
@overload(formula_energy, jit_options=dict(error_model="numpy"), inline="always")
def _formula_energy_overload(q, masses, d, kind, weighted, X, t):
    if isinstance(X, types.NoneType):
        return lambda q, masses, d, kind, weighted, X, t: 0.0
    return lambda q, masses, d, kind, weighted, X, t: _formula_energy(
        q, masses, d, kind, weighted, X, t)


@overload(formula_forces, jit_options=dict(error_model="numpy"), inline="always")
def _formula_forces_overload(y, dy, masses, d, n, n_tan, kind, weighted, X, t):
    if isinstance(X, types.NoneType):
        return lambda y, dy, masses, d, n, n_tan, kind, weighted, X, t: None
    return lambda y, dy, masses, d, n, n_tan, kind, weighted, X, t: _formula_forces(
        y, dy, masses, d, n, n_tan, kind, weighted, X, t)


@leaf
def _formula_energy(q, masses, d, kind, weighted, X, t):
    """The energy of a term written as a formula (program t of X)."""
    N = masses.size
    total = 0.0
    if kind == POSITION:
        for i in range(N):
            run_program(X, t, q[i * d], q[i * d + 1], q[i * d + 2] if d == 3 else 0.0)
            total += masses[i] * output(X, t, 0) if weighted != 0.0 else output(X, t, 0)
    elif kind == DISTANCE:
        for i in range(N - 1):
            for j in range(i + 1, N):
                run_program(X, t, norm(sub(vec(q, j * d, d), vec(q, i * d, d))), 0.0, 0.0)
                u = output(X, t, 0)
                total += masses[i] * masses[j] * u if weighted != 0.0 else u
    else:
        for i in range(N - 2):
            for j in range(i + 1, N - 1):
                for k in range(j + 1, N):
                    if kind == SIDES:
                        u, v, w = vec(q, i * d, d), vec(q, j * d, d), vec(q, k * d, d)
                        run_program(X, t, norm(sub(v, u)), norm(sub(w, v)), norm(sub(u, w)))
                    else:
                        run_program(X, t, triplet_measure(q, i, j, k, d, kind), 0.0, 0.0)
                    total += output(X, t, 0)
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
def rhs(t, y, dy, model, n_tan):
    """Hamilton's equations and the variational equations of n_tan tangent vectors
    (d dq/dt = M^-1 dp, d dp/dt = -Hess U dq) at one state y."""
    velocities_and_forces(y, dy, model, n_tan)


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
    r1, r2, r3 = reciprocals(L1, L2, L3)
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
    s1, s2, s3 = U1 * r1, U1 * r2, U1 * r3
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


@leaf
def _leading_forces(y, dy, masses, N, d, measure, prof, lead, n_tan):
    """Velocities, and the forces of the leading perimetric or areal term. The measure is
    chosen outside the triplet loop: one branch per call, not per triplet, keeps the loop
    body small enough for the compiler to keep it tight. Compiled on its own, not inlined
    into `rhs`: one call per evaluation costs nothing measurable, and `rhs` with it inlined
    took over twice as long to compile."""
    nq = N * d
    n = 2 * nq
    # flat loops over views, whose indices the compiler knows are not negative (an index
    # computed from run-time sizes gets a wrap-around fix-up at every access, and loops of
    # d trips): 1/m of each coordinate first, parked in the orbit's force slots (zeroed
    # below), then every block's velocities (the same bits, in fewer operations)
    inv = dy[nq:n]
    for b in range(N):
        x = 1.0 / masses[b]
        for c in range(d):
            inv[b * d + c] = x
    for t_ in range(1 + n_tan):
        rate, p = dy[n * t_:n * t_ + nq], y[n * t_ + nq:n * t_ + n]
        for c in range(nq):
            rate[c] = p[c] * inv[c]
    for t_ in range(1 + n_tan):
        force = dy[n * t_ + nq:n * t_ + n]
        for c in range(nq):
            force[c] = 0.0
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


@leaf
def _rows_forces(y, dy, masses, d, n, n_tan, par, X):
    """Add the forces of the terms after the leading one (par's rows 1, ...)."""
    N = masses.size
    for row in range(1, par.shape[0]):
        kind, code, weighted = int(par[row, 0]), int(par[row, 1]), par[row, 2]
        p = _term_params(par, row)
        if code == EXPRESSION:
            formula_forces(y, dy, masses, d, n, n_tan, kind, weighted, X, int(p[0]))
        elif kind == DISTANCE:
            for i in range(N - 1):
                for j in range(i + 1, N):
                    w = masses[i] * masses[j] if weighted != 0.0 else 1.0
                    pair_forces(y, dy, i, j, d, n, n_tan, code, p, w)
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


@leaf
def _formula_forces(y, dy, masses, d, n, n_tan, kind, weighted, X, t):
    """Add the forces of a term written as a formula (program t of X): one of a body's
    position on every body; one of a single measure through that measure's forces with
    the program's U' and U'' (the GIVEN profile); one of the sides through sides_forces.
    GIVEN is passed as an int64, not the literal: the forces' kernels would compile a
    second time for it."""
    N = masses.size
    given = np.int64(GIVEN)
    if kind == POSITION:
        for i in range(N):
            external_forces(y, dy, i, d, n, n_tan, X, t,
                            masses[i] if weighted != 0.0 else 1.0)
    elif kind == DISTANCE:
        for i in range(N - 1):
            for j in range(i + 1, N):
                r = norm(sub(vec(y, j * d, d), vec(y, i * d, d)))
                _, U1, U2 = expression_profile(X, t, r)
                pair_forces(y, dy, i, j, d, n, n_tan, given, (U1, U2),
                            masses[i] * masses[j] if weighted != 0.0 else 1.0)
    else:
        for i in range(N - 2):
            for j in range(i + 1, N - 1):
                for k in range(j + 1, N):
                    if kind == SIDES:
                        sides_forces(y, dy, i, j, k, d, n, n_tan, X, t)
                        continue
                    _, U1, U2 = expression_profile(X, t, triplet_measure(y, i, j, k, d, kind))
                    if kind == PERIMETER:
                        perimetric_forces(y, dy, i, j, k, d, n, n_tan, given, (U1, U2))
                    else:
                        areal_forces(y, dy, i, j, k, d, n, n_tan, given, (U1, U2))
