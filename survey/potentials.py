"""Triangle potentials: energy, forces and tangent (Hessian-vector) forces of one triplet.

A triplet potential is U(x) of one shape measure x of the triangle: its perimeter P
("perimetric") or the magnitude of its area |A| ("areal"). A *profile* gives U, U' and U''
as functions of x. The kernels take integer codes and a parameter array, so one compiled
(and cached) kernel serves every choice made at run time: numba cannot cache kernels that
take other jitted functions as arguments.

Forces use the paper's vector forms (bisector forces for P, altitude forces for |A|, with
the area vector in 3-D), not chain rules through side lengths, which are ill-conditioned
near collinear triangles. 2-D vectors are handled as 3-vectors with z = 0.
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

PERIMETER, AREA = 0, 1
POWER, YUKAWA, BARRIER = 0, 1, 2

MEASURES = {"perimetric": PERIMETER, "areal": AREA}

# profile name -> (code, formula, ordered parameters with defaults)
PROFILES = {
    "power": (POWER, "coupling * {x}**exponent / exponent  (coupling * log({x}) if exponent == 0)",
              {"coupling": 1.0, "exponent": 2.0}),
    "yukawa": (YUKAWA, "-coupling * exp(-gamma * {x}) / {x}", {"coupling": 1.0, "gamma": 1.0}),
    "barrier": (BARRIER, "alpha / {x} + beta * {x}**2", {"alpha": 2.0, "beta": 1.0}),
}

POTENTIAL_NAMES = tuple(f"{m}_{p}" for m in MEASURES for p in PROFILES)


@dataclass(frozen=True)
class Potential:
    """A triplet potential chosen by name, e.g. ``perimetric_power`` (the paper's P**2/2
    with the defaults) or ``areal_barrier`` (the paper's 2/|A| + |A|**2)."""

    name: str
    measure: int
    profile: int
    params: tuple[float, ...]
    param_names: tuple[str, ...]

    @property
    def par(self) -> np.ndarray:
        return np.array(self.params, dtype=np.float64)

    def describe(self) -> str:
        x = "P" if self.measure == PERIMETER else "|A|"
        formula = PROFILES[self.name.split("_", 1)[1]][1].format(x=x)
        values = ", ".join(f"{k}={v:g}" for k, v in zip(self.param_names, self.params))
        return f"{self.name}: U = {formula} with {values}"


def make_potential(name: str, params: dict | None = None) -> Potential:
    """Resolve a potential name and its parameters; unknown names or keys raise ValueError."""
    params = dict(params or {})
    if name not in POTENTIAL_NAMES:
        raise ValueError(f"unknown potential {name!r}; choose one of {', '.join(POTENTIAL_NAMES)}")
    measure, profile = name.split("_", 1)
    code, _, defaults = PROFILES[profile]
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise ValueError(f"potential {name!r} has no parameter {unknown[0]!r}; "
                         f"its parameters are {', '.join(defaults)}")
    values = []
    for key, default in defaults.items():
        value = params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"potential parameter {key!r} must be a finite number, got {value!r}")
        values.append(float(value))
    if profile == "yukawa" and values[1] < 0:
        raise ValueError("potential parameter 'gamma' must be >= 0 (a screening rate)")
    if profile in ("power", "yukawa") and values[0] == 0:
        raise ValueError("potential parameter 'coupling' must be nonzero")
    return Potential(name, MEASURES[measure], code, tuple(values), tuple(defaults))


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
    a, b = par[0], par[1]
    return a / x + b * x * x, -a / (x * x) + 2.0 * b * x, 2.0 * a / (x * x * x) + 2.0 * b


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
    add_to(dy, nq + i * d, d, U1, sub(e1, e3))
    add_to(dy, nq + j * d, d, U1, sub(e2, e1))
    add_to(dy, nq + k * d, d, U1, sub(e3, e2))
    for t in range(n_tan):
        base = n * (1 + t)
        du, dv, dw = vec(y, base + i * d, d), vec(y, base + j * d, d), vec(y, base + k * d, d)
        r1, r2, r3 = sub(dv, du), sub(dw, dv), sub(du, dw)
        dP = dot(e1, r1) + dot(e2, r2) + dot(e3, r3)
        g1 = _pair_tangent(e1, L1, r1, dP, U1, U2)
        g2 = _pair_tangent(e2, L2, r2, dP, U1, U2)
        g3 = _pair_tangent(e3, L3, r3, dP, U1, U2)
        off = base + nq
        add_to(dy, off + i * d, d, 1.0, sub(g1, g3))
        add_to(dy, off + j * d, d, 1.0, sub(g2, g1))
        add_to(dy, off + k * d, d, 1.0, sub(g3, g2))


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
