"""The driver: orbits (each with its tangent vectors) stepped by DOP853 as SIMD lanes, with
events, samples, periodic renormalisation and the MEGNO/FLI/WBA accumulators, compiled
(`dop853`, called by numerics.integrate, which validates and shapes what it returns).

Lanes: L orbits advance together in flat variable-major state (component i of lane k at
Y[i * L + k]), so the stage combinations, error norms, dense output and -- for three
bodies in the plane -- the right-hand side are loops over lanes that the compiler turns
into SIMD instructions. Each lane has its own time, step, error norm, accept/reject,
budget, status, events, samples and accumulators; every decision is taken lane by lane
with the arithmetic of one orbit, so a lane gives the bits one orbit alone gives (L = 1),
whatever the lane count and whatever the other lanes hold (tests/numerics/test_lanes.py).
A lane whose orbit ends takes the next start of the batch: no lane waits for the slowest.
Once every start is taken and at most half the lanes still run, those orbits move to half
as many lanes, down to SIMD_MIN, where the last orbit goes on in one lane (`_adopt`): idle
lanes cost the SIMD loops as much as busy ones, and SIMD_MIN lanes with two orbits less
than those two one after the other.

The kernel is one compiled function for every system, potential and event set (all chosen
by integer codes and parameter arrays), so it is cached on disk. Nothing raises inside it:
failures come back as a `Status`. Error control covers the first `n_err` components of
each orbit (the orbit by default; the tangent vectors optionally). Dense output is built
only for steps that need it -- a step holding requested output times, and a step in which
a watched event may cross zero (screened first on a cubic model of it from the step's ends,
`_screen`) -- for all lanes at once when any lane needs it now. A step that holds
only orbit samples at t_fine (the torus analysis': every few steps of every lane) needs it
later: its stages wait in `Deferred` until a batch of such steps fills, whose dense output
is then built in SIMD loops over the batch, not over every lane at every round.
"""
from __future__ import annotations

import contextvars
import math
import time
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np
from ..catalog.status import Status
from ..machine import portable
from ..machine.jit import helper, lanes, leaf
from ..physics.lanes import SIMD_MIN, full_rhs, rhs_lanes, state_size
from ..physics.system import Model
from .lanestate import RawOutcome, lane_state, reused_samples
from .tangents import (accumulate, begin, growth_terms, offsets, sample_at, tangent_norms,
                       width)
from .dop853 import (
    finite_lanes,
    spread_steps,
    step_factors,
    take_steps,
    EPS,
    ERR_FLOOR_ROOT,
    dense_eval,
    dense_eval_lanes,
    dense_prepare,
    error_norms,
    stages,
)
from .events import (
    event_slope,
    event_value,
    may_cross,
    scan_events,
)

# the kernel returns plain integers (numba freezes module globals as constants)
OK_, EVENT_, COLLISION_, STEP_LIMIT_, NONFINITE_, TIME_LIMIT_ = (
    int(s) for s in (Status.OK, Status.EVENT, Status.COLLISION, Status.STEP_LIMIT,
                     Status.NONFINITE, Status.TIME_LIMIT))
RUNNING = -1
# _run's returns besides the next job: every job has ended; the jobs are all started and at
# most half the lanes still run one (the rest go on in fewer lanes: `dop853`)
DONE, HANDOFF = -1, -2
# what an accepted step needs of the dense output (`_needs_dense`)
DENSE_LATER, DENSE_ORBIT, DENSE_ALL = 1, 2, 3
# what a job records besides its end state: crossings of the watched events, samples at
# t_eval, orbit samples at t_fine
EVENTS, EVAL, FINE = 1, 2, 4
# the closest approaches a job that records crossings keeps (`_near`): each pair's, and
# the triangles' perimeter, area and thin time too
NEAR_PAIRS, NEAR_TRIANGLES = 1, 2


def near_width(bodies: int) -> int:
    """A job's closest-approach record: (distance, time) of each pair i < j in order, then
    (perimeter, time), (|area|, time) of the triangle with the least of each, and the time
    the thinnest triangle was thin."""
    return bodies * (bodies - 1) + 5


@helper
def _finite(x):
    for a in range(x.size):
        if not math.isfinite(x[a]):
            return False
    return True


@helper
def _initial_step(model, n_tan, nf, n_err, t, y, K, yt, direction,
                  h_max, rtol, atol, W, rb):
    """Hairer's hinit: a first step from the sizes of y, f(y) (in K[0]) and an estimate
    of the second derivative (one evaluation, into K[1]), at most h_max."""
    dnf = 0.0
    dny = 0.0
    for a in range(n_err):
        sk = atol + rtol * abs(y[a])
        dnf += (K[0, a] / sk) * (K[0, a] / sk)
        dny += (y[a] / sk) * (y[a] / sk)
    h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else 0.01 * math.sqrt(dny / dnf)
    h = min(h, h_max)
    for a in range(nf):
        yt[a] = y[a] + direction * h * K[0, a]
    _rhs_one(t + direction * h, yt, K[1], model, n_tan, W, rb)
    der2 = 0.0
    for a in range(n_err):
        sk = atol + rtol * abs(y[a])
        q = (K[1, a] - K[0, a]) / sk
        der2 += q * q
    der2 = math.sqrt(der2 / max(n_err, 1)) / h
    der12 = max(abs(der2), math.sqrt(dnf / max(n_err, 1)))
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else portable.root8(0.01 / der12)[0]
    return min(100.0 * h, h1, h_max)


@helper
def _finish(k, ln, out, status, rows):
    """Lane k's job ends with `status`: its time and state into the outputs; the lane
    becomes idle."""
    j = ln.job[k]
    L = ln.job.size
    out.status[j] = status
    out.t[j] = ln.t[k]
    for i in range(out.y.shape[1]):
        out.y[j, i] = ln.Y[i * L + k]
    ln.job[k] = -1


@leaf
def _start(k, j, ln, out, y0s, rows, t0, t1, model, n_tan, n_err,
           rtol, atol, h0, h_max, events, t_eval, n_eval, t_fine, renorm_dt, now, rb,
           near, thin):
    """Job j into lane k: its start, first evaluation, samples at t0, events' first values
    and closest approaches, and first step. Returns False if the job ended at once
    (nonfinite start, zero span). Once a job: a leaf (machine.jit)."""
    L = ln.job.size
    nf = y0s.shape[1]
    masses, d = model.masses, model.d
    n = state_size(masses, d, rb)
    eoff, ep, direc, terminal, guard, watch = events
    y, K = ln.y1, ln.k1
    ln.job[k] = j
    ln.t[k] = t0
    for i in range(nf):
        y[i] = y0s[j, i]
        ln.Y[i * L + k] = y[i]
    out.h_range[j, 0] = np.inf
    ln.acc[k, 3] = now
    ln.i_eval[k] = 0
    ln.i_fine[k] = 0
    direction = 1.0 if t1 >= t0 else -1.0
    ln.t_next_renorm[k] = t0 + direction * renorm_dt
    for f in range(4):
        ln.flags[k, f] = 0
    ln.err_old[k] = ERR_FLOOR_ROOT
    if not _finite(y):
        _finish(k, ln, out, NONFINITE_, rows)
        return False
    begin(out.ends[j], ln.acc[k], y, n, n_tan, rb)
    _rhs_one(t0, y, K[0], model, n_tan, ln.W, rb)
    out.counts[j, 2] += 1
    for i in range(nf):
        ln.K[0, i * L + k] = K[0, i]
    if not _finite(K[0]):
        _finish(k, ln, out, NONFINITE_, rows)
        return False
    # y[::1]: the layout (any) the step's samples give these callees, not a second
    # compilation of them for contiguous arrays (and a bool, not the literal False)
    r = rows[1, j]
    if r >= 0:
        while ln.i_eval[k] < t_eval.size and t_eval[ln.i_eval[k]] == t0:
            put_sample(out.samples[r, ln.i_eval[k]], y[::1], n_eval, rb)
            sample_at(out.sampled[r, ln.i_eval[k]], out.ends[j], ln.acc[k], y[::1], n, n_tan,
                      rb, 0.0, 0.0, np.bool_(False))
            ln.i_eval[k] += 1
    r = rows[2, j]
    if r >= 0:
        while ln.i_fine[k] < t_fine.size and t_fine[ln.i_fine[k]] == t0:
            put_sample(out.fine[r, ln.i_fine[k]], y[::1], n, rb)
            ln.i_fine[k] += 1
    if rows[0, j] >= 0:
        if near > 0:
            rec = out.near[j]
            for i in range(rec.size - 1):
                rec[i] = np.inf if i % 2 == 0 else np.nan
            rec[rec.size - 1] = 0.0
            _near_lane(rec, ln.Y, ln.NX, ln.NR, ln.NT, L, k, t0, 0.0, masses.size, d, rb,
                       near, thin)
        for e in range(eoff.size - 1):
            if watch[e]:
                # the lane's strided copies, as at every step: one compiled layout
                ln.g_old[k, e] = event_value(ep, eoff[e], ln.Y[k::L], masses, d)
                ln.s_old[k, e] = event_slope(ep, eoff[e], ln.Y[k::L], ln.K[0, k::L], n, ln.yd,
                                             masses, d, 1.0)
    span = abs(t1 - t0)
    if span == 0.0:
        _finish(k, ln, out, OK_, rows)
        return False
    ln.h_max[k] = min(h_max, span) if h_max > 0.0 else span
    if h0 > 0.0:
        h = min(h0, ln.h_max[k])
    else:
        h = _initial_step(model, n_tan, nf, n_err, t0, y, K, ln.YT,
                          direction, ln.h_max[k], rtol, atol, ln.W, rb)
        out.counts[j, 2] += 1
    ln.h[k] = h * direction
    return True


@helper
def _lane(ln, k):
    """Lane k's state, new state and dense output as strided views: made where a branch
    uses them (each view's length costs an integer division, on every lane's every step
    when made up front)."""
    L = ln.job.size
    return ln.Y[k::L], ln.YN[k::L], ln.F[:, k::L]


@helper
def _pair(i, j, N):
    """The row of pair i < j of N bodies, the pairs in order (0, 1), (0, 2), ..."""
    return i * (2 * N - i - 1) // 2 + j - i - 1


@lanes
def near_terms(Y, L, k0, k1, N, d, rb, near, X, R, TP, TA, TQ):
    """What a closest-approach record takes of lanes k0..k1-1 of the states Y: each pair's
    distance (R: a row of L a pair, `_pair`) and, with NEAR_TRIANGLES, each triangle's
    perimeter P, |area| and |area|/P^2 (TP, TA, TQ: a row each a triangle; the last inf
    where P = 0) -- a distance the square root of the squares summed coordinate by
    coordinate, a perimeter its sides summed in the pairs' order, as for one orbit alone.
    The positions are Y's first rows, or for reduced states (rb: the mass ratios) rebuilt
    into X (the third body as `put_sample` rebuilds it, in the centre-of-mass frame). In
    loops over the lanes, innermost (SIMD, like the right-hand side's): lane by lane, at
    every step end, their square roots cost a batch whose orbits all record crossings a
    sixth of its integration. `_near` records them."""
    pos = Y
    if rb is not None:
        for c in range(2):
            x0, x1, x2 = X[c * L:], X[(2 + c) * L:], X[(4 + c) * L:]
            for k in range(k0, k1):
                a, b = Y[c * L + k], Y[(2 + c) * L + k]
                x0[k], x1[k], x2[k] = a, b, -(rb[0] * a + rb[1] * b)
        pos = X
    p = 0
    for i in range(N):
        for j in range(i + 1, N):
            r = R[p * L:(p + 1) * L]    # views: see dop853.error_norms
            for k in range(k0, k1):
                r[k] = 0.0
            for c in range(d):
                u, v = pos[(i * d + c) * L:], pos[(j * d + c) * L:]
                for k in range(k0, k1):
                    x = u[k] - v[k]
                    r[k] += x * x
            for k in range(k0, k1):
                r[k] = math.sqrt(r[k])
            p += 1
    if near != NEAR_TRIANGLES:
        return
    q = 0
    for i in range(N):
        for j in range(i + 1, N):
            for m in range(j + 1, N):
                P, A, Q = TP[q * L:(q + 1) * L], TA[q * L:(q + 1) * L], TQ[q * L:(q + 1) * L]
                a, b, c = R[_pair(i, j, N) * L:], R[_pair(j, m, N) * L:], R[_pair(i, m, N) * L:]
                for k in range(k0, k1):
                    P[k] = a[k] + b[k] + c[k]
                xi, yi = pos[i * d * L:], pos[(i * d + 1) * L:]
                xj, yj = pos[j * d * L:], pos[(j * d + 1) * L:]
                xm, ym = pos[m * d * L:], pos[(m * d + 1) * L:]
                if d == 2:
                    for k in range(k0, k1):
                        ux, uy, vx, vy = xj[k] - xi[k], yj[k] - yi[k], xm[k] - xi[k], ym[k] - yi[k]
                        A[k] = 0.5 * abs(ux * vy - uy * vx)
                else:
                    zi, zj = pos[(i * d + 2) * L:], pos[(j * d + 2) * L:]
                    zm = pos[(m * d + 2) * L:]
                    for k in range(k0, k1):
                        ux, uy, vx, vy = xj[k] - xi[k], yj[k] - yi[k], xm[k] - xi[k], ym[k] - yi[k]
                        uz, vz = zj[k] - zi[k], zm[k] - zi[k]
                        A[k] = 0.5 * math.sqrt((uy * vz - uz * vy) ** 2 +
                                               (uz * vx - ux * vz) ** 2 +
                                               (ux * vy - uy * vx) ** 2)
                for k in range(k0, k1):
                    Q[k] = A[k] / (P[k] * P[k]) if P[k] > 0.0 else np.inf
                q += 1


@helper
def _near(rec, NR, NT, L, k, t, dt, N, near, thin):
    """Lane k's state at time t, the end of a step of length dt, into its closest-approach
    record (`near_width`), from what `near_terms` left in the L lanes' NR and NT (`Lanes`):
    each pair's distance, and with NEAR_TRIANGLES the least perimeter and |area| of its
    triangles, where below the record's (with t), and dt added to the thin time where the
    thinnest triangle has |A|/P^2 < thin. At step ends: a close approach is where the
    steps are shortest."""
    pairs = N * (N - 1) // 2
    for p in range(pairs):
        r = NR[p * L + k]
        if r < rec[2 * p]:
            rec[2 * p], rec[2 * p + 1] = r, t
    if near != NEAR_TRIANGLES:
        return
    o = 2 * pairs
    least = np.inf
    for q in range(pairs * (N - 2) // 3):
        P, A = NT[0, q * L + k], NT[1, q * L + k]
        if P < rec[o]:
            rec[o], rec[o + 1] = P, t
        if A < rec[o + 2]:
            rec[o + 2], rec[o + 3] = A, t
        least = min(least, NT[2, q * L + k])
    if least < thin:
        rec[o + 4] += dt


@leaf
def _near_lane(rec, Y, NX, NR, NT, L, k, t, dt, N, d, rb, near, thin):
    """`near_terms` and `_near` of lane k alone (a job's start, a terminal event), on the L
    lanes' arrays of `Lanes` it reads (not the whole record: a kernel given it compiles
    ~0.3 s longer). A leaf: inlined at its calls it cost the first run 30 s of compiling."""
    near_terms(Y, L, k, k + 1, N, d, rb, near, NX, NR, NT[0], NT[1], NT[2])
    _near(rec, NR, NT, L, k, t, dt, N, near, thin)


@helper
def _record(k, ln, out, rows, t0, t1, masses, d, n, n_tan, rb, megno, events, max_events,
            n_sub, t_eval, n_eval, t_fine, later):
    """What lane k's accepted step [t, t + h] records, before the lane takes its new state
    (its dense output prepared if it needs one now): counters, event crossings, samples;
    with `later`, its samples at t_fine wait in ln.wait. Returns EVENT_ at a terminal event
    (the state and time then the event's), else RUNNING. n: the orbit's components in the
    state; rb: None, or the mass ratios of reduced states."""
    j = ln.job[k]
    yd = ln.yd
    t, h = ln.t[k], ln.h[k]
    last = ln.flags[k, 2] == 1
    direction = 1.0 if t1 >= t0 else -1.0
    eoff, ep, direc, terminal, guard, watch = events
    m = eoff.size - 1
    counts = out.counts[j]
    counts[0] += 1
    out.h_range[j, 0] = min(out.h_range[j, 0], abs(h))
    out.h_range[j, 1] = max(out.h_range[j, 1], abs(h))
    t_new = t1 if last else t + h
    nd_ready = 0
    x_stop = 1.0
    terminal_hit = False
    re = rows[0, j]
    if m > 0 and re >= 0:
        # the events `_screen` found may cross zero are scanned on the 7th-order dense output
        scan = False
        for e in range(m):
            scan = scan or ln.todo[k, e] > 0
        n_found = np.int64(0)       # not the literal 0: numba would compile scan_events twice
        if scan:        # (the crossings found below come from a scan: its views)
            y, ynew, F = _lane(ln, k)
            counts[2] += 3
            nd_ready = n
            xtol = 4.0 * EPS * max(abs(t), abs(t_new)) / abs(h)
            for e in range(m):
                if ln.todo[k, e]:
                    g0 = eoff[guard[e]] if guard[e] >= 0 else -1
                    n_found = scan_events(ep, eoff[e], ln.g_old[k, e], ln.g_new[k, e],
                                          direc[e], g0, n_sub if ln.todo[k, e] == 2 else 1,
                                          h, xtol, F, y, n, yd, masses, d, ln.found_x,
                                          ln.found_e, e, n_found)
        for e in range(m):
            ln.g_old[k, e] = ln.g_new[k, e]
            ln.s_old[k, e] = ln.s_new[k, e]
        for p in range(n_found):
            xr = ln.found_x[p]
            if counts[3] < max_events:
                dense_eval(F, y, xr, n, yd)
                out.ev_index[re, counts[3]] = ln.found_e[p]
                out.ev_t[re, counts[3]] = t + xr * h
                for i in range(n):
                    out.ev_y[re, counts[3], i] = yd[i]
            counts[3] += 1
            if terminal[ln.found_e[p]]:
                terminal_hit = True
                x_stop = xr
                break
    t_stop = t + x_stop * h if terminal_hit else t_new
    need = ln.Y.size // ln.job.size if terminal_hit else 0     # the whole state
    rs, rf = rows[1, j], rows[2, j]
    i_eval, i_fine = ln.i_eval[k], ln.i_fine[k]
    if rs >= 0 and i_eval < t_eval.size and direction * (t_eval[i_eval] - t_stop) <= 0.0:
        need = max(need, n_eval)
    if rf >= 0 and i_fine < t_fine.size and direction * (t_fine[i_fine] - t_stop) <= 0.0:
        need = max(need, n)
    if need > nd_ready:
        counts[2] += 3
    while rs >= 0 and i_eval < t_eval.size and direction * (t_eval[i_eval] - t_stop) <= 0.0:
        y, ynew, F = _lane(ln, k)
        src = ynew
        if t_eval[i_eval] != t_new:
            dense_eval(F, y, (t_eval[i_eval] - t) / h, n_eval, yd)
            src = yd
        put_sample(out.samples[rs, i_eval], src, n_eval, rb)
        sample_at(out.sampled[rs, i_eval], out.ends[j], ln.acc[k], src, n, n_tan, rb,
                  t_eval[i_eval] - t, t_eval[i_eval] - t0, megno and n_eval >= 2 * n)
        i_eval += 1
    if later:
        first = i_fine
        while rf >= 0 and i_fine < t_fine.size and \
                direction * (t_fine[i_fine] - t_stop) <= 0.0:
            i_fine += 1
        if i_fine > first:
            _defer(ln, k, rf, first, i_fine, t, h, t_new, n)
    while rf >= 0 and i_fine < t_fine.size and direction * (t_fine[i_fine] - t_stop) <= 0.0:
        y, ynew, F = _lane(ln, k)
        _fine_sample(out.fine[rf, i_fine], t_fine[i_fine], F, y, ynew, t, h, t_new, n, yd,
                     rb)
        i_fine += 1
    ln.i_eval[k], ln.i_fine[k] = i_eval, i_fine
    if terminal_hit:
        y, ynew, F = _lane(ln, k)
        nf = y.size
        dense_eval(F, y, x_stop, nf, yd)
        for a in range(nf):
            y[a] = yd[a]
        ln.t[k] = t_stop
        return EVENT_
    return RUNNING


@leaf
def _fine_sample(sample, at, F, y, ynew, t, h, t_new, n, yd, rb):
    """The orbit's state at time `at` of the step [t, t_new] (t + h but for the last) from
    its dense output (F, y), into `sample` (in full: `put_sample`)."""
    if at == t_new:
        put_sample(sample, ynew, n, rb)
    else:
        dense_eval(F, y, (at - t) / h, n, yd)
        put_sample(sample, yd[::1], n, rb)


@helper
def _copy_lane(to, p, P, src, k, L, n):
    """Components 0..n-1 of lane k of src (L lanes) into slot p of `to` (P slots). The
    indices are unsigned: a signed index computed from run-time sizes gets a wrap-around
    fix-up at every access (3 instructions; the copy 25% slower; strided views instead cost
    more to make than they save)."""
    for i in range(n):
        to[np.uint64(i * P + p)] = src[np.uint64(i * L + k)]


@helper
def _defer(ln, k, row, first, end, t, h, t_new, n):
    """Lane k's accepted step (its orbit's n components) into a slot of ln.wait: its
    samples first .. end - 1 at t_fine (row `row` of the fine output) are taken when the
    batch is built (`_flush`)."""
    w = ln.wait
    P = w.t.size
    L = ln.job.size
    p = w.count[0]
    # array by array (all of them in one loop over the components spilled their addresses
    # to the stack: 11 streams)
    _copy_lane(w.Y, p, P, ln.Y, k, L, n)
    _copy_lane(w.YN, p, P, ln.YN, k, L, n)
    _copy_lane(w.K[0], p, P, ln.K[0], k, L, n)
    for s in range(5, 13):
        _copy_lane(w.K[s], p, P, ln.K[s], k, L, n)
    w.t[p], w.h[p], w.t_new[p] = t, h, t_new
    w.row[p], w.first[p], w.end[p] = row, first, end
    w.count[0] = p + 1


@leaf
def _flush(w, yd, fine, model, t_fine, rb):
    """The waiting steps (w: `Deferred`) -- their dense output, all P slots in SIMD loops
    (slots past the count hold stale values, computed and ignored), and their samples at
    t_fine into `fine` (RawOutcome.fine): each slot's first (most steps hold one) in a SIMD
    loop too, any others one by one (yd: a lane's scratch). Given the arrays it uses, not
    the records holding them: a kernel given the whole Lanes compiled 0.3 s longer."""
    P = w.t.size
    c = w.count[0]
    if c == 0:
        return
    n = w.Y.size // P
    spread_steps(w.h, w.HH, P, n)
    dense_prepare(model, P, n, w.Y, w.YN, w.HH, w.K, w.YT, w.F, w.W,
                  rb)
    for p in range(P):
        w.x[p] = (t_fine[w.first[p]] - w.t[p]) / w.h[p] if p < c else 0.0
    spread_steps(w.x, w.XX, P, n)
    dense_eval_lanes(w.F, w.Y, w.XX, n * P, w.S)
    for p in range(c):
        F, y, ynew = w.F[:, p::P], w.Y[p::P], w.YN[p::P]
        job = fine[w.row[p]]
        first = w.first[p]
        if t_fine[first] == w.t_new[p]:
            put_sample(job[first], ynew, n, rb)
        else:
            put_sample(job[first], w.S[p::P], n, rb)
        for i in range(first + 1, w.end[p]):
            _fine_sample(job[i], t_fine[i], F, y, ynew, w.t[p], w.h[p], w.t_new[p], n,
                         yd, rb)
    w.count[0] = 0


@helper
def _advance(k, ln, out, t0, t1, n, n_tan, megno, renorm_dt, NW):
    """Lane k after its accepted step (its state already the new one): the time, the
    step-end indicators (`tangents.accumulate`, from the tangent vectors' norms, logs and
    the step's Birkhoff weight in NW: `growth_terms`), and the vectors' renormalisation
    when due. Returns OK_ if the job reached t1, else RUNNING."""
    L = ln.job.size
    j = ln.job[k]
    last = ln.flags[k, 2] == 1
    direction = 1.0 if t1 >= t0 else -1.0
    t_old = ln.t[k]
    t = t1 if last else t_old + ln.h[k]
    ln.t[k] = t
    if n_tan > 0:
        ends = out.ends[j]
        accumulate(ends, ln.acc[k], NW, L, k, n_tan, t0, t_old, t, megno)
        LOG = offsets(n_tan)[0]
        due = direction * (t - ln.t_next_renorm[k]) >= 0.0
        if due:
            ln.t_next_renorm[k] = t + direction * renorm_dt
        for tt in range(n_tan):
            wn = NW[tt * L + k]
            if due or wn > 1e100 or wn < 1e-100:
                inv = 1.0 / wn
                y, K0 = ln.Y[k::L], ln.K[0, k::L]
                for a in range(n * (1 + tt), n * (2 + tt)):
                    y[a] *= inv
                    K0[a] *= inv
                ends[LOG + tt] += NW[(n_tan + tt) * L + k]
    return OK_ if last else RUNNING


class Control(NamedTuple):
    """How every orbit of a batch is stepped: from t0 to t1, with n_tan tangent vectors
    (MEGNO of the first if megno), the error of its first n_err components held to
    rtol, atol, at most max_steps steps and time_limit wall-clock seconds (0: none), the
    first step h0 and the steps' bounds h_max, h_min (0: free), the tangent vectors
    renormalised every renorm_dt (<= 0: every step)."""

    t0: float
    t1: float
    n_tan: int
    megno: bool
    rtol: float
    atol: float
    n_err: int
    max_steps: int
    h0: float
    h_max: float
    h_min: float
    renorm_dt: float
    time_limit: float


class Recording(NamedTuple):
    """What the orbits record besides their ends: crossings of the encoded events
    (events.encode_events; at most max_events each, n_sub sub-intervals of a step
    scanned), the first n_eval components at the times t_eval, the orbit at t_fine; and
    with the crossings their closest approaches (`near`: 0 none, NEAR_PAIRS, NEAR_TRIANGLES;
    a triangle thin where |A|/P^2 < thin: `_near`)."""

    events: tuple
    max_events: int
    n_sub: int
    t_eval: np.ndarray
    n_eval: int
    t_fine: np.ndarray
    near: int = 0
    thin: float = 0.0


@leaf
def _run(ln, out, y0s, rows, model, control, recording, next_job, iterations, now, rb):
    """At most `iterations` steps of every lane (the kernel checks the clock between
    calls); returns the next job to start, DONE when every job has ended, or HANDOFF
    when every job has started and at most half the lanes run one. rb: None for full
    states, the mass ratios for reduced ones (physics.lanes.state_size): two
    compilations, each of the code its kind runs (an argument of its own, not a field of
    the records: numba prunes the branches of the other kind on arguments)."""
    masses, d = model.masses, model.d
    (t0, t1, n_tan, megno, rtol, atol, n_err, max_steps, h0, h_max, h_min, renorm_dt,
     time_limit) = control
    events, max_events, n_sub, t_eval, n_eval, t_fine, near, thin = recording
    L = ln.job.size
    nf = y0s.shape[1]
    M = y0s.shape[0]
    direction = 1.0 if t1 >= t0 else -1.0
    for _ in range(iterations):
        # ---- lanes without a job take the next one; lanes whose job must end, end it
        active = 0
        for k in range(L):
            while ln.job[k] < 0 and next_job < M:
                next_job += 1
                _start(k, next_job - 1, ln, out, y0s, rows, t0, t1, model, n_tan, n_err,
                       rtol, atol, h0, h_max, events, t_eval, n_eval, t_fine, renorm_dt,
                       now, rb, near, thin)
            j = ln.job[k]
            if j < 0:
                ln.h[k] = 0.0
                continue
            counts = out.counts[j]
            if counts[0] + counts[1] >= max_steps:
                _finish(k, ln, out, STEP_LIMIT_, rows)
            elif time_limit > 0.0 and now - ln.acc[k, 3] > time_limit:
                _finish(k, ln, out, TIME_LIMIT_, rows)
            elif not (abs(ln.h[k]) > max(h_min, 10.0 * EPS * abs(ln.t[k]), 1e-300)):
                _finish(k, ln, out, NONFINITE_ if ln.flags[k, 1] else COLLISION_, rows)
            if ln.job[k] < 0:          # ended now: take the next job at the next round
                ln.h[k] = 0.0
                continue
            active += 1
            last = direction * (ln.t[k] + ln.h[k] - t1) >= 0.0
            ln.flags[k, 2] = 1 if last else 0
            if last:
                ln.h[k] = t1 - ln.t[k]
        if active == 0:
            if next_job >= M:
                _flush(ln.wait, ln.yd, out.fine, model, t_fine, rb)
                return DONE
            continue
        spread_steps(ln.h, ln.HH, L, nf)
        # ---- one attempt of every lane's step
        stages(model, n_tan, L, ln.Y, ln.HH, ln.K, ln.YT, ln.YN,
               ln.W, rb)
        error_norms(ln.Y, ln.YN, ln.K, L, n_err, rtol, atol, ln.h, ln.err, ln.S)
        step_factors(ln.err, ln.err_old, L, ln.grow, ln.err_next, ln.cut)
        rhs_lanes(0.0, ln.YN, ln.K[12], L, model, n_tan, ln.W, rb)
        finite_lanes(ln.YN, ln.K[12], L, nf, ln.NW)
        dense = later = 0
        n = state_size(masses, d, rb)
        for k in range(L):
            j = ln.job[k]
            ln.flags[k, 3] = 0
            if j < 0:
                continue
            counts = out.counts[j]
            counts[2] += 11
            err = ln.err[k]
            ok = math.isfinite(err)
            if ok and err <= 1.0:
                counts[2] += 1
                ok = math.isfinite(ln.NW[k])
            if not ok:
                counts[1] += 1
                ln.h[k] *= 0.25
                ln.flags[k, 0] = 1
                ln.flags[k, 1] = 1
                continue
            ln.flags[k, 1] = 0
            if err > 1.0:
                counts[1] += 1
                ln.h[k] *= ln.cut[k]
                ln.flags[k, 0] = 1
                continue
            ln.flags[k, 3] = 1          # accepted
            need = _needs_dense(k, ln, rows, t1, direction, events, t_eval, t_fine,
                                n_eval > n, masses, d, n)
            later += need == DENSE_LATER
            dense = max(dense, need)
        if dense >= DENSE_ORBIT:    # the orbits' interpolant where no lane needs more
            dense_prepare(model, L, nf if dense == DENSE_ALL else n,
                          ln.Y, ln.YN, ln.HH, ln.K, ln.YT, ln.F, ln.W, rb)
        elif dense == DENSE_LATER and ln.wait.count[0] + later > ln.wait.t.size:
            _flush(ln.wait, ln.yd, out.fine, model, t_fine, rb)   # room for the steps
        for k in range(L):
            if ln.flags[k, 3]:
                t_before = ln.t[k]
                ended = _record(k, ln, out, rows, t0, t1, masses, d, n, n_tan, rb, megno,
                                events, max_events, n_sub, t_eval, n_eval, t_fine,
                                dense == DENSE_LATER)
                if ended == EVENT_:
                    if near > 0:        # the state at the event, as _record left it
                        # (only a job that records crossings watches events)
                        _near_lane(out.near[ln.job[k]], ln.Y, ln.NX, ln.NR, ln.NT, L, k,
                                   ln.t[k], abs(ln.t[k] - t_before), masses.size, d, rb, near,
                                   thin)
                    _finish(k, ln, out, EVENT_, rows)
                    ln.flags[k, 3] = 0
            ln.taken[k] = -ln.flags[k, 3]
        # ---- accepted lanes take their new states, then their tangent vectors' norms
        take_steps(ln.Y, ln.YN, ln.K[0], ln.K[12], ln.taken, L, nf)
        tangent_norms(ln.Y, L, n, n_tan, ln.NW, rb)
        if n_tan > 0:
            growth_terms(ln.NW, ln.t, ln.h, ln.flags, t0, t1, L, n_tan)
        # the closest approaches at the step ends, of every lane in SIMD loops where any
        # records them (as cheap as one lane's alone: 16 lanes, 1 to 16 of them recording)
        recording_near = False
        if near > 0:
            for k in range(L):
                if ln.flags[k, 3] == 1 and rows[0, ln.job[k]] >= 0:
                    recording_near = True
                    break
            if recording_near:
                near_terms(ln.Y, L, np.int64(0), L, masses.size, d, rb, near, ln.NX, ln.NR,
                           ln.NT[0], ln.NT[1], ln.NT[2])
        for k in range(L):
            if not ln.flags[k, 3]:
                continue
            if near > 0 and rows[0, ln.job[k]] >= 0:
                _near(out.near[ln.job[k]], ln.NR, ln.NT, L, k,
                      t1 if ln.flags[k, 2] else ln.t[k] + ln.h[k], abs(ln.h[k]), masses.size,
                      near, thin)
            if _advance(k, ln, out, t0, t1, n, n_tan, megno, renorm_dt,
                        ln.NW) == OK_:
                _finish(k, ln, out, OK_, rows)
                continue
            ln.err_old[k] = ln.err_next[k]
            fac = ln.grow[k]
            if ln.flags[k, 0]:
                fac = min(fac, 1.0)
            ln.flags[k, 0] = 0
            ln.h[k] = direction * min(abs(ln.h[k]) * fac, ln.h_max[k])
        if next_job >= M and L > 1:
            running = 0
            for k in range(L):
                running += ln.job[k] >= 0
            # half as many lanes while they are at least SIMD_MIN (`dop853`); below, one lane
            # for the last orbit alone (SIMD_MIN lanes cost less than two orbits one after
            # the other in one lane)
            if 0 < running and (2 * running <= L if L // 2 >= SIMD_MIN else running == 1):
                _flush(ln.wait, ln.yd, out.fine, model, t_fine, rb)
                return HANDOFF
    _flush(ln.wait, ln.yd, out.fine, model, t_fine, rb)
    return next_job


# Per lane: a sample written, one lane's right-hand side, a lane moved to a smaller batch,
# and what of the dense output an accepted step needs (the loops over every lane at once:
# dop853's step control, tangents' norms and growth terms).


@leaf
def put_sample(sample, src, n_eval, rb):
    """A sample of the state src (n_eval components): as it is, or a reduced one (rb: the
    mass ratios) in full blocks of 12, the third body rebuilt as `integrate.Frame.full`
    rebuilds it (the centre of mass's motion is added afterwards, `_com_added`): rebuilt in
    a second array, the samples' fresh memory cost a sampled scan task dearly."""
    if rb is None:
        for i in range(n_eval):
            sample[i] = src[i]
    else:
        a, b = rb
        for k in range(n_eval // 8):
            i, o = 8 * k, 12 * k
            for c in range(2):
                q0, q1, p0, p1 = src[i + c], src[i + 2 + c], src[i + 4 + c], src[i + 6 + c]
                sample[o + c], sample[o + 2 + c], sample[o + 4 + c] = q0, q1, -(a * q0 + b * q1)
                sample[o + 6 + c], sample[o + 8 + c], sample[o + 10 + c] = p0, p1, -(p0 + p1)


@helper
def _rhs_one(t, y, dy, model, n_tan, W, rb):
    """The right-hand side at one state: `rhs`, or for a reduced state its lane loops at
    L = 1 (W: their workspace). The 1 is given as an int64: a literal one is a type of its
    own, and compiled a second copy of the lanes' right-hand sides (seconds of a first
    run)."""
    if rb is None:
        full_rhs(t, y, dy, model, n_tan, rb)
    else:
        rhs_lanes(t, y, dy, np.int64(1), model, n_tan, W, rb)


# what a lane carries from step to step besides its state and derivative, a value or a row
# per lane (`Lanes`)
_CARRIED = ("job", "t", "h", "h_max", "err_old", "t_next_renorm", "i_eval", "i_fine", "flags",
            "acc", "g_old", "s_old")


def _adopt(to, slot, ln, k):
    """Lane k of ln into lane `slot` of `to`: everything a lane carries from step to step
    (its state and derivative, time, step, budgets, flags, samples' and events' places,
    MEGNO sums, clock), so it goes on with the same bits. numpy's copies, not a kernel: a
    batch hands a few lanes over once or twice, and a compiled copy of the Lanes cost a
    first run 1.2 s of compiling."""
    L, Lt = ln.job.size, to.job.size
    to.Y[slot::Lt] = ln.Y[k::L]
    to.K[0, slot::Lt] = ln.K[0, k::L]
    for name in _CARRIED:
        getattr(to, name)[slot] = getattr(ln, name)[k]


@helper
def _screen(k, ln, rows, events, masses, d, n):
    """Lane k's accepted step against the events it watches, on a cubic model of each g(t)
    from its values and slopes at the step's ends (no dense output): ln.todo[k, e] > 0 where
    g_e may cross zero, for `_record` to scan on the dense output. Returns what of the dense
    output those scans need: DENSE_ALL if a terminal event may cross (its crossing ends the
    lane with the whole state there), DENSE_ORBIT if another may, 0 if none -- as on most
    steps, so that one lane watching a section does not cost every lane of its batch three
    more stages with tangents at every step."""
    eoff, ep, direc, terminal, guard, watch = events
    m = eoff.size - 1
    if m == 0 or rows[0, ln.job[k]] < 0:
        return 0
    L = ln.job.size
    h = ln.h[k]
    ynew, f = ln.YN[k::L], ln.K[12, k::L]
    need = 0
    for e in range(m):
        ln.todo[k, e] = 0
        if watch[e]:
            ln.g_new[k, e] = event_value(ep, eoff[e], ynew, masses, d)
            ln.s_new[k, e] = event_slope(ep, eoff[e], ynew, f, n, ln.yd, masses, d, h)
            ln.todo[k, e] = may_cross(ln.g_old[k, e], ln.s_old[k, e], ln.g_new[k, e],
                                      ln.s_new[k, e], h)
            if ln.todo[k, e] > 0:
                need = max(need, DENSE_ALL if terminal[e] else DENSE_ORBIT)
    return need


@helper
def _needs_dense(k, ln, rows, t1, direction, events, t_eval, t_fine, tangent_samples,
                 masses, d, n):
    """What of the dense output lane k's accepted step needs: DENSE_ALL now (a terminal
    event may cross in it, or it holds a sample time and samples carry tangents),
    DENSE_ORBIT now (another event may cross, or it holds an orbit-only sample time of
    t_eval, recorded with the accumulators of the moment), DENSE_LATER (only orbit samples
    of t_fine), 0 none. It screens the lane's events on the way (`_screen`): `_record`
    reads what that stored."""
    j = ln.job[k]
    need = _screen(k, ln, rows, events, masses, d, n)
    t_new = t1 if ln.flags[k, 2] else ln.t[k] + ln.h[k]
    i = ln.i_eval[k]
    if rows[1, j] >= 0 and i < t_eval.size and direction * (t_eval[i] - t_new) <= 0.0:
        return max(need, DENSE_ALL if tangent_samples else DENSE_ORBIT)
    i = ln.i_fine[k]
    if need == 0 and rows[2, j] >= 0 and i < t_fine.size and \
            direction * (t_fine[i] - t_new) <= 0.0:
        return DENSE_LATER
    return need


# A first run compiles in two processes (pipeline.sweep): the driver compiles `_run`, whose
# typing reaches a job's start and the right-hand sides within seconds, but the stepping
# round's leaves only after a dozen; so a worker compiles those first (cells.warm_beside),
# and the driver then loads them from numba's disk cache. Under `round_only`, `dop853`
# calls them once from Python on the lanes it built, with the arguments `_run` gives them
# (so of the types its compilation asks the cache for: tests/pipeline/test_progress.py),
# and stops.
_ROUND_ONLY = contextvars.ContextVar("round_only", default=None)


class RoundCompiled(Exception):
    """dop853 stopped under `round_only`, its stepping round's leaves compiled."""


@contextmanager
def round_only(evaluating: bool):
    """dop853 compiles (or loads) the stepping round's leaves, then raises RoundCompiled:
    those that evaluate the right-hand side if `evaluating`, else the others (the driver
    compiles the right-hand side meanwhile: a job's start calls it first)."""
    token = _ROUND_ONLY.set(evaluating)
    try:
        yield
    finally:
        _ROUND_ONLY.reset(token)


def compile_round(call, *halves: bool):
    """The stepping round's leaves of the integration `call()` makes, compiled (or loaded
    from the disk cache) under `round_only(evaluating)` for each of `halves` in turn:
    nothing is integrated."""
    for evaluating in halves:
        with round_only(evaluating):
            try:
                call()
            except RoundCompiled:
                pass


def _compile_round(ln, out, model, control, recording, rb, evaluating):
    """The leaves of `_run`'s stepping round (`round_only`), called as it calls them, on
    lanes without a job."""
    L, nf = ln.job.size, out.y.shape[1]
    if evaluating:          # in the order the driver's typing reaches them, but the
        # right-hand side first: on full states it is most of the half (a figure eight's
        # pair and triplet terms: 15 s of 17), which the driver's `_flush` otherwise
        # reaches, through dense_prepare, before this has compiled it
        rhs_lanes(0.0, ln.YN, ln.K[12], L, model, control.n_tan, ln.W, rb)
        dense_prepare(model, L, nf, ln.Y, ln.YN, ln.HH, ln.K, ln.YT, ln.F, ln.W, rb)
        _flush(ln.wait, ln.yd, out.fine, model, recording.t_fine, rb)
        stages(model, control.n_tan, L, ln.Y, ln.HH, ln.K, ln.YT, ln.YN, ln.W, rb)
        return
    n = state_size(model.masses, model.d, rb)
    spread_steps(ln.h, ln.HH, L, nf)
    error_norms(ln.Y, ln.YN, ln.K, L, control.n_err, control.rtol, control.atol, ln.h, ln.err,
                ln.S)
    step_factors(ln.err, ln.err_old, L, ln.grow, ln.err_next, ln.cut)
    finite_lanes(ln.YN, ln.K[12], L, nf, ln.NW)
    take_steps(ln.Y, ln.YN, ln.K[0], ln.K[12], ln.taken, L, nf)
    tangent_norms(ln.Y, L, n, control.n_tan, ln.NW, rb)
    growth_terms(ln.NW, ln.t, ln.h, ln.flags, control.t0, control.t1, L, control.n_tan)


def dop853(y0s, rows, model: Model, control: Control, recording: Recording, L: int, rb,
           reuse_samples=False):
    """Integrate M orbits (+ n_tan tangent vectors each; starts y0s, shape (M, nf)) from t0
    to t1 in L lanes (the records: Model, Control, Recording).

    rows: (3, M) the row of each job in the event, sample and fine outputs (-1: the job
    does not record them). events: (offsets, records, direction, terminal, guard, watch)
    arrays; a watched event e records every crossing of g_e = 0 in its direction (+1
    rising in time, -1 falling, 0 both) where its guard function (index, or -1) is > 0;
    n_sub sub-intervals per step are scanned, so two crossings in one step are both found.
    t_eval: output times (monotone in the direction of integration), sampled on the dense
    output for the first n_eval components. t_fine: a second grid of output times for the
    orbit alone: the time series the torus analysis reads. Tangent vectors are rescaled to
    unit norm every renorm_dt (<= 0: every step), their logs accumulated in log_growth,
    which starts at -ln|w(t0)|. time_limit: wall-clock seconds per job (0: none). rb: None
    for full states, or the mass ratios m0/m2, m1/m2 of reduced ones (`integrate.Frame`).
    reuse_samples: the t_fine samples go into this thread's reused buffer (`reused_samples`).

    MEGNO (if megno, for the first tangent vector; Cincotta & Simo 2000): with
    L(t) = ln(|w(t)|/|w0|) and s = t - t0, Y(s) = (2/s) int_0^s u dL(u) and <Y> =
    (1/s) int_0^s Y. Integrating by parts, int_0^s u dL = s L(s) - int_0^s L: MEGNO needs
    only L, known exactly at every step end, never the rate dL/dt = w'.w/|w|^2, which near a
    close approach spikes within a single step (the Hessian grows like a power of 1/r) and
    wrecks any quadrature of it. int L and int Y are trapezoid sums over the steps (and at
    output times, over the part of the step before them, with L from the dense output).

    The state lives in arrays allocated here and the stepping in the compiled `_run`,
    called from Python: a compiled wrapper would cost the cold start seconds of
    compilation (numba re-optimises and re-generates a caller's whole call tree) for a
    loop that turns once, or once per 256 rounds with a time limit.
    """
    M, nf = y0s.shape
    masses, d = model.masses, model.d
    t0, n_tan, time_limit = control.t0, control.n_tan, control.time_limit
    events, max_events, n_sub, t_eval, n_eval, t_fine, near, thin = recording
    n = state_size(masses, d, rb)
    nfull = 2 * masses.size * d     # samples, fine ones too, are written in full (`put_sample`)
    m = events[0].size - 1
    Me, Ms, Mf = rows[0].max() + 1, rows[1].max() + 1, rows[2].max() + 1
    T, Tf = t_eval.size, t_fine.size
    out = RawOutcome(
        status=np.full(M, OK_, dtype=np.int64), t=np.full(M, t0), y=y0s.copy(),
        counts=np.zeros((M, 4), dtype=np.int64), h_range=np.zeros((M, 2)),
        # crossings are read only up to the count recorded: no need to touch the rest
        ev_index=np.empty((Me, max_events), dtype=np.int64),
        ev_t=np.empty((Me, max_events)), ev_y=np.empty((Me, max_events, n)),
        samples=np.full((Ms, T, n_eval // n * nfull), np.nan),
        near=np.full((M if recording.near else 0, near_width(masses.size)), np.nan),
        ends=np.zeros((M, width(n_tan))), sampled=np.full((Ms, T, width(n_tan, True)), np.nan),
        fine=reused_samples((Mf, Tf, nfull)) if reuse_samples else np.full((Mf, Tf, nfull), np.nan))

    def drive(ln, next_job):
        # with a time limit, back every 256 rounds to read the clock
        rounds = 256 if time_limit > 0.0 else 1 << 62
        while next_job >= 0:
            now = time.perf_counter() if time_limit > 0.0 else 0.0
            next_job = _run(ln, out, y0s, rows, model, control, recording, next_job, rounds,
                            now, rb)
        return next_job

    # The SIMD loops cost all L lanes whether they run a job or not: once every job has
    # started and at most half the lanes run one (their lengths differ 2x and more), those
    # go on in half as many lanes, down to SIMD_MIN, where the last one goes on alone.
    registers = 0 if model.expr is None else model.expr.regs.size
    N = masses.size
    ln, next_job = lane_state(L, n, nf, n_tan, m, n_sub, registers, N), 0
    if _ROUND_ONLY.get() is not None:
        _compile_round(ln, out, model, control, recording, rb, _ROUND_ONLY.get())
        raise RoundCompiled
    while drive(ln, next_job) == HANDOFF:
        next_job, running = M, np.flatnonzero(ln.job >= 0)
        if ln.job.size // 2 >= SIMD_MIN:
            fewer = lane_state(ln.job.size // 2, n, nf, n_tan, m, n_sub, registers, N)
            for slot, k in enumerate(running):
                _adopt(fewer, slot, ln, k)
            ln = fewer
            continue
        one, handed = lane_state(1, n, nf, n_tan, m, n_sub, registers, N), \
            time.perf_counter()
        for k in running:
            _adopt(one, 0, ln, k)
            if time_limit > 0.0:    # a job's budget does not run while it waits its turn
                one.acc[0, 3] += time.perf_counter() - handed
            drive(one, M)
        break
    return out
