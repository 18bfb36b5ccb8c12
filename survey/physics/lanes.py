"""The right-hand side over SIMD lanes: L states at once in flat variable-major arrays
(component i of lane k at Y[i * L + k]), for the compiled driver (numerics.driver).
Every lane gets the bits `system.rhs` gives its state alone: the paper's three bodies in
the plane run loops written for them (full or reduced states), every other system runs
term by term (`general_lanes`); tests/physics/test_system.py holds each path to `rhs`.
"""
from __future__ import annotations

import math

from numba import types
from numba.extending import overload

from ..machine.jit import VECTOR_DOUBLES, helper, lanes, leaf
from ..machine.portable import fma
from .forces import (
    areal_force_lanes,
    areal_lanes,
    areal_tangent_lanes,
    atm_lanes,
    atm_tangent_lanes,
    barrier,
    pair_geometry_lanes,
    pair_tangent_lanes,
    perimetric_lanes,
    perimetric_tangent_lanes,
    power_2,
    profile,
    profile_lanes,
    reciprocals,
)
from .system import (
    _term_params,
    areal_type,
    lead_params,
    par_type,
    rhs,
)
from .expressions import constants_lanes, run_program_lanes
from .terms import AREA, BARRIER, DISTANCE, EXPRESSION, PERIMETER, POSITION, POWER, SIDES


# A batch's lanes: four vectors' worth, 16 in 256-bit vectors (32 cost ~10% more per
# orbit-step there, `bench --only step`, and a lane that finishes idles unless the batch
# has a job left), 32 in 512-bit ones (a 51-orbit task to t = 1000 on Zen 5: 0.33-0.34 s
# in 16 lanes, 0.30 in 32). The compiler's loops over the lanes run as SIMD instructions
# from SIMD_MIN lanes on (the doubles of a vector: 4, or 8 where 512-bit vectors run in
# full, jit.vector_width); with fewer, rhs_lanes runs `rhs` lane by lane, which keeps one
# state's values in registers (the specialised loops at one lane: 5% slower).
SIMD_MIN = VECTOR_DOUBLES
SIMD_LANES = 4 * SIMD_MIN


# A reduced state (three bodies in the plane under one perimetric or areal term,
# `reducible`: bodies 0 and 1 in the centre-of-mass frame, see _lane_positions) is told
# apart by the kernels' last argument rb: the mass ratios m0/m2, m1/m2 that rebuild the
# third body, None for a full state. A type, not a value: numba compiles a kernel once for
# full states and once for reduced ones, each without the other's code: a survey compiles
# only the kind it integrates (a shorter first run).


@helper
def state_size(masses, d, rb):
    """Components of an orbit's (or a tangent vector's) block in the kernel's state: 2 N d,
    or 8 for a reduced state."""
    if rb is None:
        return 2 * masses.size * d
    return 8


@helper
def workspace_size(L, nf, registers=0):
    """Floats of the workspace `rhs_lanes` needs for L lanes of nf components (and a
    system's formula programs' `registers`: their register file in every lane, and a row
    of scratch)."""
    return max((GENERAL_ROWS + registers + (registers > 0)) * L, 2 * nf)


@leaf
def rhs_lanes(t, Y, dY, L, model, n_tan, W, rb):
    """`rhs` for L states at once, stored variable-major (component i of lane k at
    Y[i * L + k]); W: workspace_size(L, nf) floats; rb: None, or the mass ratios of reduced
    states. Three bodies in the plane under one perimetric or areal term (every workflow,
    most of the paper) run loops over the lanes that the compiler turns into SIMD
    instructions (from SIMD_MIN lanes on, and reduced states at any L): the general path's
    operations on the same values in the same order, without its loops, zero z components
    and accumulations, so every lane gets the bits `rhs` gives
    (tests/physics/test_system.py). So does every other system, term by term
    (`general_lanes`: perimetric and areal terms of more bodies or in 3-D, pair and ATM
    terms). Fewer than SIMD_MIN full states run `rhs` lane by lane."""
    if rb is not None:
        _planar_lanes(Y, dY, L, W, model, n_tan, rb)
    else:
        full_lanes(t, Y, dY, L, model, n_tan, W, rb)


# numba prunes a branch on `rb is None` where rb is None, not where rb is the mass ratios:
# a reduced state's kernels would still type, and so compile, the full states' branches
# they never take (`rhs` and its forces: 2 s of a first run). So those branches call
# full_lanes and full_rhs, which compile to nothing where rb is not None.
def full_lanes(t, Y, dY, L, model, n_tan, W, rb):
    """`rhs_lanes` of full states (rb is None); nothing for reduced ones."""


def full_rhs(t, y, dy, model, n_tan, rb):
    """`rhs` of one full state (rb is None); nothing for a reduced one."""


@overload(full_rhs, jit_options=dict(error_model="numpy"), inline="always")
def _full_rhs(t, y, dy, model, n_tan, rb):
    if isinstance(rb, types.NoneType):
        return lambda t, y, dy, model, n_tan, rb: rhs(t, y, dy, model, n_tan)
    return lambda t, y, dy, model, n_tan, rb: None


@overload(full_lanes, jit_options=dict(error_model="numpy"), inline="always")
def _full_lanes_overload(t, Y, dY, L, model, n_tan, W, rb):
    if isinstance(rb, types.NoneType):
        return _full_lanes
    return lambda t, Y, dY, L, model, n_tan, W, rb: None


def _full_lanes(t, Y, dY, L, model, n_tan, W, rb):
    """`full_lanes` (rb None, passed on to _planar_lanes)."""
    masses, d, measure, par = model.masses, model.d, model.measure, model.par
    if L >= SIMD_MIN and masses.size == 3 and d == 2 and par.ndim == 1 and (
            measure == PERIMETER or measure == AREA):
        _planar_lanes(Y, dY, L, W, model, n_tan, rb)
    elif L == 1:
        rhs(t, Y, dY, model, n_tan)
    elif L >= SIMD_MIN and not _sides_formula(model.par):
        general_lanes(Y, dY, L, W, model, n_tan)
    else:
        nf = Y.size // L
        y, dy = W[:nf], W[nf:2 * nf]
        for k in range(L):
            for i in range(nf):
                y[i] = Y[i * L + k]
            rhs(t, y, dy, model, n_tan)
            for i in range(nf):
                dY[i * L + k] = dy[i]


# Any system but the paper's three bodies in the plane under one perimetric or areal term
# (which _planar_lanes runs) in loops over the lanes: sums of pair and ATM terms (the LJAT
# clusters, gravity), alone or beside such a term, and perimetric and areal terms of more
# bodies or in 3-D: each faster in these loops than lane by lane through `rhs` (`bench
# --only terms` sets them side by side). A pair term's loops and a triangle's run in
# functions of their own (_pair_term_lanes, _triplet_term_lanes): in the one that loops
# over the terms, a LJAT trimer's orbit-step ran 10-25% slower. The
# workspace's rows: G the gathered coordinates and deviations (18), P a pair's unit vector
# and distance (4), U the profile's U' and U'' (2), O what is added to the rates (20), T a
# triangle's geometry (13).
GENERAL_ROWS = 57


def _sides_formula(par):
    """Whether a system has a triplet formula in the sides a, b, c (`rhs` runs those lane
    by lane: the other formulas run in the lanes' loops)."""


@overload(_sides_formula, jit_options=dict(error_model="numpy"), inline="always")
def _sides_formula_overload(par):
    if par.ndim == 1:           # the paper's systems: no formulas
        return lambda par: False

    def sides(par):
        for row in range(1, par.shape[0]):
            if int(par[row, 0]) == SIDES and int(par[row, 1]) == EXPRESSION:
                return True
        return False
    return sides


def general_lanes(Y, dY, L, W, model, n_tan):
    """`_general_lanes` of a 2-D par (any system but the paper's: see _encode)."""


@overload(general_lanes, jit_options=dict(error_model="numpy"), inline="always")
def _general_lanes_overload(Y, dY, L, W, model, n_tan):
    if par_type(model).ndim == 1:       # the paper's systems, which _planar_lanes runs
        return lambda Y, dY, L, W, model, n_tan: None

    def run(Y, dY, L, W, model, n_tan):
        masses, d, measure, prof, par = model.masses, model.d, model.measure, model.prof, \
            model.par
        planar = (measure == PERIMETER or measure == AREA) and masses.size == 3 and d == 2
        if planar:      # the velocities and the leading term's forces, as _leading_forces
            _planar_lanes(Y, dY, L, W, model, n_tan, None)
        X = model.expr
        R = W[GENERAL_ROWS * L:]
        formula_constants(X, R, L)
        _general_lanes(Y, dY, L, W[:18 * L], W[18 * L:22 * L], W[22 * L:24 * L],
                       W[24 * L:44 * L], W[44 * L:GENERAL_ROWS * L], masses, d, measure, prof,
                       par, n_tan, planar, X, R)
    return run


@lanes
def _general_lanes(Y, dY, L, G, P, U, O, T, masses, d, measure, prof, par, n_tan, lead, X,
                   R):
    """`rhs` of L full states: the velocities and the leading perimetric or areal term's
    forces (unless `lead`: that term's lanes wrote them), then each further term's forces
    (par's rows 1, ...), as `_leading_forces` and `_rows_forces` give them, term by term
    and pair or triplet by pair or triplet in their order, each in loops over the lanes
    (forces.py's lane kernels), so every lane gets the bits `rhs` gives. A formula's
    values come from its program run over the lanes (X, R: the programs and their
    registers in every lane; None and unused for a system without formulas)."""
    N = masses.size
    nq = N * d
    n = 2 * nq
    if d == 2:          # the z rows the gathers leave alone (forces.vec's 0.0)
        for r in range(2, 18, 3):
            z = G[r * L:(r + 1) * L]
            for k in range(L):
                z[k] = 0.0
    if not lead:
        # a body's d rows are one run of d L values: one loop each (tiny loops cost their
        # setup)
        for b in range(N):
            x = 1.0 / masses[b]
            for t_ in range(1 + n_tan):
                rate, p = dY[(n * t_ + b * d) * L:], Y[(n * t_ + nq + b * d) * L:]
                for k in range(d * L):
                    rate[k] = p[k] * x
        for t_ in range(1 + n_tan):
            force = dY[(n * t_ + nq) * L:(n * t_ + n) * L]
            for k in range(nq * L):
                force[k] = 0.0
        if measure == PERIMETER or measure == AREA:
            _triplet_term_lanes(Y, dY, L, G, T, U, O, N, d, measure, prof,
                                (par[0, 0], par[0, 1]), n_tan, X, R)
    for row in range(1, par.shape[0]):
        kind, code, p = int(par[row, 0]), int(par[row, 1]), _term_params(par, row)
        if kind == POSITION:
            external_lanes(Y, dY, L, R, masses, d, par[row, 2] != 0.0, X, int(p[0]), n_tan)
        elif kind == DISTANCE:
            _pair_term_lanes(Y, dY, L, G, P, U, O, masses, d, code, p, par[row, 2] != 0.0,
                             n_tan, X, R)
        else:
            _triplet_term_lanes(Y, dY, L, G, T, U, O, N, d, kind, code, p, n_tan, X, R)


@lanes
def _pair_term_lanes(Y, dY, L, G, P, U, O, masses, d, code, p, weighted, n_tan, X, R):
    """One pair term's forces, pair i < j by pair, as `_rows_forces` adds them
    (forces.pair_forces)."""
    N = masses.size
    nq = N * d
    n = 2 * nq
    for i in range(N - 1):
        for j in range(i + 1, N):
            w = masses[i] * masses[j] if weighted else 1.0
            _gather(G, 0, Y, (i * d, j * d), d, L)
            pair_geometry_lanes(G, P, L)
            _measure_profile_lanes(code, p, X, R, P[3 * L:], U, L)
            for k in range(L):
                O[k] = w * U[k]
            _pair_sums(dY[(nq + i * d) * L:], dY[(nq + j * d) * L:], O, P, L, d)
            for t_ in range(n_tan):
                base = n * (1 + t_)
                _gather(G, 0, Y, (base + i * d, base + j * d), d, L)
                pair_tangent_lanes(G, P, U, O, L)
                _pair_tangent_sums(dY[(base + nq + i * d) * L:],
                                   dY[(base + nq + j * d) * L:], w, O, L, d)


@lanes
def _triplet_term_lanes(Y, dY, L, G, E, U, O, N, d, measure, prof, par, n_tan, X, R):
    """One perimetric, areal or ATM term's forces, triplet i < j < k by triplet, as
    `_leading_forces` and `_rows_forces` add them (forces.perimetric_forces, areal_forces,
    atm_forces)."""
    nq = N * d
    n = 2 * nq
    for i in range(N - 2):
        for j in range(i + 1, N - 1):
            for k3 in range(j + 1, N):
                bodies = (i, j, k3)
                _gather(G, 0, Y, (i * d, j * d, k3 * d), d, L)
                if measure == PERIMETER:
                    perimetric_lanes(G, E, O, L)
                    _measure_profile_lanes(prof, par, X, R, E[12 * L:], U, L)
                    _add_cyclic_lanes(dY, nq, bodies, d, U, O, L)
                elif measure == AREA:
                    areal_lanes(G, E, L)
                    _measure_profile_lanes(prof, par, X, R, E[3 * L:], U, L)
                    areal_force_lanes(G, E, U, O, L)
                    _add_cyclic_lanes(dY, nq, bodies, d, O, O[L:], L)
                else:
                    atm_lanes(G, O, L, par[0])
                    _add_cyclic_lanes(dY, nq, bodies, d, O, O[L:], L)
                for t_ in range(n_tan):
                    base = n * (1 + t_)
                    _gather(G, 9, Y, (base + i * d, base + j * d, base + k3 * d), d, L)
                    if measure == PERIMETER:
                        perimetric_tangent_lanes(G, E, U, O, L)
                        _add_cyclic_lanes(dY, base + nq, bodies, d, O[9 * L:], O, L)
                        continue
                    # areal: U''(|A|) d|A| times the gradients, then U'(|A|) times their
                    # variations (areal_forces' a and b); ATM: dW times the H's
                    # differences, then W times the dH's
                    if measure == AREA:
                        areal_tangent_lanes(G, E, U, O[10 * L:], L)
                    else:
                        atm_tangent_lanes(G, O[10 * L:], L, par[0])
                    _add_cyclic_lanes(dY, base + nq, bodies, d, O[10 * L:], O[L:], L)
                    _add_cyclic_lanes(dY, base + nq, bodies, d, O, O[11 * L:], L)


@helper
def _measure_profile_lanes(code, par, X, R, x, U, L):
    """U' and U'' (U rows 0, 1) of a pair's or triangle's measure x in every lane: from the
    term's profile, or from its formula's program (code EXPRESSION, par[0] its index)."""
    if code == EXPRESSION:
        program_profile_lanes(X, int(par[0]), R, x, U, L)
    else:
        profile_lanes(code, par, x, U, L)


def formula_constants(X, R, L):
    """`constants_lanes`, or nothing where the system has no formulas (X None)."""


def program_profile_lanes(X, t, R, x, U, L):
    """`_program_profile_lanes`, or nothing where the system has no formulas (X None)."""


def external_lanes(Y, dY, L, R, masses, d, weighted, X, t, n_tan):
    """`_external_lanes`, or nothing where the system has no formulas (X None)."""


# typed on X, as system.formula_forces: a system without formulas compiles none of this
@overload(formula_constants, jit_options=dict(error_model="numpy"), inline="always")
def _formula_constants_overload(X, R, L):
    if isinstance(X, types.NoneType):
        return lambda X, R, L: None
    return lambda X, R, L: constants_lanes(X, R, L)


@overload(program_profile_lanes, jit_options=dict(error_model="numpy"), inline="always")
def _program_profile_overload(X, t, R, x, U, L):
    if isinstance(X, types.NoneType):
        return lambda X, t, R, x, U, L: None
    return lambda X, t, R, x, U, L: _program_profile_lanes(X, t, R, x, U, L)


@overload(external_lanes, jit_options=dict(error_model="numpy"), inline="always")
def _external_overload(Y, dY, L, R, masses, d, weighted, X, t, n_tan):
    if isinstance(X, types.NoneType):
        return lambda Y, dY, L, R, masses, d, weighted, X, t, n_tan: None
    return lambda Y, dY, L, R, masses, d, weighted, X, t, n_tan: _external_lanes(
        Y, dY, L, R, masses, d, weighted, X, t, n_tan)


@leaf
def _program_profile_lanes(X, t, R, x, U, L):
    """forces.expression_profile in every lane: program t at the measures x, its U' and
    U'' into U's rows 0 and 1."""
    into = R[X.inputs[t, 0] * L:]
    for k in range(L):
        into[k] = x[k]
    run_program_lanes(X, t, R, L)
    d1, d2 = R[X.outputs[t, 1] * L:], R[X.outputs[t, 2] * L:]
    for k in range(L):
        U[k] = d1[k]
        U[L + k] = d2[k]


@leaf
def _external_lanes(Y, dY, L, R, masses, d, weighted, X, t, n_tan):
    """forces.external_forces of every body in every lane: program t at each body's
    position, the force -w grad U added to its momentum rates and -w Hess U dq to each
    tangent vector's (the same products and sums, the z terms zero in the plane)."""
    N = masses.size
    nq = N * d
    n = 2 * nq
    out = X.outputs[t]
    for i in range(N):
        w = masses[i] if weighted else 1.0
        o = i * d
        for c in range(d):
            into, q = R[X.inputs[t, c] * L:], Y[(o + c) * L:]
            for k in range(L):
                into[k] = q[k]
        run_program_lanes(X, t, R, L)
        for c in range(d):
            _external_force_lanes(dY[(nq + o + c) * L:], R[out[1 + c] * L:], -w, L)
        for tt in range(n_tan):
            r, q = dY[(n * (1 + tt) + nq + o) * L:], Y[(n * (1 + tt) + o) * L:]
            if d == 2:      # H's (xx, xy, yy)
                _external_tangent_plane(r, r[L:], q, q[L:], R[out[3] * L:], R[out[4] * L:],
                                        R[out[5] * L:], -w, L)
            else:           # (xx, xy, xz, yy, yz, zz)
                _external_tangent_space(r, r[L:], r[2 * L:], q, q[L:], q[2 * L:],
                                        R[out[4] * L:], R[out[5] * L:], R[out[6] * L:],
                                        R[out[7] * L:], R[out[8] * L:], R[out[9] * L:], -w, L)


@lanes
def _external_force_lanes(rate, g, s, L):
    """add_to's rate += s g, every lane."""
    for k in range(L):
        rate[k] += s * g[k]


@lanes
def _external_tangent_plane(r0, r1, q0, q1, Hxx, Hxy, Hyy, s, L):
    """external_forces' tangent force in the plane, every lane: rates += s (H dq), with
    the zero z terms of the scalar kernel's padded vectors (their products summed all the
    same, so the same bits)."""
    for k in range(L):
        a, b = q0[k], q1[k]
        r0[k] += s * (Hxx[k] * a + Hxy[k] * b + 0.0 * 0.0)
        r1[k] += s * (Hxy[k] * a + Hyy[k] * b + 0.0 * 0.0)


@lanes
def _external_tangent_space(r0, r1, r2, q0, q1, q2, Hxx, Hxy, Hxz, Hyy, Hyz, Hzz, s, L):
    """external_forces' tangent force in space, every lane: rates += s (H dq)."""
    for k in range(L):
        a, b, c = q0[k], q1[k], q2[k]
        r0[k] += s * (Hxx[k] * a + Hxy[k] * b + Hxz[k] * c)
        r1[k] += s * (Hxy[k] * a + Hyy[k] * b + Hyz[k] * c)
        r2[k] += s * (Hxz[k] * a + Hyz[k] * b + Hzz[k] * c)


@helper
def _gather(G, r0, Y, offsets, d, L):
    """Coordinates offsets[b] .. + d of each body b into G's rows r0 + 3 b .. (in the plane
    the z rows stay zero, as forces.vec reads them: _general_lanes zeroes them)."""
    for b in range(len(offsets)):
        g, y = G[(r0 + 3 * b) * L:], Y[offsets[b] * L:]
        for k in range(d * L):
            g[k] = y[k]


@lanes
def _pair_sums(fi, fj, S, V, L, d):
    """forces.add_to of a pair's forces to its bodies' d rows from fi and fj: fi += S V,
    fj += (-S) V, each lane with its scale S (two bodies' rows in one loop: as views of one
    array the compiler could not tell them apart)."""
    for c in range(d):
        a, b, v = fi[c * L:], fj[c * L:], V[c * L:]
        for k in range(L):
            a[k] += S[k] * v[k]
            b[k] += -S[k] * v[k]


@lanes
def _pair_tangent_sums(fi, fj, w, V, L, d):
    """As _pair_sums with one scale w for every lane (add_to's w, then -w)."""
    for c in range(d):
        a, b, v = fi[c * L:], fj[c * L:], V[c * L:]
        for k in range(L):
            a[k] += w * v[k]
            b[k] += -w * v[k]


@helper
def _add_cyclic_lanes(dY, off, bodies, d, S, V, L):
    """forces._add_cyclic of every lane: the scale in S's first row, the three bodies'
    differences in V's rows: body b's d components in rows 3 b ..."""
    for b in range(3):
        for c in range(d):
            rate, v = dY[(off + bodies[b] * d + c) * L:], V[(3 * b + c) * L:]
            for k in range(L):
                rate[k] += S[k] * v[k]


@leaf
def _planar_lanes(Y, dY, L, W, model, n_tan, rb):
    """`rhs_lanes` of three bodies in the plane under one perimetric or areal term: full
    states (rb None) or reduced ones (rb: the mass ratios that rebuild the third body)."""
    masses, prof, par = model.masses, model.prof, model.par
    inv = (1.0 / masses[0], 1.0 / masses[1], 1.0 / masses[2])
    nb = 12                                         # a block's components
    if rb is not None:
        nb = 8
    _lead_lanes(Y, dY, L, W, model, prof, lead_params(par), inv, rb, n_tan, nb)


def _lead_lanes(Y, dY, L, W, model, prof, par, inv, rb, n_tan, nb):
    """The leading term's loops, the orbits' then each tangent vector's: perimetric or
    areal as the Model's type says (`Model.areal`), so a system compiles its own kind's
    alone (the other's cost a first run 2-3 s)."""


@overload(_lead_lanes, jit_options=dict(error_model="numpy"), inline="always")
def _lead_lanes_overload(Y, dY, L, W, model, prof, par, inv, rb, n_tan, nb):
    if areal_type(model):
        def areal(Y, dY, L, W, model, prof, par, inv, rb, n_tan, nb):
            _areal_orbits(Y, dY, L, W, prof, par, inv, rb)
            for t in range(1, 1 + n_tan):
                _areal_tangent(Y, Y[nb * L * t:], dY[nb * L * t:], L, W, inv, rb)
        return areal

    def perimetric(Y, dY, L, W, model, prof, par, inv, rb, n_tan, nb):
        _perimetric_orbits(Y, dY, L, W, prof, par, inv, rb)
        for t in range(1, 1 + n_tan):
            _perimetric_tangent(Y[nb * L * t:], dY[nb * L * t:], L, W, inv, rb)
    return perimetric


# The loops over the lanes below are separate compiled functions, not inlined helpers:
# numba vectorises each alone, but not all of them inlined into one function (the tangent
# loop ran several times slower inside the whole right-hand side). Each is given distinct
# arrays (`lanes`: compiled as such, so vectorised from 4 lanes on). The orbits' forces take
# one loop (geometry, profile, forces, velocities; as five loops, their calls cost more than
# their arithmetic), but for profiles other than x^2/2 (the paper's P^2/2 and |A|^2/2) and
# the barrier: a branch on the profile inside a loop keeps it scalar, so each of those has a
# loop of its own, and any other takes three.

# A reduced state (rb: the mass ratios m0/m2, m1/m2) holds bodies 0 and 1 alone, positions
# then momenta (8 rows), the centre of mass at rest at 0: body 2 is rebuilt from them where
# needed, and its rates are not computed. rb is None for the full state (12 rows): numba
# compiles each loop once per kind, the branches on rb pruned.

@helper
def _lane_positions(Y, L, k, rb):
    """Lane k's three positions (of the orbit, or of a tangent vector's deviations)."""
    x0, y0, x1, y1 = Y[k], Y[L + k], Y[2 * L + k], Y[3 * L + k]
    if rb is None:
        return x0, y0, x1, y1, Y[4 * L + k], Y[5 * L + k]
    return x0, y0, x1, y1, -fma(rb[0], x0, rb[1] * x1), -fma(rb[0], y0, rb[1] * y1)


@helper
def _forces_row(rb):
    """The first momentum row: 6 in a full state, 4 in a reduced one."""
    return 6 if rb is None else 4


@helper
def _lane_velocities(y, dy, L, k, inv, rb):
    """dq/dt = p/m of lane k's block (the orbit's or a tangent vector's; inv: 1/m)."""
    P = _forces_row(rb)
    dy[k] = y[P * L + k] * inv[0]
    dy[L + k] = y[(P + 1) * L + k] * inv[0]
    dy[2 * L + k] = y[(P + 2) * L + k] * inv[1]
    dy[3 * L + k] = y[(P + 3) * L + k] * inv[1]
    if rb is None:
        dy[4 * L + k] = y[10 * L + k] * inv[2]
        dy[5 * L + k] = y[11 * L + k] * inv[2]


@lanes
def _perimetric_orbits(Y, dY, L, W, prof, par, inv, rb):
    """forces.perimetric_forces of bodies (0, 1, 2) in the plane and the velocities, lane by
    lane, the leading `0.0 +` of each force keeping the general path's zero signs (it adds
    into zeros). W rows: e1x e1y e2x e2y e3x e3y 1/L1 1/L2 1/L3 P U' U'' U'/L1 U'/L2
    U'/L3 (the tangent vectors' loops read the unit vectors, U'' and U'/L_i; 1/L_i, P and
    U' are stored by the general profile's loops only)."""
    if prof == POWER and par[1] == 2.0:
        for k in range(L):
            e, s, r = _triangle_sides(Y, L, W, k, rb)
            _, U1, U2 = power_2(par[0], s[0] + s[1] + s[2])
            _perimetric_lane(Y, dY, L, W, k, inv, e, r, U1, U2, rb)
    elif prof == BARRIER:
        for k in range(L):
            e, s, r = _triangle_sides(Y, L, W, k, rb)
            _, U1, U2 = barrier(par[0], par[1], s[0] + s[1] + s[2])
            _perimetric_lane(Y, dY, L, W, k, inv, e, r, U1, U2, rb)
    else:
        for k in range(L):
            _, s, r = _triangle_sides(Y, L, W, k, rb)
            W[6 * L + k], W[7 * L + k], W[8 * L + k] = r
            W[9 * L + k] = s[0] + s[1] + s[2]
        for k in range(L):
            _, W[10 * L + k], W[11 * L + k] = profile(prof, par, W[9 * L + k])
        for k in range(L):
            e = (W[k], W[L + k], W[2 * L + k], W[3 * L + k], W[4 * L + k], W[5 * L + k])
            r = (W[6 * L + k], W[7 * L + k], W[8 * L + k])
            _perimetric_lane(Y, dY, L, W, k, inv, e, r, W[10 * L + k], W[11 * L + k], rb)


@helper
def _triangle_sides(Y, L, W, k, rb):
    """Lane k's side unit vectors into W (rows 0-5), and returned with its side lengths and
    their reciprocals (forces.reciprocals).
    (A loop that reads back what it wrote to other rows of W runs scalar -- the compiler
    cannot tell the rows apart, L being a run-time value --, and so does the loop of the
    paper's profile with the lengths stored too: the general profile's loops store them.)"""
    ux, uy, vx, vy, wx, wy = _lane_positions(Y, L, k, rb)
    ax, ay = vx - ux, vy - uy           # v - u
    bx, by = wx - vx, wy - vy           # w - v
    cx, cy = ux - wx, uy - wy           # u - w
    L1 = math.sqrt(ax * ax + ay * ay)
    L2 = math.sqrt(bx * bx + by * by)
    L3 = math.sqrt(cx * cx + cy * cy)
    r1, r2, r3 = reciprocals(L1, L2, L3)
    e = (ax * r1, ay * r1, bx * r2, by * r2, cx * r3, cy * r3)
    W[k], W[L + k], W[2 * L + k], W[3 * L + k], W[4 * L + k], W[5 * L + k] = e
    return e, (L1, L2, L3), (r1, r2, r3)


@helper
def _perimetric_lane(Y, dY, L, W, k, inv, e, r, U1, U2, rb):
    """Lane k's velocities and forces from its side unit vectors e and 1 / lengths r (U1,
    U2: U', U'' at its perimeter), and U'', U'/L_i into W for its tangent vectors."""
    W[11 * L + k] = U2
    W[12 * L + k], W[13 * L + k], W[14 * L + k] = U1 * r[0], U1 * r[1], U1 * r[2]
    _lane_velocities(Y, dY, L, k, inv, rb)
    e1x, e1y, e2x, e2y, e3x, e3y = e
    P = _forces_row(rb)
    dY[P * L + k] = 0.0 + U1 * (e1x - e3x)
    dY[(P + 1) * L + k] = 0.0 + U1 * (e1y - e3y)
    dY[(P + 2) * L + k] = 0.0 + U1 * (e2x - e1x)
    dY[(P + 3) * L + k] = 0.0 + U1 * (e2y - e1y)
    if rb is None:
        dY[10 * L + k] = 0.0 + U1 * (e3x - e2x)
        dY[11 * L + k] = 0.0 + U1 * (e3y - e2y)


@lanes
def _perimetric_tangent(y, dy, L, W, inv, rb):
    """One tangent vector's block (y, dy start at it): velocities and tangent forces."""
    P = _forces_row(rb)
    for k in range(L):
        _lane_velocities(y, dy, L, k, inv, rb)
        e1x, e1y, e2x, e2y = W[k], W[L + k], W[2 * L + k], W[3 * L + k]
        e3x, e3y, U2 = W[4 * L + k], W[5 * L + k], W[11 * L + k]
        s1, s2, s3 = W[12 * L + k], W[13 * L + k], W[14 * L + k]
        dux, duy, dvx, dvy, dwx, dwy = _lane_positions(y, L, k, rb)
        p1x, p1y = dvx - dux, dvy - duy
        p2x, p2y = dwx - dvx, dwy - dvy
        p3x, p3y = dux - dwx, duy - dwy
        d1 = e1x * p1x + e1y * p1y
        d2 = e2x * p2x + e2y * p2y
        d3 = e3x * p3x + e3y * p3y
        dP = d1 + d2 + d3
        c1, c2, c3 = U2 * dP - s1 * d1, U2 * dP - s2 * d2, U2 * dP - s3 * d3
        g1x, g1y = c1 * e1x + s1 * p1x, c1 * e1y + s1 * p1y
        g2x, g2y = c2 * e2x + s2 * p2x, c2 * e2y + s2 * p2y
        g3x, g3y = c3 * e3x + s3 * p3x, c3 * e3y + s3 * p3y
        dy[P * L + k] = 0.0 + (g1x - g3x)
        dy[(P + 1) * L + k] = 0.0 + (g1y - g3y)
        dy[(P + 2) * L + k] = 0.0 + (g2x - g1x)
        dy[(P + 3) * L + k] = 0.0 + (g2y - g1y)
        if rb is None:
            dy[10 * L + k] = 0.0 + (g3x - g2x)
            dy[11 * L + k] = 0.0 + (g3y - g2y)


@lanes
def _areal_orbits(Y, dY, L, W, prof, par, inv, rb):
    """forces.areal_forces of bodies (0, 1, 2) in the plane and the velocities, lane by
    lane (see _perimetric_orbits): there the area vector and its unit vector have z
    components only. W rows: Ahat_z, 1/|A|, |A|, U', U''."""
    if prof == POWER and par[1] == 2.0:
        for k in range(L):
            hz, absA = _triangle_area(Y, L, W, k, rb)
            _, U1, U2 = power_2(par[0], absA)
            _areal_lane(Y, dY, L, W, k, inv, hz, U1, U2, rb)
    elif prof == BARRIER:
        for k in range(L):
            hz, absA = _triangle_area(Y, L, W, k, rb)
            _, U1, U2 = barrier(par[0], par[1], absA)
            _areal_lane(Y, dY, L, W, k, inv, hz, U1, U2, rb)
    else:
        for k in range(L):
            _triangle_area(Y, L, W, k, rb)
        for k in range(L):
            _, W[3 * L + k], W[4 * L + k] = profile(prof, par, W[2 * L + k])
        for k in range(L):
            _areal_lane(Y, dY, L, W, k, inv, W[k], W[3 * L + k], W[4 * L + k], rb)


@helper
def _triangle_area(Y, L, W, k, rb):
    """Lane k's Ahat_z, 1/|A| and |A| into W (rows 0-2); returns Ahat_z and |A|."""
    ux, uy, vx, vy, wx, wy = _lane_positions(Y, L, k, rb)
    ax, ay = vx - ux, vy - uy           # v - u
    bx, by = wx - ux, wy - uy           # w - u
    Az = 0.5 * (ax * by - ay * bx)
    absA = math.sqrt(Az * Az)
    inv = 1.0 / absA if absA > 0.0 else 0.0
    hz = Az * inv
    W[k], W[L + k], W[2 * L + k] = hz, inv, absA
    return hz, absA


@helper
def _areal_lane(Y, dY, L, W, k, inv, hz, U1, U2, rb):
    """Lane k's velocities and forces from its area's unit vector hz (U1, U2: U', U'' at
    |A|), and U', U'' into W for its tangent vectors."""
    W[3 * L + k], W[4 * L + k] = U1, U2
    _lane_velocities(Y, dY, L, k, inv, rb)
    f = -0.5 * U1
    sv, sw, su = _areal_sides(Y, L, k, rb)
    # (v - w) x Ahat: twice grad_u |A|, and cyclic
    P = _forces_row(rb)
    dY[P * L + k] = 0.0 + f * (sv[1] * hz)
    dY[(P + 1) * L + k] = 0.0 + f * -(sv[0] * hz)
    dY[(P + 2) * L + k] = 0.0 + f * (sw[1] * hz)
    dY[(P + 3) * L + k] = 0.0 + f * -(sw[0] * hz)
    if rb is None:
        dY[10 * L + k] = 0.0 + f * (su[1] * hz)
        dY[11 * L + k] = 0.0 + f * -(su[0] * hz)


@helper
def _areal_sides(Y, L, k, rb):
    """Lane k's v - w, w - u, u - v."""
    ux, uy, vx, vy, wx, wy = _lane_positions(Y, L, k, rb)
    return (vx - wx, vy - wy), (wx - ux, wy - uy), (ux - vx, uy - vy)


@lanes
def _areal_tangent(Y, y, dy, L, W, inv, rb):
    """One tangent vector's block (y, dy start at it; Y is the orbit): velocities and
    tangent forces."""
    P = _forces_row(rb)
    for k in range(L):
        _lane_velocities(y, dy, L, k, inv, rb)
        hz, inv_a = W[k], W[L + k]
        f, g = -0.5 * W[3 * L + k], -0.5 * W[4 * L + k]
        (svx, svy), (swx, swy), (sux, suy) = _areal_sides(Y, L, k, rb)
        dux, duy, dvx, dvy, dwx, dwy = _lane_positions(y, L, k, rb)
        dAz = 0.5 * ((dux * svy - duy * svx) + (dvx * swy - dvy * swx)
                     + (dwx * suy - dwy * sux))
        dabs = hz * dAz
        dhz = (-dabs * inv_a) * hz + dAz * inv_a
        a = g * dabs
        dy[P * L + k] = (0.0 + a * (svy * hz)) + f * ((dvy - dwy) * hz + svy * dhz)
        dy[(P + 1) * L + k] = (0.0 + a * -(svx * hz)) + f * (-((dvx - dwx) * hz)
                                                             + -(svx * dhz))
        dy[(P + 2) * L + k] = (0.0 + a * (swy * hz)) + f * ((dwy - duy) * hz + swy * dhz)
        dy[(P + 3) * L + k] = (0.0 + a * -(swx * hz)) + f * (-((dwx - dux) * hz)
                                                             + -(swx * dhz))
        if rb is None:
            dy[10 * L + k] = (0.0 + a * (suy * hz)) + f * ((duy - dvy) * hz + suy * dhz)
            dy[11 * L + k] = (0.0 + a * -(sux * hz)) + f * (-((dux - dvx) * hz)
                                                            + -(sux * dhz))
