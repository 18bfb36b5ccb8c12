"""The driver: an orbit (and its tangent vectors) stepped by DOP853 from t0 to t1 with
events, samples, periodic renormalisation and the MEGNO/FLI/WBA accumulators, compiled; and
`integrate`, its validating Python wrapper returning a typed `Outcome`.

The kernel `dop853` is one compiled function for every system, potential and event set
(all chosen by integer codes and parameter arrays), so it is cached on disk and callable
from other compiled loops. Nothing raises inside it: failures come back as a `Status`.

Error control covers the first `n_err` components (the orbit by default; the tangent
vectors optionally). Dense output is built only for steps that need it: a step holding
requested output times, and every step while events are watched -- then for the orbit
alone (3 extra evaluations of the orbit's right-hand side, not of the tangent dynamics),
unless the full state is asked for.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple, Sequence

import numpy as np
from numba import objmode

from ..catalog import defaults
from ..catalog.status import Status
from ..physics.jit import helper, kernel
from ..physics.system import System, rhs
from .dop853 import (
    BETA,
    EPS,
    RTOL_MIN,
    dense_eval,
    dense_prepare,
    error_norm,
    norm_block,
    stages,
)
from .events import (
    Crossings,
    Event,
    encode_events,
    event_slope,
    event_value,
    may_cross,
    scan_events,
)

# the kernel returns plain integers (numba freezes module globals as constants)
OK_, EVENT_, COLLISION_, STEP_LIMIT_, NONFINITE_, TIME_LIMIT_ = (
    int(s) for s in (Status.OK, Status.EVENT, Status.COLLISION, Status.STEP_LIMIT,
                     Status.NONFINITE, Status.TIME_LIMIT))


class RawOutcome(NamedTuple):
    """What the compiled driver returns (`integrate` turns it into an Outcome)."""

    status: int
    t: float                  # time reached
    y: np.ndarray             # full state at t
    counts: np.ndarray        # accepted steps, rejected steps, rhs evaluations, events found
    h_range: np.ndarray       # smallest and largest accepted step
    ev_index: np.ndarray      # recorded crossings: event index, time, orbit state
    ev_t: np.ndarray
    ev_y: np.ndarray
    samples: np.ndarray       # states at t_eval (first n_eval components)
    sample_log: np.ndarray    # accumulated log growth of each tangent vector at t_eval
    log_growth: np.ndarray    # accumulated log growth at t (the vectors are rescaled)
    max_log: np.ndarray       # largest ln(|w|/|w0|) seen at step ends (the FLI)
    fine: np.ndarray          # orbit states at t_fine
    wba: np.ndarray           # (sum of g dL, sum of g dt) over the steps, first vector: their
    #                           ratio is the weighted Birkhoff average of the growth rate
    #                           (g(s) = exp(-1/(s(1-s))) at the step's mid-time s;
    #                           Sander & Meiss 2025)
    megno_sums: np.ndarray    # (s L - int L, int Y) at t: their ratios to s are Y/2 and <Y>
    sample_megno: np.ndarray  # the same at t_eval


@helper
def _initial_step(masses, d, measure, prof, par, n_tan, nf, n_err, t, y, K, yt, direction,
                  h_max, rtol, atol):
    """Hairer's hinit: a first step from the sizes of y, f(y) (in K[0]) and an estimate
    of the second derivative (one evaluation, into K[1]), at most h_max."""
    dnf = 0.0
    dny = 0.0
    for a in range(n_err):
        sk = atol + rtol * abs(y[a])
        dnf += (K[0, a] / sk) ** 2
        dny += (y[a] / sk) ** 2
    h = 1e-6 if (dnf <= 1e-10 or dny <= 1e-10) else 0.01 * math.sqrt(dny / dnf)
    h = min(h, h_max)
    for a in range(nf):
        yt[a] = y[a] + direction * h * K[0, a]
    rhs(t + direction * h, yt, K[1], masses, d, measure, prof, par, n_tan)
    der2 = 0.0
    for a in range(n_err):
        sk = atol + rtol * abs(y[a])
        der2 += ((K[1, a] - K[0, a]) / sk) ** 2
    der2 = math.sqrt(der2 / max(n_err, 1)) / h
    der12 = max(abs(der2), math.sqrt(dnf / max(n_err, 1)))
    h1 = max(1e-6, h * 1e-3) if der12 <= 1e-15 else (0.01 / der12) ** (1.0 / 8.0)
    return min(100.0 * h, h1, h_max)


@kernel
def dop853(y0, t0, t1, masses, d, measure, prof, par, n_tan, megno, rtol, atol, n_err,
           max_steps, h0, h_max, h_min, events, max_events, n_sub, t_eval, n_eval, renorm_dt,
           time_limit, t_fine):
    """Integrate the orbit (+ n_tan tangent vectors) from t0 to t1.

    events: (offsets, records, direction, terminal, guard, watch) arrays; a watched
    event e records every crossing of g_e = 0 in its direction (+1 rising in time, -1
    falling, 0 both) where its guard function (index, or -1) is > 0; n_sub sub-intervals per
    step are scanned, so two crossings in one step are both found. t_eval: output times
    (monotone in the direction of integration), sampled on the dense output for the first
    n_eval components. t_fine: a second grid of output times for the orbit alone (its dense
    output costs 3 orbit evaluations, not the tangents'): the time series the torus analysis
    reads. Tangent vectors are rescaled to unit norm every renorm_dt (<= 0: every step),
    their logs accumulated in log_growth, which starts at -ln|w(t0)|.

    MEGNO (if megno, for the first tangent vector; Cincotta & Simo 2000): with
    L(t) = ln(|w(t)|/|w0|) and s = t - t0, Y(s) = (2/s) int_0^s u dL(u) and <Y> =
    (1/s) int_0^s Y. Integrating by parts, int_0^s u dL = s L(s) - int_0^s L: MEGNO needs
    only L, known exactly at every step end, never the rate dL/dt = w'.w/|w|^2, which near a
    close approach spikes within a single step (the Hessian grows like a power of 1/r) and
    wrecks any quadrature of it. int L and int Y are trapezoid sums over the steps (and at
    output times, over the part of the step before them, with L from the dense output).

    Returns a RawOutcome.
    """
    n = 2 * masses.size * d
    nf = y0.size
    direction = 1.0 if t1 >= t0 else -1.0
    K = np.zeros((16, nf))
    F = np.zeros((7, nf))
    y = y0.copy()
    yt = np.zeros(nf)
    ynew = np.zeros(nf)
    yd = np.zeros(nf)
    counts = np.zeros(4, dtype=np.int64)
    h_range = np.array([np.inf, 0.0])
    ev_index = np.full(max_events, -1, dtype=np.int64)
    ev_t = np.full(max_events, np.nan)
    ev_y = np.full((max_events, n), np.nan)
    n_ev_total = 0
    samples = np.full((t_eval.size, n_eval), np.nan)
    sample_log = np.full((t_eval.size, n_tan), np.nan)
    fine = np.full((t_fine.size, n), np.nan)
    wba = np.zeros(2)
    megno_sums = np.zeros(2)
    sample_megno = np.full((t_eval.size, 2), np.nan)
    int_L = 0.0           # int_0^t L of the first tangent vector, to the last step end
    Y_prev = 0.0          # Y at the last step end
    log_growth = np.zeros(n_tan)
    max_log = np.zeros(n_tan)
    eoff, ep, direc, terminal, guard, watch = events
    m = eoff.size - 1
    g_old = np.zeros(m)
    s_old = np.zeros(m)
    g_new = np.zeros(m)
    s_new = np.zeros(m)
    todo = np.zeros(m, dtype=np.int64)
    found_x = np.zeros(max(1, m * n_sub))
    found_e = np.zeros(max(1, m * n_sub), dtype=np.int64)

    t = t0
    status = OK_
    for a in range(nf):
        if not math.isfinite(y[a]):
            status = NONFINITE_
    if status == OK_:
        for tt in range(n_tan):
            w0 = norm_block(y, n * (1 + tt), n)
            log_growth[tt] = -math.log(w0)
        rhs(t, y, K[0], masses, d, measure, prof, par, n_tan)
        counts[2] += 1
        for a in range(nf):
            if not math.isfinite(K[0, a]):
                status = NONFINITE_
    i_eval = 0
    i_fine = 0
    if status == OK_:
        while i_eval < t_eval.size and t_eval[i_eval] == t0:
            samples[i_eval, :] = y[:n_eval]
            sample_log[i_eval, :] = log_growth
            i_eval += 1
        while i_fine < t_fine.size and t_fine[i_fine] == t0:
            fine[i_fine, :] = y[:n]
            i_fine += 1
        for e in range(m):
            if watch[e]:
                g_old[e] = event_value(ep, eoff[e], y, masses, d)
                s_old[e] = event_slope(ep, eoff[e], y, K[0], n, yd, masses, d, 1.0)
    L_prev = 0.0          # ln(|w|/|w0|) of the first tangent vector at the last step end
    t_next_renorm = t0 + direction * renorm_dt
    span = abs(t1 - t0) if status == OK_ else 0.0     # 0: nothing to step
    h_max = min(h_max, span) if h_max > 0.0 else span
    if span == 0.0:
        h = 0.0
    elif h0 > 0.0:
        h = min(h0, h_max)
    else:
        h = _initial_step(masses, d, measure, prof, par, n_tan, nf, n_err, t, y, K, yt,
                          direction, h_max, rtol, atol)
        counts[2] += 1
    h *= direction

    rejected_last = False
    nonfinite_last = False
    err_old = 1e-4
    if time_limit > 0.0:
        with objmode(clock0="f8"):
            clock0 = time.perf_counter()
    while span > 0.0:
        if counts[0] + counts[1] >= max_steps:
            status = STEP_LIMIT_
            break
        if time_limit > 0.0 and (counts[0] + counts[1]) % 256 == 255:
            with objmode(clock="f8"):
                clock = time.perf_counter()
            if clock - clock0 > time_limit:
                status = TIME_LIMIT_
                break
        if not (abs(h) > max(h_min, 10.0 * EPS * abs(t), 1e-300)):
            status = NONFINITE_ if nonfinite_last else COLLISION_
            break
        last = direction * (t + h - t1) >= 0.0
        if last:
            h = t1 - t
        stages(masses, d, measure, prof, par, n_tan, nf, t, y, h, K, yt, ynew)
        counts[2] += 11
        err = error_norm(y, ynew, K, h, n_err, rtol, atol)
        ok = math.isfinite(err)
        if ok and err <= 1.0:
            rhs(t + h, ynew, K[12], masses, d, measure, prof, par, n_tan)
            counts[2] += 1
            for a in range(nf):
                if not (math.isfinite(ynew[a]) and math.isfinite(K[12, a])):
                    ok = False
                    break
        if not ok:
            counts[1] += 1
            h *= 0.25
            rejected_last = True
            nonfinite_last = True
            continue
        nonfinite_last = False
        if err > 1.0:
            counts[1] += 1
            h *= max(1.0 / 3.0, 0.9 * err ** (-1.0 / 8.0))
            rejected_last = True
            continue

        # ---- accepted step [t, t + h]
        counts[0] += 1
        h_range[0] = min(h_range[0], abs(h))
        h_range[1] = max(h_range[1], abs(h))
        t_new = t1 if last else t + h
        nd_ready = 0
        x_stop = 1.0
        terminal_hit = False
        if m > 0:
            # screen every watched event on a cubic model of g(t); scan only steps whose
            # model may cross zero, on the 7th-order dense output
            scan = False
            for e in range(m):
                if watch[e]:
                    g_new[e] = event_value(ep, eoff[e], ynew, masses, d)
                    s_new[e] = event_slope(ep, eoff[e], ynew, K[12], n, yd, masses, d, h)
                    todo[e] = may_cross(g_old[e], s_old[e], g_new[e], s_new[e], h)
                    scan = scan or todo[e] > 0
            n_found = 0
            if scan:
                dense_prepare(masses, d, measure, prof, par, n_tan, n, False, t, y,
                               ynew, h, K, yt, F)
                counts[2] += 3
                nd_ready = n
                xtol = 4.0 * EPS * max(abs(t), abs(t_new)) / abs(h)
                for e in range(m):
                    if todo[e]:
                        g0 = eoff[guard[e]] if guard[e] >= 0 else -1
                        n_found = scan_events(ep, eoff[e], g_old[e], g_new[e], direc[e], g0,
                                        n_sub if todo[e] == 2 else 1, h, xtol, F, y, n, yd,
                                        masses, d, found_x, found_e, e, n_found)
            for e in range(m):
                g_old[e] = g_new[e]
                s_old[e] = s_new[e]
            for p in range(n_found):
                xr = found_x[p]
                if n_ev_total < max_events:
                    dense_eval(F, y, xr, n, yd)
                    ev_index[n_ev_total] = found_e[p]
                    ev_t[n_ev_total] = t + xr * h
                    ev_y[n_ev_total, :] = yd[:n]
                n_ev_total += 1
                if terminal[found_e[p]]:
                    terminal_hit = True
                    x_stop = xr
                    break
        t_stop = t + x_stop * h if terminal_hit else t_new
        need = nf if terminal_hit else 0
        if i_eval < t_eval.size and direction * (t_eval[i_eval] - t_stop) <= 0.0:
            need = max(need, n_eval)
        if i_fine < t_fine.size and direction * (t_fine[i_fine] - t_stop) <= 0.0:
            need = max(need, n)
        if need > nd_ready:
            dense_prepare(masses, d, measure, prof, par, n_tan, need, need > n, t, y, ynew, h, K, yt, F)
            counts[2] += 3
            nd_ready = need
        while i_eval < t_eval.size and direction * (t_eval[i_eval] - t_stop) <= 0.0:
            if t_eval[i_eval] == t_new:
                samples[i_eval, :] = ynew[:n_eval]
            else:
                dense_eval(F, y, (t_eval[i_eval] - t) / h, n_eval, yd)
                samples[i_eval, :] = yd[:n_eval]
            sample_log[i_eval, :] = log_growth
            if megno and n_eval >= 2 * n:
                part = t_eval[i_eval] - t
                L_at = log_growth[0] + math.log(norm_block(samples[i_eval], n, n))
                elapsed = t_eval[i_eval] - t0
                int_at = int_L + 0.5 * part * (L_prev + L_at)
                Y_at = 2.0 * (elapsed * L_at - int_at) / elapsed if elapsed != 0.0 else 0.0
                sample_megno[i_eval, 0] = elapsed * L_at - int_at
                sample_megno[i_eval, 1] = megno_sums[1] + 0.5 * part * (Y_prev + Y_at)
            i_eval += 1
        while i_fine < t_fine.size and direction * (t_fine[i_fine] - t_stop) <= 0.0:
            if t_fine[i_fine] == t_new:
                fine[i_fine, :] = ynew[:n]
            else:
                dense_eval(F, y, (t_fine[i_fine] - t) / h, n, yd)
                fine[i_fine, :] = yd[:n]
            i_fine += 1
        if terminal_hit:
            dense_eval(F, y, x_stop, nf, yd)
            y[:] = yd
            t = t_stop
            status = EVENT_
            break
        t_old = t
        t = t_new
        for a in range(nf):
            y[a] = ynew[a]
            K[0, a] = K[12, a]

        # ---- tangent vectors: track growth (FLI) and renormalise when due
        if n_tan > 0:
            due = direction * (t - t_next_renorm) >= 0.0
            if due:
                t_next_renorm = t + direction * renorm_dt
            for tt in range(n_tan):
                off = n * (1 + tt)
                wn = norm_block(y, off, n)
                L = log_growth[tt] + math.log(wn)
                max_log[tt] = max(max_log[tt], L)
                if tt == 0:
                    x = (0.5 * (t_old + t) - t0) / (t1 - t0)
                    g = math.exp(-1.0 / (x * (1.0 - x))) if 0.0 < x < 1.0 else 0.0
                    wba[0] += g * (L - L_prev)
                    wba[1] += g * (t - t_old)
                    if megno:
                        int_L += 0.5 * (t - t_old) * (L_prev + L)
                        elapsed = t - t0
                        Y_new = 2.0 * (elapsed * L - int_L) / elapsed
                        megno_sums[0] = elapsed * L - int_L
                        megno_sums[1] += 0.5 * (t - t_old) * (Y_prev + Y_new)
                        Y_prev = Y_new
                    L_prev = L
                if due or wn > 1e100 or wn < 1e-100:
                    inv = 1.0 / wn
                    for a in range(off, off + n):
                        y[a] *= inv
                        K[0, a] *= inv
                    log_growth[tt] += math.log(wn)
        if last:
            break

        fac = 0.9 * max(err, 1e-10) ** (-1.0 / 8.0 + 0.2 * BETA) * err_old ** BETA
        err_old = max(err, 1e-4)
        fac = min(6.0, max(1.0 / 3.0, fac))
        if rejected_last:
            fac = min(fac, 1.0)
        rejected_last = False
        h = direction * min(abs(h) * fac, h_max)

    counts[3] = n_ev_total
    return RawOutcome(status, t, y, counts, h_range, ev_index, ev_t, ev_y, samples, sample_log,
                      log_growth, max_log, fine, wba, megno_sums, sample_megno)


class Outcome(NamedTuple):
    """What one integration returns; nothing is raised for numerical trouble."""

    status: Status
    t: float                  # time reached
    y: np.ndarray             # final orbit state (n,)
    tangents: np.ndarray      # final tangent vectors, rescaled (n_tan, n)
    tangent_norms0: np.ndarray  # |w(t0)| per tangent vector
    megno_sums: np.ndarray    # MEGNO of the first tangent vector: (s Y/2, s <Y>) at the end
    log_growth: np.ndarray    # ln(|w(t)| / |w(t0)|) per tangent vector
    fli: np.ndarray           # max over step ends of ln(|w| / |w0|) per tangent vector
    n_steps: int              # accepted steps
    n_rejected: int
    n_rhs: int                # right-hand-side evaluations
    h_min: float              # smallest and largest accepted step
    h_max: float
    crossings: Crossings      # recorded crossings (at most max_events)
    n_crossings: int          # all crossings found, recorded or not
    t_eval: np.ndarray
    samples: np.ndarray       # dense-output states at t_eval (NaN beyond the end reached)
    sample_log_growth: np.ndarray  # ln(|w|/|w0|) at t_eval, per tangent vector
    sample_megno: np.ndarray  # (s Y/2, s <Y>) at t_eval (NaN unless megno and tangents sampled)
    fine: np.ndarray          # orbit states at t_fine (NaN beyond the end reached)
    ftle_wba: float           # weighted Birkhoff average of d ln|w|/dt, first tangent vector

    @property
    def ok(self) -> bool:
        return self.status.finished

    @property
    def deviations(self) -> np.ndarray:
        """Tangent vectors at their true length |w0| e^log_growth (inf past e^709)."""
        norms = np.linalg.norm(self.tangents, axis=1, keepdims=True)
        with np.errstate(over="ignore"):
            scale = self.tangent_norms0 * np.exp(self.log_growth)
            return self.tangents / norms * scale[:, None]


def integrate(system: System, y0, t_span, *, tangents=None, megno=False, rtol=defaults.RTOL,
              atol=defaults.ATOL, control_tangents=False, max_steps=defaults.MAX_STEPS,
              first_step=0.0,
              max_step=0.0, min_step=0.0, events: Sequence[Event] = (), max_events=100_000,
              event_substeps=8, t_eval=None, sample_tangents=False, renorm_interval=1.0,
              time_limit=0.0, t_fine=None):
    """Integrate an orbit of `system` (and optionally tangent vectors) over t_span.

    y0: orbit state (n,). t_span: t_final or (t0, t_final); backwards if t_final < t0.
    tangents: initial deviation vectors (n_tan, n). megno: also compute the MEGNO
    accumulators of the first tangent vector. control_tangents: include tangent vectors in the
    error norm. t_eval: output times sampled from the dense output (orbit only unless
    sample_tangents). t_fine: output times of the orbit alone, usually many (the torus
    analysis). time_limit: wall-clock seconds (0: none). Returns an `Outcome`.
    """
    y0 = np.asarray(y0, dtype=np.float64).ravel()
    if y0.size != system.n:
        raise ValueError(f"y0 must have {system.n} components (2 N d), got {y0.size}")
    t0, t1 = (0.0, float(t_span)) if np.ndim(t_span) == 0 else map(float, t_span)
    if not (rtol >= RTOL_MIN and atol > 0):
        raise ValueError(f"rtol must be >= {RTOL_MIN:.2g} (ten units of roundoff: double "
                         f"precision cannot honour less) and atol > 0, got {rtol!r}, {atol!r}")
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValueError(f"t_span must be finite, got {t_span!r}")
    n = system.n
    tan = np.zeros((0, n)) if tangents is None else np.asarray(tangents, float).reshape(-1, n)
    n_tan = tan.shape[0]
    if n_tan and not np.all(np.linalg.norm(tan, axis=1) > 0):
        raise ValueError("tangent vectors must be nonzero")
    megno = bool(megno and n_tan)
    state = np.concatenate([y0, tan.ravel()])
    t_eval = np.zeros(0) if t_eval is None else np.asarray(t_eval, dtype=np.float64).ravel()
    t_fine = np.zeros(0) if t_fine is None else np.asarray(t_fine, dtype=np.float64).ravel()
    for grid in (t_eval, t_fine):
        if grid.size and np.any(np.diff(grid) * (t1 - t0) < 0):
            raise ValueError("t_eval and t_fine must be monotone in the direction of "
                             "integration")
    n_eval = state.size if sample_tangents else n
    n_err = n * (1 + n_tan) if control_tangents else n
    masses, d, measure, prof, par = system.kernel_args
    res = dop853(y0=state, t0=t0, t1=t1, masses=masses, d=d, measure=measure, prof=prof,
                 par=par, n_tan=n_tan, megno=megno, rtol=float(rtol), atol=float(atol),
                 n_err=n_err, max_steps=int(max_steps), h0=float(first_step),
                 h_max=float(max_step), h_min=float(min_step),
                 events=encode_events(events, system), max_events=int(max_events),
                 n_sub=int(event_substeps), t_eval=t_eval, n_eval=n_eval,
                 renorm_dt=float(renorm_interval), time_limit=float(time_limit), t_fine=t_fine)
    y, samples, s_log = res.y, res.samples, res.sample_log
    tans = y[n:n * (1 + n_tan)].reshape(n_tan, n)
    norms = np.linalg.norm(tans, axis=1)
    if n_tan and sample_tangents:
        w = samples[:, n:n * (1 + n_tan)].reshape(-1, n_tan, n)
        s_log = s_log + np.log(np.linalg.norm(w, axis=2))
    else:
        s_log = np.full((t_eval.size, n_tan), np.nan)
    counts, wba, log_g = res.counts, res.wba, res.log_growth
    kept = min(int(counts[3]), int(max_events))
    return Outcome(
        status=Status(res.status), t=float(res.t), y=y[:n].copy(), tangents=tans.copy(),
        tangent_norms0=np.linalg.norm(tan, axis=1),
        megno_sums=res.megno_sums if megno else np.zeros(0), sample_megno=res.sample_megno,
        log_growth=log_g + np.log(norms), fli=np.maximum(res.max_log, log_g + np.log(norms)),
        n_steps=int(counts[0]), n_rejected=int(counts[1]), n_rhs=int(counts[2]),
        h_min=float(res.h_range[0]), h_max=float(res.h_range[1]),
        crossings=Crossings(res.ev_index[:kept].copy(), res.ev_t[:kept].copy(),
                            res.ev_y[:kept].copy()),
        n_crossings=int(counts[3]), t_eval=t_eval, samples=samples, sample_log_growth=s_log,
        fine=res.fine, ftle_wba=float(wba[0] / wba[1]) if wba[1] != 0 else np.nan)
