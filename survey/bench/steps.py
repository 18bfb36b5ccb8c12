"""Where a step goes (right-hand sides, stage sums, the rest) in lanes, and one orbit's step
against the same step in plain scalar code."""
from __future__ import annotations


import math

import numpy as np

from ..numerics.dop853 import (A2, A3, A4, A5, A6, A7, A8, A9, A10, A11, A12, B, BETA_ROOTS,
                              BHH1, BHH2, BHH3, ER, ERR_FLOOR_ROOT, stage_dot, error_norms, stages)
from ..numerics.indicators import deviation_vectors
from ..numerics.integrate import Frame, integrate, integrate_batch
from ..numerics.lanestate import aligned_zeros
from ..physics.families import initial_state
from ..machine import portable
from ..machine.jit import helper, kernel, lanes, leaf
from ..machine.portable import fma
from ..physics.lanes import rhs_lanes, state_size, workspace_size
from ..physics.system import System
from .common import CASES, best_time, checked


@leaf
def _rhs_loop(Y, K, W, reps, L, model, n_tan, rb):
    """reps times the 12 right-hand-side evaluations of a step of L lanes, at one state (rb:
    the reduced states' mass ratios, as the driver runs the paper's systems), into K's
    rows; W: the workspace. Without reference counting, as the driver (the rows' views
    would each cost an atomic increment and decrement)."""
    for _ in range(reps):
        for s in range(12):
            rhs_lanes(0.0, Y, K[s], L, model, n_tan, W, rb)
    return K[11, 0]


@kernel
def _stage_loop(Y, reps, h, L, model, n_tan, rb):
    """reps times a step's stages and error norms of L lanes, from one state."""
    nf = Y.size // L
    K, YT, YN = np.zeros((16, Y.size)), np.zeros(Y.size), np.zeros(Y.size)
    W, S = np.zeros(workspace_size(L, nf)), np.zeros(2 * (nf + 1) * L)
    H, err = np.full(L, h), np.zeros(L)
    HH = np.full(Y.size, h)
    rhs_lanes(0.0, Y, K[0], L, model, n_tan, W, rb)
    acc = 0.0
    for _ in range(reps):
        stages(model, n_tan, L, Y, HH, K, YT, YN, W, rb)
        error_norms(Y, YN, K, L, state_size(model.masses, model.d, rb), 1e-12, 1e-12, H, err, S)
        acc += err[0]
    return acc


@helper
def _plain_forces(y):
    """The paper's system written plainly for the step baselines: three unit masses in the
    plane, U = P^2/2, the relative motion (bodies 0 and 1 in the centre-of-mass frame, the
    third at -(q0 + q1)) and one tangent vector; 16 components, as survey integrates it.
    Values in (y indexable), values out: the scalar baseline stores them in an array, the
    lanes' probe in its lane of the rows (`_put`)."""
    ux, uy, vx, vy = y[0], y[1], y[2], y[3]
    wx, wy = -(ux + vx), -(uy + vy)
    ax, ay, bx, by, cx, cy = vx - ux, vy - uy, wx - vx, wy - vy, ux - wx, uy - wy
    L1, L2, L3 = math.sqrt(ax * ax + ay * ay), math.sqrt(bx * bx + by * by), \
        math.sqrt(cx * cx + cy * cy)
    L23 = L2 * L3               # physics.forces.reciprocals without its exact rescaling
    q = 1.0 / (L1 * L23)
    r1, r2, r3 = q * L23, q * (L1 * L3), q * (L1 * L2)
    e1x, e1y, e2x, e2y, e3x, e3y = ax * r1, ay * r1, bx * r2, by * r2, cx * r3, cy * r3
    U1 = L1 + L2 + L3                               # U' = P, U'' = 1
    s1, s2, s3 = U1 * r1, U1 * r2, U1 * r3
    dux, duy, dvx, dvy = y[8], y[9], y[10], y[11]
    dwx, dwy = -(dux + dvx), -(duy + dvy)
    p1x, p1y, p2x, p2y, p3x, p3y = dvx - dux, dvy - duy, dwx - dvx, dwy - dvy, dux - dwx, \
        duy - dwy
    d1, d2, d3 = e1x * p1x + e1y * p1y, e2x * p2x + e2y * p2y, e3x * p3x + e3y * p3y
    dP = d1 + d2 + d3
    c1, c2, c3 = dP - s1 * d1, dP - s2 * d2, dP - s3 * d3
    g1x, g1y = c1 * e1x + s1 * p1x, c1 * e1y + s1 * p1y
    g2x, g2y = c2 * e2x + s2 * p2x, c2 * e2y + s2 * p2y
    g3x, g3y = c3 * e3x + s3 * p3x, c3 * e3y + s3 * p3y
    return (y[4], y[5], y[6], y[7], U1 * (e1x - e3x), U1 * (e1y - e3y),
            U1 * (e2x - e1x), U1 * (e2y - e1y), y[12], y[13], y[14], y[15],
            g1x - g3x, g1y - g3y, g2x - g1x, g2y - g1y)


@helper
def _put(out, L, k, d):
    """The 16 values d into lane k of out (L lanes, variable-major; L = 1: one orbit)."""
    out[k], out[L + k], out[2 * L + k], out[3 * L + k] = d[0], d[1], d[2], d[3]
    out[4 * L + k], out[5 * L + k], out[6 * L + k], out[7 * L + k] = d[4], d[5], d[6], d[7]
    out[8 * L + k], out[9 * L + k], out[10 * L + k], out[11 * L + k] = d[8], d[9], d[10], d[11]
    out[12 * L + k], out[13 * L + k], out[14 * L + k], out[15 * L + k] = \
        d[12], d[13], d[14], d[15]


@helper
def _plain_rhs(y, dy):
    _put(dy, 1, 0, _plain_forces(y))


@helper
def _plain_stage(y, yt, K, h, comb, s):
    """Stage s of `_plain_dop853` from the tableau row comb (a helper, as numba cannot loop
    over the rows: each is a tuple of its own length)."""
    for i in range(y.size):
        yt[i] = fma(h, stage_dot(K, i, comb), y[i])
    _plain_rhs(yt, K[s])


@kernel
def _plain_dop853(z, t1, tol, h):
    """The baseline of a scalar step: DOP853 as plain code for one orbit of `_plain_rhs` --
    one function, fixed sizes, the right-hand side inlined, survey's tableau sums, error
    norm (over the orbit's 8 components) and step control, the tangent's log norm summed
    at each step, and nothing else (no events, samples, budgets, statuses or lanes).
    Returns the attempted steps, the sum (kept so the compiler cannot drop it) and the
    final state."""
    n = 16
    y, yt, yn, K = z.copy(), np.empty(n), np.empty(n), np.empty((13, n))
    _plain_rhs(y, K[0])
    t, err_old, attempts, acc = 0.0, ERR_FLOOR_ROOT, 0, 0.0
    while t < t1:
        if t + h >= t1:
            h = t1 - t
        attempts += 1
        _plain_stage(y, yt, K, h, A2, 1)
        _plain_stage(y, yt, K, h, A3, 2)
        _plain_stage(y, yt, K, h, A4, 3)
        _plain_stage(y, yt, K, h, A5, 4)
        _plain_stage(y, yt, K, h, A6, 5)
        _plain_stage(y, yt, K, h, A7, 6)
        _plain_stage(y, yt, K, h, A8, 7)
        _plain_stage(y, yt, K, h, A9, 8)
        _plain_stage(y, yt, K, h, A10, 9)
        _plain_stage(y, yt, K, h, A11, 10)
        _plain_stage(y, yt, K, h, A12, 11)
        for i in range(n):
            yn[i] = fma(h, stage_dot(K, i, B), y[i])
        e3 = e5 = 0.0
        for i in range(8):
            isk = 1.0 / fma(tol, max(abs(y[i]), abs(yn[i])), tol)
            er3 = fma(-BHH3, K[11, i], fma(-BHH2, K[8, i], fma(-BHH1, K[0, i], stage_dot(K, i, B))))
            er3, er5 = er3 * isk, stage_dot(K, i, ER) * isk
            e3, e5 = e3 + er3 * er3, e5 + er5 * er5
        err = abs(h) * e5 / math.sqrt(8 * (e5 + 0.01 * e3)) if e5 + e3 > 0.0 else 0.0
        r8, r128 = portable.root8(max(err, 1e-10))
        _plain_rhs(yn, K[12])
        if err <= 1.0:
            t += h
            for i in range(n):
                y[i], K[0, i] = yn[i], K[12, i]
            w = 0.0
            for i in range(8, n):
                w += y[i] * y[i]
            acc += portable.log(w) * h
            fac = 0.9 * r128 / r8 * portable.ipow(err_old, BETA_ROOTS)
            err_old = r128 if err >= 1e-4 else ERR_FLOOR_ROOT
            h *= min(6.0, max(1.0 / 3.0, fac))
        else:
            h *= max(1.0 / 3.0, 0.9 / r8)
    return attempts, acc, y


class _Counted(float):
    """A float that counts the arithmetic done with it (`step_flops`), and apart from it
    the divisions and square roots (`divider_ops`)."""
    ops = divisions = roots = 0

    def _op(f, division=False):
        def op(a, b):
            _Counted.ops += 1
            _Counted.divisions += division
            return _Counted(f(float(a), float(b)))
        return op

    __add__ = __radd__ = _op(float.__add__)
    __sub__ = _op(float.__sub__)
    __rsub__ = _op(float.__rsub__)
    __mul__ = __rmul__ = _op(float.__mul__)
    __truediv__ = _op(float.__truediv__, True)
    __rtruediv__ = _op(float.__rtruediv__, True)

    def __neg__(a):             # a sign flip, no arithmetic
        return _Counted(-float(a))


def _counted_forces(n=16) -> tuple[int, int, int]:
    """One evaluation of `_plain_forces` on counting numbers: its operations (a square root
    one), divisions and square roots."""
    import types as pytypes

    class CountingMath:
        @staticmethod
        def sqrt(x):
            _Counted.ops += 1
            _Counted.roots += 1
            return _Counted(math.sqrt(float(x)))

    f = _plain_forces.py_func
    counted = pytypes.FunctionType(f.__code__, {**f.__globals__, "math": CountingMath})
    y = [_Counted(0.3 + 0.1 * i) for i in range(n)]
    _Counted.ops = _Counted.divisions = _Counted.roots = 0
    counted(y)
    return _Counted.ops, _Counted.divisions, _Counted.roots


def step_flops(n=16, n_err=8) -> tuple[int, int]:
    """Floating-point operations (an FMA two) of one DOP853 step of the paper's reduced
    system with a tangent vector (n components, the first n_err error-controlled): the 12
    right-hand sides, counted by running `_plain_forces`'s source on counting numbers (a
    square root one operation), and the stage sums from the tableau -- a stage whose row
    has m terms costs 2m + 1 a component (m products, m - 1 sums, the multiply-add of h),
    the solution's row the same, the error norm 45 an error-controlled component (1/sk: a
    multiply-add and a division; the solution's sum again, 15; three multiply-adds and a
    product for the 3rd-order estimate, the 8 terms of ER and a product for the 5th; two
    squares and two sums). Returns (right-hand sides, stage sums and norm)."""
    rhs = 12 * _counted_forces(n)[0]
    rows = (A2, A3, A4, A5, A6, A7, A8, A9, A10, A11, A12, B)
    combos = n * sum(2 * len(idx) + 1 for idx, _ in rows) + 45 * n_err
    return rhs, combos


def divider_ops(n=16, n_err=8) -> tuple[int, int]:
    """Of `step_flops`' operations, the divisions and square roots (the core's divider runs
    them, at a fraction of the multiply-adds' rate): the 12 right-hand sides' and the
    error norm's (a division an error-controlled component, and a square root and a
    division for the lane's norm). Returns (divisions, square roots)."""
    _, divisions, roots = _counted_forces(n)
    return 12 * divisions + n_err + 1, 12 * roots + 1


@leaf
def _fma_chains(x, reps, a, b):
    """reps rounds of 8 multiply-adds x[i] = fma(x[i], a, b) on each of x's lanes: x.size
    independent chains in a flat array, as the lanes' loops run them, each value kept in a
    register for its 8 (the core's peak FMA rate, `fma_peak`)."""
    for _ in range(reps):
        for i in range(x.size):
            v = x[i]
            for _ in range(8):
                v = fma(v, a, b)
            x[i] = v
    return x[0]


def fma_peak(repeats=5, full_width=False) -> float:
    """The core's peak rate of floating-point operations (an FMA two) in vectorised
    multiply-adds: 64 independent chains (enough to cover an FMA's latency on both
    pipes), best of `repeats`; at the vector width survey compiles for, or (full_width)
    at the widest the core has, measured in a process compiled for it (an AVX-512 core
    that survey runs at 256 bits: machine.jit.vector_width)."""
    if full_width:
        import sys
        import tempfile

        from llvmlite import binding as llvm

        from .common import user_env
        features = llvm.get_host_cpu_features()
        if not features.get("avx512f"):
            return fma_peak(repeats)
        with tempfile.TemporaryDirectory() as cache:
            env = user_env(NUMBA_CACHE_DIR=cache, NUMBA_CPU_NAME=llvm.get_host_cpu_name(),
                           NUMBA_CPU_FEATURES=features.flatten() + ",-prefer-256-bit")
            code = f"from survey.bench.steps import fma_peak; print(fma_peak({repeats}))"
            return float(checked([sys.executable, "-c", code], env).split()[-1])
    x, reps = np.full(64, 0.5), 100_000
    _fma_chains(x, 1, 0.999999, 1e-7)
    best, _ = best_time(lambda: _fma_chains(x, reps, 0.999999, 1e-7), repeats)
    return 2 * 8 * x.size * reps / best


@leaf
def _divider_chains(x, reps, root):
    """reps rounds of a square root (root) or a reciprocal on each of x's lanes, x[i] =
    sqrt(x[i]) or 1 / x[i]: independent chains in a flat array, as the lanes' loops run
    them (`divider_rates`)."""
    for _ in range(reps):
        if root:
            for i in range(x.size):
                x[i] = math.sqrt(x[i])
        else:
            for i in range(x.size):
                x[i] = 1.0 / x[i]
    return x[0]


def divider_rates(repeats=5) -> tuple[float, float]:
    """Seconds a lane of a division and of a square root in vectorised loops (64 independent
    chains, enough to keep the divider busy; best of `repeats`): the divider runs them, not
    the multiply-add pipes, at a fraction of their rate."""
    rates = []
    for root in (False, True):
        x, reps = np.linspace(1.5, 2.5, 64), 100_000
        _divider_chains(x, 1, root)
        best, _ = best_time(lambda: _divider_chains(x, reps, root), repeats)
        rates.append(best / (x.size * reps))
    return rates[0], rates[1]


# The probe of a step's arithmetic alone (`arithmetic_probe`): the step of `_plain_dop853`
# in L lanes, variable-major as survey's, each stage's sums and right-hand side in one loop
# over the lanes that keeps a lane's 16 values in registers (no stage state stored and read
# back), then the solution and the error norm; nothing else -- no step control, finiteness,
# tangent norms, events or bookkeeping, one h for every lane.

@helper
def _staged(Y, K, h, L, k, comb, i):
    j = i * L + k
    return fma(h, stage_dot(K, j, comb), Y[j])


@helper
def _stage_values(Y, K, h, L, k, comb):
    """Lane k's 16 values at the stage whose tableau row is comb."""
    return (_staged(Y, K, h, L, k, comb, 0), _staged(Y, K, h, L, k, comb, 1),
            _staged(Y, K, h, L, k, comb, 2), _staged(Y, K, h, L, k, comb, 3),
            _staged(Y, K, h, L, k, comb, 4), _staged(Y, K, h, L, k, comb, 5),
            _staged(Y, K, h, L, k, comb, 6), _staged(Y, K, h, L, k, comb, 7),
            _staged(Y, K, h, L, k, comb, 8), _staged(Y, K, h, L, k, comb, 9),
            _staged(Y, K, h, L, k, comb, 10), _staged(Y, K, h, L, k, comb, 11),
            _staged(Y, K, h, L, k, comb, 12), _staged(Y, K, h, L, k, comb, 13),
            _staged(Y, K, h, L, k, comb, 14), _staged(Y, K, h, L, k, comb, 15))


@lanes
def _probe_stage(Y, K, h, L, comb, out):
    """One stage of every lane: its sums and its right-hand side into out (a row of K)."""
    for k in range(L):
        _put(out, L, k, _plain_forces(_stage_values(Y, K, h, L, k, comb)))


@lanes
def _probe_rhs(Y, L, out):
    """The right-hand side of every lane of Y into out."""
    for k in range(L):
        _put(out, L, k, _plain_forces((
            Y[k], Y[L + k], Y[2 * L + k], Y[3 * L + k], Y[4 * L + k], Y[5 * L + k],
            Y[6 * L + k], Y[7 * L + k], Y[8 * L + k], Y[9 * L + k], Y[10 * L + k],
            Y[11 * L + k], Y[12 * L + k], Y[13 * L + k], Y[14 * L + k], Y[15 * L + k])))


@lanes
def _probe_solution(Y, K, h, L, tol, YN, sq3, sq5, err):
    """Every lane's 8th-order solution into YN and its error norm (over the orbit's 8
    components) into err, as `_plain_dop853` computes them: the squared terms of every
    lane in one loop (sq3, sq5: 8 L each), then each lane's sums in its components'
    order."""
    for i in range(Y.size):
        YN[i] = fma(h, stage_dot(K, i, B), Y[i])
    for i in range(8 * L):
        isk = 1.0 / fma(tol, max(abs(Y[i]), abs(YN[i])), tol)
        er3 = fma(-BHH3, K[11, i], fma(-BHH2, K[8, i], fma(-BHH1, K[0, i], stage_dot(K, i, B))))
        er3, er5 = er3 * isk, stage_dot(K, i, ER) * isk
        sq3[i], sq5[i] = er3 * er3, er5 * er5
    for k in range(L):
        e3 = e5 = 0.0
        for c in range(8):
            e3, e5 = e3 + sq3[c * L + k], e5 + sq5[c * L + k]
        err[k] = abs(h) * e5 / math.sqrt(8 * (e5 + 0.01 * e3)) if e5 + e3 > 0.0 else 0.0


@leaf
def _probe_steps(Y, K, YN, sq, err, h, tol, L, reps):
    """reps steps of every lane from Y (K[0] holding f(Y)): their arithmetic alone."""
    for _ in range(reps):
        _probe_stage(Y, K, h, L, A2, K[1])
        _probe_stage(Y, K, h, L, A3, K[2])
        _probe_stage(Y, K, h, L, A4, K[3])
        _probe_stage(Y, K, h, L, A5, K[4])
        _probe_stage(Y, K, h, L, A6, K[5])
        _probe_stage(Y, K, h, L, A7, K[6])
        _probe_stage(Y, K, h, L, A8, K[7])
        _probe_stage(Y, K, h, L, A9, K[8])
        _probe_stage(Y, K, h, L, A10, K[9])
        _probe_stage(Y, K, h, L, A11, K[10])
        _probe_stage(Y, K, h, L, A12, K[11])
        _probe_solution(Y, K, h, L, tol, YN, sq[0], sq[1], err)
        _probe_rhs(YN, L, K[12])
    return err[0]


def _chaotic_start():
    """The chaotic orbit of CASES with a tangent vector: its system, start and the 16
    components survey integrates (the relative motion and its deviation), with its frame."""
    system = System.create()
    y0 = initial_state(system, CASES[0][1], **CASES[0][2])
    w = deviation_vectors(system, y0, 1, seed=0)
    frame = Frame.of(system, y0[None], w[None], [])
    return system, y0, frame.reduce(np.concatenate([y0, w[0]])[None], 1)[0], frame


def arithmetic_probe(lanes=16, repeats=5, h=1e-3, reps=20_000):
    """ns per orbit-step of a step's arithmetic alone (`_probe_steps`) in `lanes` lanes of
    the chaotic orbit's start with a tangent, best of `repeats`; and every lane's state
    after one step of h (which `_plain_dop853` must reproduce bit for bit: the probe does
    the step's arithmetic, all of it)."""
    _, _, z, _ = _chaotic_start()
    # on cache lines, as the driver's buffers (lanestate.aligned_zeros: numpy's own start
    # moved the probe's time by a tenth from one process to the next)
    Y, K = aligned_zeros(z.size * lanes), aligned_zeros((13, z.size * lanes))
    YN, err, sq = aligned_zeros(Y.size), aligned_zeros(lanes), aligned_zeros((2, 8 * lanes))
    Y[:] = np.repeat(z[:, None], lanes, 1).ravel()
    _probe_rhs(Y, lanes, K[0])
    _probe_steps(Y, K, YN, sq, err, h, 1e-12, lanes, 1)
    after = YN.reshape(z.size, lanes).T.copy()
    best, _ = best_time(lambda: _probe_steps(Y, K, YN, sq, err, h, 1e-12, lanes, reps),
                        repeats)
    return 1e9 * best / (reps * lanes), after


def plain_step(t_final, repeats):
    """ns per attempted step of `_plain_dop853` on the chaotic orbit of CASES, with a
    tangent vector (best of `repeats`), its steps, and its relative motion and survey's at
    t_final (8 components each)."""
    system, y0, z, frame = _chaotic_start()
    _plain_dop853(z, 1.0, 1e-12, 1e-3)
    best, (steps, _, y) = best_time(lambda: _plain_dop853(z, t_final, 1e-12, 1e-3), repeats)
    ref = integrate(system, y0, t_final)
    return 1e9 * best / steps, steps, y[:8], frame.reduce(ref.y[None], 0)[0]


def step_costs(t_final=2000.0, repeats=5, lanes=(1, 4, 8, 16), out=print):
    """Where a DOP853 step's time goes, per orbit-step, on the paper's two orbits, for one
    orbit alone and for lanes of copies of it: the right-hand-side evaluations (12 per
    accepted step), the stage combinations with the error norm (the same 11 evaluations
    subtracted), and the rest of the driver (step control, events, samples, tangent
    renormalisation, MEGNO), as shares of `integrate_batch`'s time; compiled loops over
    survey's own kernels at the orbit's start, best of `repeats` interleaved runs."""
    system = System.create()
    # the core's peak, here and after the steps' timings, the higher kept: a slow spell of
    # the machine (a shared host's) during one measurement would raise the limit
    peak = fma_peak(repeats)
    rows = []
    for label, family, params in CASES:
        y0 = initial_state(system, family, **params)
        for n_tan in (0, 1):
            w = deviation_vectors(system, y0, n_tan, seed=0) if n_tan else None
            one = integrate(system, y0, t_final, tangents=w, megno=n_tan > 0)
            steps = one.n_steps + one.n_rejected
            h = t_final / one.n_steps
            model = system.model
            for L in lanes:
                starts = np.repeat(y0[None], L, 0)
                tangents = np.repeat(w[None], L, 0) if n_tan else None
                # the states the driver integrates: each orbit's relative motion
                frame = Frame.of(system, starts, np.zeros((L, n_tan, y0.size))
                                  if tangents is None else tangents, [])
                Y = np.ascontiguousarray(frame.reduce(
                    starts if tangents is None else
                    np.concatenate([starts, tangents.reshape(L, -1)], 1), n_tan).T).ravel()
                K, W = np.zeros((16, Y.size)), np.zeros(workspace_size(L, Y.size // L))
                _rhs_loop(Y, K, W, 1, L, model, n_tan, frame.ratios)
                _stage_loop(Y, 1, h, L, model, n_tan, frame.ratios)
                reps = max(1, steps // L)
                # interleaved, so a slow spell of the machine does not fall on one of three
                best = [math.inf] * 3
                for _ in range(repeats):
                    for k, go in enumerate((
                            lambda: _rhs_loop(Y, K, W, reps, L, model, n_tan,
                                              frame.ratios),
                            lambda: _stage_loop(Y, reps, h, L, model, n_tan,
                                                frame.ratios),
                            lambda: integrate_batch(system, starts, t_final, tangents=tangents,
                                                    megno=n_tan > 0, lanes=L))):
                        best[k] = min(best[k], best_time(go, 1)[0])
                t_rhs, t_stage = best[0] * steps / (reps * L), best[1] * steps / (reps * L)
                t_all = best[2] / L
                rows.append((label, n_tan, L, steps, t_all, t_rhs, t_stage - t_rhs * 11 / 12))
    out("")
    out(f"Where a step goes (t = {t_final:g}, tol 1e-12; per orbit-step, ns; shares of "
        "integrate_batch's time; L orbits as SIMD lanes)")
    out(f"{'case':26s} {'tangents':>8s} {'lanes':>5s} {'steps':>7s} {'step ns':>8s} "
        f"{'12 rhs':>7s} {'stages+norm':>12s} {'rest':>6s}")
    for label, n_tan, L, steps, t_all, t_rhs, t_comb in rows:
        ns = 1e9 / steps
        rest = t_all - t_rhs - t_comb
        out(f"{label:26s} {n_tan:8d} {L:5d} {steps:7d} {t_all * ns:8.0f} "
            f"{t_rhs / t_all:7.0%} {t_comb / t_all:12.0%} {rest / t_all:6.0%}")
    plain, plain_steps, *_ = plain_step(t_final, repeats)
    alone = next(1e9 * t_all / steps for label, n_tan, L, steps, t_all, *_ in rows
                 if label == CASES[0][0] and n_tan == 1 and L == 1)
    out(f"the same orbit with a tangent in plain scalar code (bench.steps._plain_dop853: one "
        f"function, the right-hand side inlined, no events, samples or lanes): {plain:.0f} ns "
        f"per attempted step ({plain_steps} steps); survey's one orbit alone {alone:.0f} ns, "
        f"{alone / plain:.2f}x (target <= 0.45 us)")
    rhs_flops, sum_flops = step_flops()
    peak, full = max(peak, fma_peak(repeats)), fma_peak(repeats, full_width=True)
    limit = 1e9 * (rhs_flops + sum_flops) / peak
    widest = max(lanes)
    _, _, _, steps, t_all, t_rhs, t_comb = next(
        r for r in rows if r[0] == CASES[0][0] and r[1] == 1 and r[2] == widest)
    step, arithmetic = 1e9 * t_all / steps, 1e9 * (t_rhs + t_comb) / steps
    out(f"the machine's limit: {rhs_flops + sum_flops} floating-point operations an "
        f"orbit-step with a tangent ({rhs_flops} in the 12 right-hand sides, {sum_flops} in "
        f"the stage sums and error norm: bench.steps.step_flops) at this core's peak of "
        f"{peak / 1e9:.1f} Gflop/s in vectorised multiply-adds (bench.steps.fma_peak) = "
        f"{limit:.0f} ns; survey in {widest} lanes {step:.0f} ns, {step / limit:.2f}x the "
        f"limit (target <= 2.5x), of which its stage and right-hand-side loops alone "
        f"{arithmetic:.0f} ns ({arithmetic / limit:.2f}x)" + (
            "" if full < 1.2 * peak else
            f"; at the core's full vector width (peak {full / 1e9:.1f} Gflop/s, survey's "
            f"lanes measured narrower: machine.jit.vector_width) the limit is "
            f"{limit * peak / full:.0f} ns, survey {step * full / peak / limit:.2f}x it"))
    probe, _ = arithmetic_probe(widest, repeats)
    (t_div, t_root), (divisions, roots) = divider_rates(repeats), divider_ops()
    out(f"the limit checked by a probe that does only that arithmetic "
        f"(bench.steps.arithmetic_probe: the step in {widest} lanes, each stage's sums and "
        f"right-hand side in one loop over the lanes, then the solution and error norm; no "
        f"step control, bookkeeping or tangent norms): {probe:.0f} ns, {probe / limit:.2f}x "
        f"the limit -- of the step's operations {divisions} divisions and {roots} square "
        f"roots run on the divider, not at the multiply-adds' rate (this core's "
        f"{1e9 * t_div:.2f} and {1e9 * t_root:.2f} ns a lane: "
        f"{1e9 * (divisions * t_div + roots * t_root):.0f} ns of divider alone, "
        f"bench.steps.divider_rates); survey {step / probe:.2f}x the probe")
    return rows, plain, limit
