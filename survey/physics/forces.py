"""Energy, forces and tangent (Hessian-vector) forces of one triplet or one pair, compiled.

A *profile* gives U, U' and U'' as functions of a triangle's measure x or a pair's distance
r. Forces use vector forms (bisector forces for P, altitude forces for |A|, with the area
vector in 3-D; ATM through the side vectors' dot products), not chain rules through side
lengths or angles, which are ill-conditioned near collinear triangles. 2-D vectors are
handled as 3-vectors with z = 0.
"""
from __future__ import annotations

import math

import numpy as np

from ..machine import portable
from ..machine.jit import helper, lanes, leaf
from .expressions import output, run_program
from .terms import BARRIER, GIVEN, LENNARD_JONES, PERIMETER, POWER, YUKAWA

# The perimetric and areal forces exist in one reference and hand-specialised copies, each
# for speed on the paths that run most; every copy is held to what it specialises, bit for
# bit, by the test named (tests/physics/test_system.py; the reduced states to roundoff).
# The reference: perimetric_forces and areal_forces here, one triplet of any bodies in any
# dimension with its tangent vectors, which system._leading_forces runs over the triplets.
# (copy, what it specialises, the test holding it there)
SPECIALISED = (
    ("physics.system._planar_perimetric", "physics.system._leading_forces",
     "test_the_planar_path_gives_the_general_n_body_path_bit_for_bit"),
    ("physics.system._planar_areal", "physics.system._leading_forces",
     "test_the_planar_path_gives_the_general_n_body_path_bit_for_bit"),
    ("physics.lanes._perimetric_orbits", "physics.system.rhs",
     "test_the_simd_lanes_give_the_general_path_bit_for_bit"),
    ("physics.lanes._perimetric_tangent", "physics.system.rhs",
     "test_the_simd_lanes_give_the_general_path_bit_for_bit"),
    ("physics.lanes._areal_orbits", "physics.system.rhs",
     "test_the_simd_lanes_give_the_general_path_bit_for_bit"),
    ("physics.lanes._areal_tangent", "physics.system.rhs",
     "test_the_simd_lanes_give_the_general_path_bit_for_bit"),
    ("physics.forces.perimetric_lanes", "physics.system.rhs",
     "test_other_systems_in_lanes_give_the_same_bits"),
    ("physics.forces.perimetric_tangent_lanes", "physics.system.rhs",
     "test_other_systems_in_lanes_give_the_same_bits"),
    ("physics.forces.areal_lanes", "physics.system.rhs",
     "test_other_systems_in_lanes_give_the_same_bits"),
    ("physics.forces.areal_force_lanes", "physics.system.rhs",
     "test_other_systems_in_lanes_give_the_same_bits"),
    ("physics.forces.areal_tangent_lanes", "physics.system.rhs",
     "test_other_systems_in_lanes_give_the_same_bits"),
    ("physics.lanes._perimetric_orbits (reduced states)", "physics.system.rhs",
     "test_a_reduced_state_has_the_full_states_rates_to_roundoff"),
)


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
def scale(s, a):
    return (a[0] * s, a[1] * s, a[2] * s)


@helper
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@helper
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@helper
def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@helper
def power_2(c, x):
    """U, U', U'' of the power profile c x^2 / 2 (the paper's U = P^2 / 2)."""
    return 0.5 * c * x * x, c * x, c


@helper
def barrier(a, b, x):
    """U, U', U'' of the barrier profile a / x + b x^2."""
    return a / x + b * x * x, -a / (x * x) + 2.0 * b * x, 2.0 * a / (x * x * x) + 2.0 * b


@helper
def lennard_jones(eps, sigma, x):
    """U, U', U'' of 4 eps ((sigma/x)^12 - (sigma/x)^6)."""
    r2 = sigma / x
    r2 = r2 * r2
    r6 = r2 * r2 * r2
    return (4.0 * eps * (r6 * r6 - r6), 24.0 * eps * (r6 - 2.0 * r6 * r6) / x,
            24.0 * eps * (26.0 * r6 * r6 - 7.0 * r6) / (x * x))


@helper
def profile(code, par, x):
    """U(x), U'(x), U''(x) of a profile. The algebraic ones are written in place, those
    with exp, log or a real power are a call: inlined at each of their call sites they
    made the kernels' code several times larger (and `rhs` three times slower to compile)
    for profiles the paper's systems do not use."""
    if code == POWER and par[1] == 2.0:
        return power_2(par[0], x)
    if code == BARRIER:
        return barrier(par[0], par[1], x)
    if code == LENNARD_JONES:
        return lennard_jones(par[0], par[1], x)
    return _transcendental_profile(code, par, x)


@leaf
def _transcendental_profile(code, par, x):
    """The power profile c x^k / k (k != 2; log for k = 0) and Yukawa's; GIVEN: U' and U''
    as par holds them (a formula's, from its program: `expression_profile`)."""
    if code == GIVEN:
        return 0.0, par[0], par[1]
    if code == POWER:
        c, k = par[0], par[1]
        if k == 0.0:
            return c * portable.log(x), c / x, -c / (x * x)
        xk2 = portable.power(x, k - 2.0)
        return c * xk2 * x * x / k, c * xk2 * x, c * (k - 1.0) * xk2
    return yukawa(par[0], par[1], x)


@helper
def yukawa(c, g, x):
    """-c e^(-g x) / x and its first two derivatives."""
    e = portable.exp(-g * x)
    return (-c * e / x, c * e * (g * x + 1.0) / (x * x),
            -c * e * (g * g * x * x + 2.0 * g * x + 2.0) / (x * x * x))


@leaf
def triplet_measure(q, i, j, k, d, measure):
    """Perimeter, or |A|, of the triangle of bodies i, j, k (positions q, flat)."""
    u, v, w = vec(q, i * d, d), vec(q, j * d, d), vec(q, k * d, d)
    if measure == PERIMETER:
        return norm(sub(v, u)) + norm(sub(w, v)) + norm(sub(u, w))
    return 0.5 * norm(cross(sub(v, u), sub(w, u)))


@helper
def _unit(a):
    """a's unit vector, length L and 1 / L."""
    L = norm(a)
    r = 1.0 / L
    return scale(r, a), L, r


@helper
def reciprocals(L1, L2, L3):
    """1 / L1, 1 / L2, 1 / L3 of a triangle's sides from one division: a step's
    right-hand sides wait on the core's divider, which their square roots keep busy
    (`bench --only step`); each is within a few units of roundoff of its own division.
    The sides are first scaled by the power of two s that brings the longest into
    [1, 2), exactly, and the results scaled back exactly (where nothing under- or
    overflows, the bits of the unscaled products). So the product cannot under- or
    overflow, as the plain one does for a triangle under 1e-103 across (the isosceles
    plane restarts a triple collision with all three sides near 1e-150): the middle
    side is at least half the longest (the triangle inequality), and only the shortest
    may be as small as 1e-300 times it."""
    longest = max(L1, max(L2, L3))
    e = min(max((np.float64(longest).view(np.int64) >> 52) & 0x7FF, 1), 2045)
    s = np.int64((2046 - e) << 52).view(np.float64)
    a, b, c = L1 * s, L2 * s, L3 * s
    bc = b * c
    q = 1.0 / (a * bc)
    return (q * bc) * s, (q * (a * c)) * s, (q * (a * b)) * s


@helper
def _pair_tangent(e, r, dr, dP, U1, U2):
    """Variation of U'(P) e for one side of 1 / length r: U'' dP e + U' (I - e e^T) dr r."""
    s = U1 * r
    return axpy(U2 * dP - s * dot(e, dr), e, (s * dr[0], s * dr[1], s * dr[2]))


@helper
def _add_cyclic(dy, off, i, j, k, d, s, g1, g2, g3):
    """Add s times the derivatives along the sides i->j, j->k, k->i (g1, g2, g3) to bodies
    i, j, k: -dU/dq_i = g1 - g3, and cyclic."""
    add_to(dy, off + i * d, d, s, sub(g1, g3))
    add_to(dy, off + j * d, d, s, sub(g2, g1))
    add_to(dy, off + k * d, d, s, sub(g3, g2))


@helper
def _perimetric_sides(u, v, w):
    """Unit vectors along the sides i->j, j->k, k->i of the triangle (u, v, w), the sides'
    lengths and their reciprocals: the force on a body is U'(P) times the sum of the unit
    vectors towards its two neighbours, which bisects the interior angle."""
    a, b, c = sub(v, u), sub(w, v), sub(u, w)
    L1, L2, L3 = norm(a), norm(b), norm(c)
    r1, r2, r3 = reciprocals(L1, L2, L3)
    return (scale(r1, a), scale(r2, b), scale(r3, c), L1, L2, L3, r1, r2, r3)


@helper
def _perimetric_tangent(e1, e2, e3, r1, r2, r3, U1, U2, du, dv, dw):
    """The variations g1, g2, g3 of U'(P) e along the three sides (_add_cyclic's
    derivatives; r: the sides' 1 / length) for deviations du, dv, dw of the bodies."""
    p1, p2, p3 = sub(dv, du), sub(dw, dv), sub(du, dw)
    dP = dot(e1, p1) + dot(e2, p2) + dot(e3, p3)
    return (_pair_tangent(e1, r1, p1, dP, U1, U2), _pair_tangent(e2, r2, p2, dP, U1, U2),
            _pair_tangent(e3, r3, p3, dP, U1, U2))


@leaf
def perimetric_forces(y, dy, i, j, k, d, n, n_tan, prof, par):
    """Add the forces of triplet (i, j, k) under U(P) to dy's momentum rates, and for each
    tangent vector t (stored at y[n*(1+t):]) its tangent force -Hess U . dq to dy at the
    same offsets (the paper's one-jet, Appendix E)."""
    nq = n // 2
    e1, e2, e3, L1, L2, L3, r1, r2, r3 = _perimetric_sides(
        vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d))
    _, U1, U2 = profile(prof, par, L1 + L2 + L3)
    _add_cyclic(dy, nq, i, j, k, d, U1, e1, e2, e3)
    for t in range(n_tan):
        base = n * (1 + t)
        g1, g2, g3 = _perimetric_tangent(e1, e2, e3, r1, r2, r3, U1, U2,
                                         vec(y, base + i * d, d), vec(y, base + j * d, d),
                                         vec(y, base + k * d, d))
        _add_cyclic(dy, base + nq, i, j, k, d, 1.0, g1, g2, g3)


@helper
def _areal_vector(u, v, w):
    """The triangle's unit area vector Ahat, |A| and 1/|A|. A collinear triangle (|A| = 0)
    gets Ahat = 0 and 1/|A| = 0, the limit of a smooth profile."""
    A = cross(sub(v, u), sub(w, u))
    A = (0.5 * A[0], 0.5 * A[1], 0.5 * A[2])
    absA = norm(A)
    inv = 1.0 / absA if absA > 0.0 else 0.0
    return (A[0] * inv, A[1] * inv, A[2] * inv), absA, inv


@helper
def _areal_gradients(u, v, w, Ah):
    """The sides v - w, w - u, u - v opposite each body and (v - w) x Ahat and cyclic, each
    twice grad |A| of its body: the force on a body is parallel to its altitude."""
    svw, swu, suv = sub(v, w), sub(w, u), sub(u, v)
    return svw, swu, suv, cross(svw, Ah), cross(swu, Ah), cross(suv, Ah)


@helper
def _areal_tangent(svw, swu, suv, Ah, inv, U2, du, dv, dw):
    """For deviations du, dv, dw of the bodies: the scale -U''(|A|) d|A| / 2 of the
    gradients, and the gradients' variations (whose scale is -U'(|A|) / 2)."""
    c1, c2, c3 = cross(du, svw), cross(dv, swu), cross(dw, suv)
    dA = (0.5 * (c1[0] + c2[0] + c3[0]), 0.5 * (c1[1] + c2[1] + c3[1]),
          0.5 * (c1[2] + c2[2] + c3[2]))
    dabs = dot(Ah, dA)
    dAh = axpy(-dabs * inv, Ah, (dA[0] * inv, dA[1] * inv, dA[2] * inv))
    return (-0.5 * U2 * dabs, axpy(1.0, cross(sub(dv, dw), Ah), cross(svw, dAh)),
            axpy(1.0, cross(sub(dw, du), Ah), cross(swu, dAh)),
            axpy(1.0, cross(sub(du, dv), Ah), cross(suv, dAh)))


@leaf
def areal_forces(y, dy, i, j, k, d, n, n_tan, prof, par):
    """As perimetric_forces, for U(|A|): grad_u |A| = (v - w) x Ahat / 2 (cyclic)."""
    nq = n // 2
    u, v, w = vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d)
    Ah, absA, inv = _areal_vector(u, v, w)
    _, U1, U2 = profile(prof, par, absA)
    svw, swu, suv, Gu, Gv, Gw = _areal_gradients(u, v, w, Ah)
    add_to(dy, nq + i * d, d, -0.5 * U1, Gu)
    add_to(dy, nq + j * d, d, -0.5 * U1, Gv)
    add_to(dy, nq + k * d, d, -0.5 * U1, Gw)
    for t in range(n_tan):
        base = n * (1 + t)
        a, Xu, Xv, Xw = _areal_tangent(svw, swu, suv, Ah, inv, U2, vec(y, base + i * d, d),
                                       vec(y, base + j * d, d), vec(y, base + k * d, d))
        off = base + nq
        b = -0.5 * U1
        add_to(dy, off + i * d, d, a, Gu)
        add_to(dy, off + i * d, d, b, Xu)
        add_to(dy, off + j * d, d, a, Gv)
        add_to(dy, off + j * d, d, b, Xv)
        add_to(dy, off + k * d, d, a, Gw)
        add_to(dy, off + k * d, d, b, Xw)


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
    parts = _atm_parts(vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d), par[0])
    W, H1, H2, H3 = parts[10], parts[14], parts[15], parts[16]
    _add_cyclic(dy, nq, i, j, k, d, W, H1, H2, H3)
    for t in range(n_tan):
        base = n * (1 + t)
        dW, dH1, dH2, dH3 = _atm_tangent(parts, vec(y, base + i * d, d),
                                         vec(y, base + j * d, d), vec(y, base + k * d, d))
        _add_cyclic(dy, base + nq, i, j, k, d, dW, H1, H2, H3)
        _add_cyclic(dy, base + nq, i, j, k, d, W, dH1, dH2, dH3)


@helper
def _atm_parts(u, v, w, Z):
    """What atm_forces computes of the triangle (u, v, w) before its forces: the sides,
    their dot products, Q, W = Z Q^(-5/2), the c's and the H's."""
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
    return s1, s2, s3, l1, l2, l3, a12, a23, a31, Q, W, c1, c2, c3, H1, H2, H3


@helper
def _atm_tangent(parts, du, dv, dw):
    """The variations dW, dH1, dH2, dH3 of the triangle's W and H's (_atm_parts) along the
    deviations du, dv, dw of its bodies."""
    s1, s2, s3, l1, l2, l3, a12, a23, a31, Q, W, c1, c2, c3, _, _, _ = parts
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
    return dW, dH1, dH2, dH3


@helper
def pair_forces(y, dy, i, j, d, n, n_tan, prof, par, w):
    """As perimetric_forces, for a pair potential w U(r) of bodies i and j (w = m_i m_j for
    a mass-weighted term, else 1): the force on i is w U'(r) along the unit vector towards
    j, its tangent force the variation of that."""
    nq = n // 2
    e, L, inv = _unit(sub(vec(y, j * d, d), vec(y, i * d, d)))
    _, U1, U2 = profile(prof, par, L)
    add_to(dy, nq + i * d, d, w * U1, e)
    add_to(dy, nq + j * d, d, -(w * U1), e)
    for t in range(n_tan):
        base = n * (1 + t)
        r = sub(vec(y, base + j * d, d), vec(y, base + i * d, d))
        g = _pair_tangent(e, inv, r, dot(e, r), U1, U2)
        add_to(dy, base + nq + i * d, d, w, g)
        add_to(dy, base + nq + j * d, d, -w, g)


# The same pair, ATM, perimetric and areal forces for L orbits at once (any system but the
# paper's three bodies in the plane under one term, which have loops of their own,
# `system._general_lanes`):
# each pair's or triangle's coordinates are first gathered into rows of G (G[r * L + k]:
# row r of lane k, z rows zero in the plane), then one loop over the lanes computes what
# the functions above compute, with their helpers in their order, into rows of another
# array, which system._general_lanes adds to the rates as add_to does. Reading and writing
# separate arrays (declared disjoint, jit.lanes) lets the compiler turn the loops into SIMD
# instructions; the values are those of one orbit's, bit for bit.

@helper
def _row3(G, r, L, k):
    """Rows r, r + 1, r + 2 of lane k as a 3-tuple."""
    return (G[r * L + k], G[(r + 1) * L + k], G[(r + 2) * L + k])


@helper
def _put3(O, r, L, k, v):
    O[r * L + k], O[(r + 1) * L + k], O[(r + 2) * L + k] = v


@helper
def _put_cyclic(O, r, L, k, g1, g2, g3):
    """The cyclic differences g1 - g3, g2 - g1, g3 - g2 (_add_cyclic's, bodies i, j, k) of
    lane k into O's rows r .. r + 8."""
    _put3(O, r, L, k, sub(g1, g3))
    _put3(O, r + 3, L, k, sub(g2, g1))
    _put3(O, r + 6, L, k, sub(g3, g2))


@lanes
def pair_geometry_lanes(G, P, L):
    """Unit vector from body i (G rows 0-2) to body j (rows 3-5) and their distance, into P
    rows 0-2 and 3, as pair_forces takes them."""
    for k in range(L):
        e, r, _ = _unit(sub(_row3(G, 3, L, k), _row3(G, 0, L, k)))
        _put3(P, 0, L, k, e)
        P[3 * L + k] = r


@lanes
def profile_lanes(code, par, X, U, L):
    """U' and U'' (U rows 0, 1) of a profile at X, with its code chosen outside the loop
    over the lanes (inside, the call of the transcendental ones keeps the algebraic ones
    from running as SIMD instructions)."""
    if code == LENNARD_JONES:
        for k in range(L):
            _, U[k], U[L + k] = lennard_jones(par[0], par[1], X[k])
    elif code == BARRIER:
        for k in range(L):
            _, U[k], U[L + k] = barrier(par[0], par[1], X[k])
    elif code == POWER and par[1] == 2.0:
        for k in range(L):
            _, U[k], U[L + k] = power_2(par[0], X[k])
    elif code == YUKAWA:        # portable.exp has no branches: SIMD instructions too
        for k in range(L):
            _, U[k], U[L + k] = yukawa(par[0], par[1], X[k])
    else:
        for k in range(L):
            _, U[k], U[L + k] = profile(code, par, X[k])


@lanes
def pair_tangent_lanes(G, P, U, O, L):
    """pair_forces' tangent force g of one tangent vector (its bodies i, j in G rows 0-2,
    3-5; the pair's unit vector and distance in P, U', U'' in U) into O rows 0-2 (1 / the
    distance divided again: pair_forces' own, the same bits)."""
    for k in range(L):
        e, inv = _row3(P, 0, L, k), 1.0 / P[3 * L + k]
        dr = sub(_row3(G, 3, L, k), _row3(G, 0, L, k))
        _put3(O, 0, L, k, _pair_tangent(e, inv, dr, dot(e, dr), U[k], U[L + k]))


@lanes
def atm_lanes(G, O, L, Z):
    """atm_forces' forces of one triangle (bodies u, v, w in G rows 0-8): W into O row 0
    and the cyclic differences H1 - H3, H2 - H1, H3 - H2 into rows 1-9."""
    for k in range(L):
        parts = _atm_parts(_row3(G, 0, L, k), _row3(G, 3, L, k), _row3(G, 6, L, k), Z)
        W, H1, H2, H3 = parts[10], parts[14], parts[15], parts[16]
        O[k] = W
        _put_cyclic(O, 1, L, k, H1, H2, H3)


@lanes
def atm_tangent_lanes(G, O, L, Z):
    """atm_forces' tangent terms of one tangent vector (bodies in G rows 0-8, their
    deviations in rows 9-17): dW into O row 0 and the differences dH1 - dH3, dH2 - dH1,
    dH3 - dH2 into rows 1-9 (W and the H's differences are atm_lanes'). (With W and the
    H's differences written here too, 20 rows, the compiler left the loop scalar.)"""
    for k in range(L):
        parts = _atm_parts(_row3(G, 0, L, k), _row3(G, 3, L, k), _row3(G, 6, L, k), Z)
        dW, dH1, dH2, dH3 = _atm_tangent(parts, _row3(G, 9, L, k), _row3(G, 12, L, k),
                                         _row3(G, 15, L, k))
        O[k] = dW
        _put_cyclic(O, 1, L, k, dH1, dH2, dH3)


@lanes
def perimetric_lanes(G, E, O, L):
    """perimetric_forces of one triangle (bodies in G rows 0-8) up to U'(P): the unit
    vectors into E rows 0-8, the sides' 1 / length into rows 9-11, the perimeter into row
    12, and the cyclic differences e1 - e3, e2 - e1, e3 - e2 into O rows 0-8."""
    for k in range(L):
        e1, e2, e3, L1, L2, L3, r1, r2, r3 = _perimetric_sides(
            _row3(G, 0, L, k), _row3(G, 3, L, k), _row3(G, 6, L, k))
        _put3(E, 0, L, k, e1)
        _put3(E, 3, L, k, e2)
        _put3(E, 6, L, k, e3)
        E[9 * L + k], E[10 * L + k], E[11 * L + k] = r1, r2, r3
        E[12 * L + k] = L1 + L2 + L3
        _put_cyclic(O, 0, L, k, e1, e2, e3)


@lanes
def perimetric_tangent_lanes(G, E, U, O, L):
    """perimetric_forces' tangent forces of one tangent vector (the bodies' deviations in G
    rows 9-17; E as perimetric_lanes leaves it, U' and U'' in U): the differences g1 - g3,
    g2 - g1, g3 - g2 into O rows 0-8, and their scale in _add_cyclic, 1.0, into row 9."""
    for k in range(L):
        g1, g2, g3 = _perimetric_tangent(
            _row3(E, 0, L, k), _row3(E, 3, L, k), _row3(E, 6, L, k), E[9 * L + k],
            E[10 * L + k], E[11 * L + k], U[k], U[L + k], _row3(G, 9, L, k),
            _row3(G, 12, L, k), _row3(G, 15, L, k))
        _put_cyclic(O, 0, L, k, g1, g2, g3)
        O[9 * L + k] = 1.0


@lanes
def areal_lanes(G, E, L):
    """areal_forces' Ahat (E rows 0-2), |A| (row 3) and 1/|A| (row 4) of one triangle
    (bodies in G rows 0-8)."""
    for k in range(L):
        Ah, absA, inv = _areal_vector(_row3(G, 0, L, k), _row3(G, 3, L, k),
                                      _row3(G, 6, L, k))
        _put3(E, 0, L, k, Ah)
        E[3 * L + k], E[4 * L + k] = absA, inv


@lanes
def areal_force_lanes(G, E, U, O, L):
    """areal_forces' forces: -U'(|A|) / 2 into O row 0, the gradients (twice grad |A|) of
    the three bodies into rows 1-9."""
    for k in range(L):
        gradients = _areal_gradients(_row3(G, 0, L, k), _row3(G, 3, L, k),
                                     _row3(G, 6, L, k), _row3(E, 0, L, k))
        O[k] = -0.5 * U[k]
        _put3(O, 1, L, k, gradients[3])
        _put3(O, 4, L, k, gradients[4])
        _put3(O, 7, L, k, gradients[5])


@lanes
def areal_tangent_lanes(G, E, U, O, L):
    """areal_forces' tangent terms of one tangent vector (deviations in G rows 9-17): the
    gradients' scale into O row 0 and their variations, whose scale is areal_force_lanes'
    row 0, into rows 1-9."""
    for k in range(L):
        svw, swu, suv, _, _, _ = _areal_gradients(_row3(G, 0, L, k), _row3(G, 3, L, k),
                                                  _row3(G, 6, L, k), _row3(E, 0, L, k))
        a, Xu, Xv, Xw = _areal_tangent(svw, swu, suv, _row3(E, 0, L, k), E[4 * L + k],
                                       U[L + k], _row3(G, 9, L, k), _row3(G, 12, L, k),
                                       _row3(G, 15, L, k))
        O[k] = a
        _put3(O, 1, L, k, Xu)
        _put3(O, 4, L, k, Xv)
        _put3(O, 7, L, k, Xw)


# ---------------------------------------------------------------- terms written as formulas
# (physics.expressions: each a program of a Programs X, here program t). A formula of one
# measure -- a pair's distance, a triangle's P or |A| -- runs the forces above with its
# values as the GIVEN profile; one of the three sides and one of a body's position have
# forces of their own.

@helper
def expression_profile(X, t, x):
    """U, U', U'' of program t (a formula of one measure) at x."""
    run_program(X, t, x, 0.0, 0.0)
    return output(X, t, 0), output(X, t, 1), output(X, t, 2)


@leaf
def sides_forces(y, dy, i, j, k, d, n, n_tan, X, t):
    """As perimetric_forces, for a symmetric U(a, b, c) of the sides a = |v - u|,
    b = |w - v|, c = |u - w| (program t): the force on u is U_a e1 - U_c e3 (cyclic), and
    each side's term varies by (sum over sides s of U_as (e_s . dr_s)) e1 plus U_a's
    turning of e1."""
    nq = n // 2
    e1, e2, e3, L1, L2, L3, r1, r2, r3 = _perimetric_sides(
        vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d))
    run_program(X, t, L1, L2, L3)
    Ua, Ub, Uc = output(X, t, 1), output(X, t, 2), output(X, t, 3)
    Haa, Hab, Hac = output(X, t, 4), output(X, t, 5), output(X, t, 6)
    Hbb, Hbc, Hcc = output(X, t, 7), output(X, t, 8), output(X, t, 9)
    _add_cyclic(dy, nq, i, j, k, d, 1.0, (Ua * e1[0], Ua * e1[1], Ua * e1[2]),
                (Ub * e2[0], Ub * e2[1], Ub * e2[2]), (Uc * e3[0], Uc * e3[1], Uc * e3[2]))
    for tt in range(n_tan):
        base = n * (1 + tt)
        du, dv, dw = vec(y, base + i * d, d), vec(y, base + j * d, d), vec(y, base + k * d, d)
        p1, p2, p3 = sub(dv, du), sub(dw, dv), sub(du, dw)
        d1, d2, d3 = dot(e1, p1), dot(e2, p2), dot(e3, p3)
        g1 = _pair_tangent(e1, r1, p1, Haa * d1 + Hab * d2 + Hac * d3, Ua, 1.0)
        g2 = _pair_tangent(e2, r2, p2, Hab * d1 + Hbb * d2 + Hbc * d3, Ub, 1.0)
        g3 = _pair_tangent(e3, r3, p3, Hac * d1 + Hbc * d2 + Hcc * d3, Uc, 1.0)
        _add_cyclic(dy, base + nq, i, j, k, d, 1.0, g1, g2, g3)


@leaf
def external_forces(y, dy, i, d, n, n_tan, X, t, w):
    """The force -w grad U(q_i) of an external field U(x, y[, z]) (program t) on body i
    (w its mass for a mass-weighted term, else 1), and its tangent force -w Hess U dq_i."""
    nq = n // 2
    o = i * d
    run_program(X, t, y[o], y[o + 1], y[o + 2] if d == 3 else 0.0)
    if d == 2:
        g = (output(X, t, 1), output(X, t, 2), 0.0)
        H = (output(X, t, 3), output(X, t, 4), 0.0, output(X, t, 5), 0.0, 0.0)
    else:
        g = (output(X, t, 1), output(X, t, 2), output(X, t, 3))
        H = (output(X, t, 4), output(X, t, 5), output(X, t, 6), output(X, t, 7),
             output(X, t, 8), output(X, t, 9))
    add_to(dy, nq + o, d, -w, g)
    for tt in range(n_tan):
        base = n * (1 + tt)
        q = vec(y, base + o, d)
        add_to(dy, base + nq + o, d, -w, (H[0] * q[0] + H[1] * q[1] + H[2] * q[2],
                                          H[1] * q[0] + H[3] * q[1] + H[4] * q[2],
                                          H[2] * q[0] + H[4] * q[1] + H[5] * q[2]))
