"""Interaction terms: energy, forces and tangent (Hessian-vector) forces of one triplet or
one pair.

A perimetric or areal triplet potential is U(x) of one shape measure x of the triangle: its
perimeter P ("perimetric") or the magnitude of its area |A| ("areal"). The Axilrod-Teller-
Muto triple dipole depends on the whole triangle. A pair potential is U(r) of a pair's
distance. A *profile* gives U, U' and U'' as functions of x or r. The kernels take integer
codes and a parameter array, so one compiled (and cached) kernel serves every choice made at
run time: numba cannot cache kernels that take other jitted functions as arguments.

Forces use vector forms (bisector forces for P, altitude forces for |A|, with the area
vector in 3-D; ATM through the side vectors' dot products), not chain rules through side
lengths or angles, which are ill-conditioned near collinear triangles. 2-D vectors are
handled as 3-vectors with z = 0.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

# Every compiled function: cached on disk, and IEEE arithmetic (inf/nan, never a Python
# exception such as ZeroDivisionError from inside a kernel; the integrator turns
# non-finite values into a status).
kernel = njit(cache=True, error_model="numpy")
# small helpers are inlined at numba-IR level: calls between separately compiled functions
# otherwise cost more than the arithmetic (3x on the right-hand side).
helper = njit(cache=True, error_model="numpy", inline="always")

# what a term depends on: a triangle's perimeter or area, the whole triangle (ATM), or a
# pair's distance; NONE marks "no perimetric or areal term" in the kernels' arguments
NONE, PERIMETER, AREA, TRIANGLE, DISTANCE = -1, 0, 1, 2, 3
POWER, YUKAWA, BARRIER, LENNARD_JONES = 0, 1, 2, 3

MEASURES = {"perimetric": PERIMETER, "areal": AREA}

# profile name -> (code, formula, ordered parameters with defaults)
PROFILES = {
    "power": (POWER, "coupling * {x}**exponent / exponent  (coupling * log({x}) if exponent == 0)",
              {"coupling": 1.0, "exponent": 2.0}),
    "yukawa": (YUKAWA, "-coupling * exp(-gamma * {x}) / {x}", {"coupling": 1.0, "gamma": 1.0}),
    "barrier": (BARRIER, "alpha / {x} + beta * {x}**2", {"alpha": 2.0, "beta": 1.0}),
}
ATM = "axilrod_teller"
ATM_FORMULA = "strength * (1 + 3 cos t_i cos t_j cos t_k) / (r_ij r_jk r_ki)**3"
TRIPLET_NAMES = tuple(f"{m}_{p}" for m in MEASURES for p in PROFILES) + (ATM,)
POTENTIAL_NAMES = TRIPLET_NAMES      # the [system].potential shorthand: one triplet term

# pair potential name -> (profile code, formula, ordered parameters with defaults); the
# repulsive pair Yukawa is the YUKAWA profile with its coupling negated
PAIR_PROFILES = {
    "lennard_jones": (LENNARD_JONES, "4 epsilon ((sigma / r)**12 - (sigma / r)**6)",
                      {"epsilon": 1.0, "sigma": 1.0}),
    "yukawa": (YUKAWA, "coupling * exp(-gamma * r) / r  (repulsive for coupling > 0)",
               {"coupling": 1.0, "gamma": 1.0}),
    "power": (POWER, "coupling * r**exponent / exponent  (coupling * log(r) if exponent == 0)",
              {"coupling": 1.0, "exponent": -1.0}),
}
PAIR_NAMES = tuple(PAIR_PROFILES)
KINDS = ("pair", "triplet")


@dataclass(frozen=True)
class Potential:
    """One term of a system's potential, chosen by kind and name: a triplet potential summed
    over all triangles, e.g. ``perimetric_power`` (the paper's P**2/2 with the defaults),
    ``areal_barrier`` (the paper's 2/|A| + |A|**2) or ``axilrod_teller``, or a pair
    potential summed over all pairs, e.g. ``lennard_jones``."""

    name: str
    measure: int
    profile: int
    params: tuple[float, ...]
    param_names: tuple[str, ...]

    @property
    def kind(self) -> str:
        return "pair" if self.measure == DISTANCE else "triplet"

    @property
    def par(self) -> np.ndarray:
        """The parameters as the kernels read them (a pair Yukawa's coupling negated)."""
        p = np.array(self.params, dtype=np.float64)
        if self.kind == "pair" and self.profile == YUKAWA:
            p[0] = -p[0]
        return p

    def describe(self) -> str:
        if self.kind == "pair":
            formula = PAIR_PROFILES[self.name][1]
        elif self.measure == TRIANGLE:
            formula = ATM_FORMULA
        else:
            x = "P" if self.measure == PERIMETER else "|A|"
            formula = PROFILES[self.name.split("_", 1)[1]][1].format(x=x)
        values = ", ".join(f"{k}={v:g}" for k, v in zip(self.param_names, self.params))
        return f"{self.name} ({self.kind}): U = {formula} with {values}"


def parameter_defaults(name: str, kind: str = "triplet") -> dict:
    """The parameters of a potential with their defaults; unknown names raise ValueError,
    with a hint when the name is a potential of the other kind."""
    if kind not in KINDS:
        raise ValueError(f"unknown interaction kind {kind!r}; choose one of {', '.join(KINDS)}")
    names, other, other_kind = ((PAIR_NAMES, TRIPLET_NAMES, "triplet") if kind == "pair"
                                else (TRIPLET_NAMES, PAIR_NAMES, "pair"))
    if name not in names:
        hint = (f" ({name!r} is a {other_kind} potential: give it kind = \"{other_kind}\")"
                if name in other else "")
        raise ValueError(f"unknown {kind} potential {name!r}; choose one of "
                         f"{', '.join(names)}{hint}")
    if kind == "pair":
        return dict(PAIR_PROFILES[name][2])
    if name == ATM:
        return {"strength": 1.0}
    return dict(PROFILES[name.split("_", 1)[1]][2])


def make_potential(name: str, params: dict | None = None, kind: str = "triplet") -> Potential:
    """Resolve a potential of a kind ("triplet" or "pair"), its name and its parameters;
    anything unknown, missing or out of range raises ValueError naming it."""
    params = dict(params or {})
    defaults = parameter_defaults(name, kind)
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise ValueError(f"potential {name!r} has no parameter {unknown[0]!r}; "
                         f"its parameters are {', '.join(defaults)}")
    values = {}
    for key, default in defaults.items():
        value = params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"potential parameter {key!r} must be a finite number, got {value!r}")
        values[key] = float(value)
    if values.get("gamma", 0.0) < 0:
        raise ValueError("potential parameter 'gamma' must be >= 0 (a screening rate)")
    if values.get("coupling") == 0:      # divides by it, and means "no term"
        raise ValueError("potential parameter 'coupling' must be nonzero")
    for key, what in (("epsilon", "a well depth"), ("sigma", "a length")):
        if key in values and not values[key] > 0:
            raise ValueError(f"potential parameter {key!r} must be > 0 ({what}), "
                             f"got {values[key]:g}")
    if kind == "pair":
        measure, code = DISTANCE, PAIR_PROFILES[name][0]
    elif name == ATM:
        measure, code = TRIANGLE, 0
    else:
        measure, profile_name = name.split("_", 1)
        measure, code = MEASURES[measure], PROFILES[profile_name][0]
    return Potential(name, measure, code, tuple(values.values()), tuple(defaults))


# ---------------------------------------------------------------- 3-vector helpers

@helper
def vec(a, off, d):
    """Components off..off+d of a flat array as a 3-tuple (z = 0 in 2-D)."""
    if d == 3:
        return (a[off], a[off + 1], a[off + 2])
    return (a[off], a[off + 1], 0.0)


@helper
def add_to(a, off, d, s, v):
    """a[off:off+d] += s * v."""
    a[off] += s * v[0]
    a[off + 1] += s * v[1]
    if d == 3:
        a[off + 2] += s * v[2]


@helper
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@helper
def axpy(s, a, b):
    """s * a + b."""
    return (s * a[0] + b[0], s * a[1] + b[1], s * a[2] + b[2])


@helper
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@helper
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@helper
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


# ---------------------------------------------------------------- profiles

@helper
def profile(code, par, x):
    """U(x), U'(x), U''(x) of a profile."""
    if code == POWER:
        c, k = par[0], par[1]
        if k == 2.0:
            return 0.5 * c * x * x, c * x, c
        if k == 0.0:
            return c * math.log(x), c / x, -c / (x * x)
        xk2 = x ** (k - 2.0)
        return c * xk2 * x * x / k, c * xk2 * x, c * (k - 1.0) * xk2
    if code == YUKAWA:
        c, g = par[0], par[1]
        e = math.exp(-g * x)
        return (-c * e / x, c * e * (g * x + 1.0) / (x * x),
                -c * e * (g * g * x * x + 2.0 * g * x + 2.0) / (x * x * x))
    if code == BARRIER:
        a, b = par[0], par[1]
        return a / x + b * x * x, -a / (x * x) + 2.0 * b * x, 2.0 * a / (x * x * x) + 2.0 * b
    eps, r6 = par[0], (par[1] / x) ** 6     # LENNARD_JONES
    return (4.0 * eps * (r6 * r6 - r6), 24.0 * eps * (r6 - 2.0 * r6 * r6) / x,
            24.0 * eps * (26.0 * r6 * r6 - 7.0 * r6) / (x * x))


# ---------------------------------------------------------------- one triplet

@kernel
def triplet_measure(q, i, j, k, d, measure):
    """Perimeter, or |A|, of the triangle of bodies i, j, k (positions q, flat)."""
    u, v, w = vec(q, i * d, d), vec(q, j * d, d), vec(q, k * d, d)
    if measure == PERIMETER:
        return norm(sub(v, u)) + norm(sub(w, v)) + norm(sub(u, w))
    return 0.5 * norm(cross(sub(v, u), sub(w, u)))


@helper
def _unit(a):
    L = norm(a)
    r = 1.0 / L
    return (a[0] * r, a[1] * r, a[2] * r), L


@helper
def _pair_tangent(e, L, dr, dP, U1, U2):
    """Variation of U'(P) e for one side: U'' dP e + U' (I - e e^T) dr / L."""
    s = U1 / L
    return axpy(U2 * dP - s * dot(e, dr), e, (s * dr[0], s * dr[1], s * dr[2]))


@helper
def _add_cyclic(dy, off, i, j, k, d, s, g1, g2, g3):
    """Add s times the derivatives along the sides i->j, j->k, k->i (g1, g2, g3) to bodies
    i, j, k: -dU/dq_i = g1 - g3, and cyclic."""
    add_to(dy, off + i * d, d, s, sub(g1, g3))
    add_to(dy, off + j * d, d, s, sub(g2, g1))
    add_to(dy, off + k * d, d, s, sub(g3, g2))


@helper
def perimetric_forces(y, dy, i, j, k, d, n, n_tan, prof, par):
    """Add the forces of triplet (i, j, k) under U(P) to dy's momentum rates, and for each
    tangent vector t (stored at y[n*(1+t):]) its tangent force -Hess U . dq to dy at the
    same offsets (the paper's one-jet, Appendix E)."""
    nq = n // 2
    u, v, w = vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d)
    # unit vectors along the sides i->j, j->k, k->i; the force on a body is U'(P) times the
    # sum of the unit vectors towards its two neighbours: it bisects the interior angle.
    e1, L1 = _unit(sub(v, u))
    e2, L2 = _unit(sub(w, v))
    e3, L3 = _unit(sub(u, w))
    _, U1, U2 = profile(prof, par, L1 + L2 + L3)
    _add_cyclic(dy, nq, i, j, k, d, U1, e1, e2, e3)
    for t in range(n_tan):
        base = n * (1 + t)
        du, dv, dw = vec(y, base + i * d, d), vec(y, base + j * d, d), vec(y, base + k * d, d)
        r1, r2, r3 = sub(dv, du), sub(dw, dv), sub(du, dw)
        dP = dot(e1, r1) + dot(e2, r2) + dot(e3, r3)
        g1 = _pair_tangent(e1, L1, r1, dP, U1, U2)
        g2 = _pair_tangent(e2, L2, r2, dP, U1, U2)
        g3 = _pair_tangent(e3, L3, r3, dP, U1, U2)
        _add_cyclic(dy, base + nq, i, j, k, d, 1.0, g1, g2, g3)


@helper
def areal_forces(y, dy, i, j, k, d, n, n_tan, prof, par):
    """As perimetric_forces, for U(|A|)."""
    nq = n // 2
    u, v, w = vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d)
    # grad_u |A| = (v - w) x Ahat / 2 (cyclic): the force on a body is parallel to its
    # altitude. A collinear start (|A| = 0) gets Ahat = 0, the limit of a smooth profile.
    A = cross(sub(v, u), sub(w, u))
    A = (0.5 * A[0], 0.5 * A[1], 0.5 * A[2])
    absA = norm(A)
    inv = 1.0 / absA if absA > 0.0 else 0.0
    Ah = (A[0] * inv, A[1] * inv, A[2] * inv)
    _, U1, U2 = profile(prof, par, absA)
    svw, swu, suv = sub(v, w), sub(w, u), sub(u, v)
    Gu, Gv, Gw = cross(svw, Ah), cross(swu, Ah), cross(suv, Ah)   # each 2 grad |A|
    add_to(dy, nq + i * d, d, -0.5 * U1, Gu)
    add_to(dy, nq + j * d, d, -0.5 * U1, Gv)
    add_to(dy, nq + k * d, d, -0.5 * U1, Gw)
    for t in range(n_tan):
        base = n * (1 + t)
        du, dv, dw = vec(y, base + i * d, d), vec(y, base + j * d, d), vec(y, base + k * d, d)
        c1, c2, c3 = cross(du, svw), cross(dv, swu), cross(dw, suv)
        dA = (0.5 * (c1[0] + c2[0] + c3[0]), 0.5 * (c1[1] + c2[1] + c3[1]),
              0.5 * (c1[2] + c2[2] + c3[2]))
        dabs = dot(Ah, dA)
        dAh = axpy(-dabs * inv, Ah, (dA[0] * inv, dA[1] * inv, dA[2] * inv))
        off = base + nq
        a = -0.5 * U2 * dabs
        b = -0.5 * U1
        add_to(dy, off + i * d, d, a, Gu)
        add_to(dy, off + i * d, d, b, axpy(1.0, cross(sub(dv, dw), Ah), cross(svw, dAh)))
        add_to(dy, off + j * d, d, a, Gv)
        add_to(dy, off + j * d, d, b, axpy(1.0, cross(sub(dw, du), Ah), cross(swu, dAh)))
        add_to(dy, off + k * d, d, a, Gw)
        add_to(dy, off + k * d, d, b, axpy(1.0, cross(sub(du, dv), Ah), cross(suv, dAh)))


# ---------------------------------------------------------------- the triple dipole

@helper
def _atm_h(c, s, A, B, sb, C, sc):
    """Q^(5/2)/Z times dU/ds for one side s of the ATM triangle (see atm_forces)."""
    return axpy(c, s, axpy(-3.0 * A * B, sb, (-3.0 * A * C * sc[0], -3.0 * A * C * sc[1],
                                               -3.0 * A * C * sc[2])))


@helper
def _atm_dh(c, dc, s, r, A, dA, B, dB, sb, rb, C, dC, sc, rc):
    """Variation of _atm_h along side variations r, rb, rc."""
    out = axpy(dc, s, (c * r[0], c * r[1], c * r[2]))
    out = axpy(-3.0 * (dA * B + A * dB), sb, out)
    out = axpy(-3.0 * (dA * C + A * dC), sc, out)
    out = axpy(-3.0 * A * B, rb, out)
    return axpy(-3.0 * A * C, rc, out)


@helper
def atm_energy(u, v, w, Z):
    """Axilrod-Teller-Muto energy of one triangle. With side vectors s1 = v - u,
    s2 = w - v, s3 = u - w, Q = |s1|^2 |s2|^2 |s3|^2 and D = (s1.s2)(s2.s3)(s3.s1), the
    cosines' product is -D/Q and U = Z (Q - 3 D) / Q^(5/2): polynomials in the sides, with
    no angle or side length to lose accuracy near collinear triangles."""
    s1, s2, s3 = sub(v, u), sub(w, v), sub(u, w)
    Q = dot(s1, s1) * dot(s2, s2) * dot(s3, s3)
    D = dot(s1, s2) * dot(s2, s3) * dot(s3, s1)
    return Z * (Q - 3.0 * D) / (Q * Q * math.sqrt(Q))


@helper
def atm_forces(y, dy, i, j, k, d, n, n_tan, par):
    """As perimetric_forces, for the Axilrod-Teller-Muto potential of strength par[0].
    dU/ds1 = Z Q^(-5/2) ((15 D - 3 Q) s1 / |s1|^2 - 3 (s2.s3) ((s3.s1) s2 + (s1.s2) s3))
    (cyclic), and the force on u is dU/ds1 - dU/ds3 (s1 = v - u, s3 = u - w)."""
    nq = n // 2
    Z = par[0]
    u, v, w = vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d)
    s1, s2, s3 = sub(v, u), sub(w, v), sub(u, w)
    l1, l2, l3 = dot(s1, s1), dot(s2, s2), dot(s3, s3)
    a12, a23, a31 = dot(s1, s2), dot(s2, s3), dot(s3, s1)
    Q = l1 * l2 * l3
    D = a12 * a23 * a31
    W = Z / (Q * Q * math.sqrt(Q))
    num = 15.0 * D - 3.0 * Q
    c1, c2, c3 = num / l1, num / l2, num / l3
    H1 = _atm_h(c1, s1, a23, a31, s2, a12, s3)
    H2 = _atm_h(c2, s2, a31, a12, s3, a23, s1)
    H3 = _atm_h(c3, s3, a12, a23, s1, a31, s2)
    _add_cyclic(dy, nq, i, j, k, d, W, H1, H2, H3)
    for t in range(n_tan):
        base = n * (1 + t)
        du, dv, dw = vec(y, base + i * d, d), vec(y, base + j * d, d), vec(y, base + k * d, d)
        r1, r2, r3 = sub(dv, du), sub(dw, dv), sub(du, dw)
        dl1, dl2, dl3 = 2.0 * dot(s1, r1), 2.0 * dot(s2, r2), 2.0 * dot(s3, r3)
        da12 = dot(s1, r2) + dot(r1, s2)
        da23 = dot(s2, r3) + dot(r2, s3)
        da31 = dot(s3, r1) + dot(r3, s1)
        dQ = dl1 * l2 * l3 + l1 * dl2 * l3 + l1 * l2 * dl3
        dD = da12 * a23 * a31 + a12 * da23 * a31 + a12 * a23 * da31
        dW = -2.5 * W * dQ / Q
        dcc = 15.0 * dD - 3.0 * dQ
        dH1 = _atm_dh(c1, (dcc - c1 * dl1) / l1, s1, r1, a23, da23, a31, da31, s2, r2,
                      a12, da12, s3, r3)
        dH2 = _atm_dh(c2, (dcc - c2 * dl2) / l2, s2, r2, a31, da31, a12, da12, s3, r3,
                      a23, da23, s1, r1)
        dH3 = _atm_dh(c3, (dcc - c3 * dl3) / l3, s3, r3, a12, da12, a23, da23, s1, r1,
                      a31, da31, s2, r2)
        _add_cyclic(dy, base + nq, i, j, k, d, dW, H1, H2, H3)
        _add_cyclic(dy, base + nq, i, j, k, d, W, dH1, dH2, dH3)


# ---------------------------------------------------------------- one pair

@helper
def pair_forces(y, dy, i, j, d, n, n_tan, prof, par):
    """As perimetric_forces, for a pair potential U(r) of bodies i and j: the force on i is
    U'(r) along the unit vector towards j, its tangent force the variation of that."""
    nq = n // 2
    e, L = _unit(sub(vec(y, j * d, d), vec(y, i * d, d)))
    _, U1, U2 = profile(prof, par, L)
    add_to(dy, nq + i * d, d, U1, e)
    add_to(dy, nq + j * d, d, -U1, e)
    for t in range(n_tan):
        base = n * (1 + t)
        r = sub(vec(y, base + j * d, d), vec(y, base + i * d, d))
        g = _pair_tangent(e, L, r, dot(e, r), U1, U2)
        add_to(dy, base + nq + i * d, d, 1.0, g)
        add_to(dy, base + nq + j * d, d, -1.0, g)
