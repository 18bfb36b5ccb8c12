"""Integration as a user asks for it: `integrate_batch` for many orbits and `integrate` for
one, each validating its options, running the compiled lanes driver (numerics.driver) in
the frame it integrates (the relative motion of three bodies in the plane, `Frame`, or
the full state) and returning typed `Outcome`s; nothing is raised for numerical trouble.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Sequence

import numpy as np

from ..catalog import defaults
from ..catalog.status import Status
from ..machine import linalg, portable
from ..machine.jit import leaf
from ..physics.lanes import SIMD_LANES, SIMD_MIN
from ..physics.system import System
from ..physics.terms import AREA, PERIMETER
from .dop853 import RTOL_MIN
from .driver import (EVAL, EVENTS, FINE, NEAR_PAIRS, NEAR_TRIANGLES, Control, Model,
                     Recording, dop853, put_sample)
from .tangents import outcome_fields
from .events import Crossings, Event, encode_events, relative_events
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
    near: np.ndarray          # closest approaches (driver.near_width; empty unless asked)

    @property
    def ok(self) -> bool:
        return self.status.finished

    @property
    def deviations(self) -> np.ndarray:
        """Tangent vectors at their true length |w0| e^log_growth (inf past e^709)."""
        norms = portable.vnorm(self.tangents)[:, None]
        with np.errstate(over="ignore"):
            scale = self.tangent_norms0 * portable.vexp(self.log_growth)
            return self.tangents / norms * scale[:, None]


def lanes_for(jobs: int) -> int:
    """The lane count for a batch of jobs: SIMD_LANES, or for fewer jobs the largest power
    of two they fill, from SIMD_MIN (the fewest with which the compiler's SIMD loops run),
    which also takes 2 to SIMD_MIN - 1 jobs (SIMD_MIN lanes cost an orbit-step less than
    half of one lane's: `bench --only step`); one job runs in one lane, where its state's
    values stay in registers."""
    L = SIMD_LANES
    while L > jobs and L > SIMD_MIN:
        L //= 2
    return L if jobs >= min(L, 2) else 1


def integrate_batch(system: System, starts, t_span, *, tangents=None, record=None,
                    megno=False, rtol=defaults.RTOL, atol=defaults.ATOL,
                    control_tangents=False, max_steps=defaults.MAX_STEPS, first_step=0.0,
                    max_step=0.0, min_step=0.0, events: Sequence[Event] = (),
                    max_events=100_000, event_substeps=8, t_eval=None, sample_tangents=False,
                    renorm_interval=1.0, time_limit=0.0, t_fine=None,
                    lanes=None, reuse_samples=False, approach=False,
                    thin=0.0) -> list[Outcome]:
    """Integrate many orbits of `system` (starts (M, n)), each with its tangent vectors
    (tangents (M, n_tan, n)), over t_span, as SIMD lanes; one Outcome per orbit, each the
    bits `integrate` gives that orbit alone.

    record: per orbit, what it records besides its end (EVENTS | EVAL | FINE: crossings of
    `events`, samples at t_eval, orbit samples at t_fine; default all); an orbit that does
    not record one gets an empty array of it. lanes: the lane count (default `lanes_for`).
    time_limit: wall-clock seconds per orbit (0: none). reuse_samples: the outcomes' `fine`
    arrays are views of this thread's reused buffer, valid until its next batch with
    reuse_samples (for a caller done with them by then). The rest as for `integrate`.
    """
    starts = np.atleast_2d(np.asarray(starts, dtype=np.float64))
    M, n = starts.shape
    if n != system.n:
        raise ValueError(f"starts must have {system.n} components (2 N d), got {n}")
    t0, t1 = (0.0, float(t_span)) if np.ndim(t_span) == 0 else map(float, t_span)
    if not (rtol >= RTOL_MIN and atol > 0):
        raise ValueError(f"rtol must be >= {RTOL_MIN:.2g} (ten units of roundoff: double "
                         f"precision cannot honour less) and atol > 0, got {rtol!r}, {atol!r}")
    if not (math.isfinite(t0) and math.isfinite(t1)):
        raise ValueError(f"t_span must be finite, got {t_span!r}")
    tan = np.zeros((M, 0, n)) if tangents is None else \
        np.asarray(tangents, dtype=np.float64).reshape(M, -1, n)
    n_tan = tan.shape[1]
    if n_tan and not np.all(np.linalg.norm(tan, axis=2) > 0):
        raise ValueError("tangent vectors must be nonzero")
    megno = bool(megno and n_tan)
    y0s = np.concatenate([starts, tan.reshape(M, -1)], axis=1)
    t_eval = np.zeros(0) if t_eval is None else np.asarray(t_eval, dtype=np.float64).ravel()
    t_fine = np.zeros(0) if t_fine is None else np.asarray(t_fine, dtype=np.float64).ravel()
    for grid in (t_eval, t_fine):
        if grid.size and np.any(np.diff(grid) * (t1 - t0) < 0):
            raise ValueError("t_eval and t_fine must be monotone in the direction of "
                             "integration")
    record = np.full(M, EVENTS | EVAL | FINE) if record is None else \
        np.broadcast_to(np.asarray(record, dtype=np.int64), (M,))
    rows = np.full((3, M), -1, dtype=np.int64)
    for r, flag in enumerate((EVENTS, EVAL, FINE)):
        which = (record & flag) != 0
        rows[r, which] = np.arange(which.sum())
    frame = Frame.of(system, starts, tan, events)
    rb = None
    if frame is not None:               # bodies 0 and 1 in the centre-of-mass frame
        y0s, rb = frame.reduce(y0s, n_tan), frame.ratios
    r = y0s.shape[1] // (1 + n_tan)     # the kernel's block: n, or 8 reduced
    n_eval = y0s.shape[1] if sample_tangents else r
    n_err = r * (1 + n_tan) if control_tangents else r
    if not events:
        max_events = 0                  # nothing to record: no room for it
    model = system.model
    control = Control(t0=t0, t1=t1, n_tan=n_tan, megno=megno, rtol=float(rtol),
                      atol=float(atol), n_err=n_err, max_steps=int(max_steps),
                      h0=float(first_step), h_max=float(max_step), h_min=float(min_step),
                      renorm_dt=float(renorm_interval), time_limit=float(time_limit))
    L = int(lanes or lanes_for(M))
    # (one lane runs its jobs one after another: their order changes nothing)
    order = _costliest_first(np.ascontiguousarray(y0s[:, :r]), model, control, L, rb) \
        if M > L > 1 else np.arange(M)
    # (rows[:, order] alone would be Fortran-ordered: a second compilation of the kernel)
    recording = Recording(events=encode_events(frame.events if frame else events, system),
                          max_events=int(max_events), n_sub=int(event_substeps),
                          t_eval=t_eval, n_eval=n_eval, t_fine=t_fine,
                          near=0 if not approach or system.n_bodies < 2 else
                          NEAR_TRIANGLES if system.n_bodies == 3 else NEAR_PAIRS,
                          thin=float(thin))
    res = dop853(y0s[order], np.ascontiguousarray(rows[:, order]), model, control,
                 recording, L, rb, reuse_samples=bool(reuse_samples))
    at = np.empty(M, dtype=np.int64)
    at[order] = np.arange(M)
    if frame is not None:
        res = frame.restore(res, order, rows, t0, t_eval, t_fine)
        n_eval = y0s.shape[1] // r * n if sample_tangents else n
    return [_outcome(res, at[j], rows[:, j], n, n_tan, tan[j], megno, max_events, t_eval,
                     n_eval, t_fine, sample_tangents) for j in range(M)]


class Frame(NamedTuple):
    """A batch integrated as reduced states (physics.lanes.state_size): three bodies in the
    plane under one perimetric or areal term, every orbit moved to its centre-of-mass frame
    and bodies 0 and 1 integrated (the centre of mass rides along in 12 components -- a
    third of the stage combinations, error norms and dense output -- though the forces
    never move it: the scan's task 19% faster). Tangent vectors must have no centre-of-mass
    part (to roundoff), whose motion is not integrated; events must be linear or quadratic
    forms the centre of mass leaves alone (the Jacobi surfaces: events.relative_events),
    written anew for the reduced state; other batches run full."""

    masses: np.ndarray
    Q0: np.ndarray            # (M, 2) each orbit's centre of mass at t0
    V: np.ndarray             # (M, 2) and its velocity
    events: list              # the events as functions of the reduced state

    @staticmethod
    def of(system, starts, tan, events):
        model = system.model
        masses, d, measure, par = model.masses, model.d, model.measure, model.par
        if masses.size != 3 or d != 2 or par.ndim != 1 or measure not in (PERIMETER, AREA):
            return None
        m = masses[None, :, None]
        w = tan.reshape(tan.shape[0], tan.shape[1], 2, 3, 2)
        moments = np.concatenate([(m[:, None] * w[:, :, 0]).sum(2), w[:, :, 1].sum(2)], -1)
        if np.any(np.abs(moments) > 1e-12 * np.abs(w).max(initial=0.0)):
            return None
        relative = relative_events(events, system, *Frame.basis(masses))
        if relative is None:
            return None
        q, p = starts[:, :6].reshape(-1, 3, 2), starts[:, 6:].reshape(-1, 3, 2)
        return Frame(masses, (m * q).sum(1) / masses.sum(), p.sum(1) / masses.sum(),
                      relative)

    @staticmethod
    def basis(masses):
        """(R, C): a full state is R x + C c for the reduced state x (bodies 0 and 1 in the
        centre-of-mass frame) and c, the centre of mass's place and velocity."""
        R, C = np.zeros((12, 8)), np.zeros((12, 4))
        for k in range(2):
            for b in range(2):                        # bodies 0, 1: q at 2b, p at 6 + 2b
                R[2 * b + k, 2 * b + k] = R[6 + 2 * b + k, 4 + 2 * b + k] = 1.0
                R[4 + k, 2 * b + k] = -masses[b] / masses[2]
                R[10 + k, 4 + 2 * b + k] = -1.0
            C[k:6:2, k] = 1.0
            C[6 + k::2, 2 + k] = masses
        return R, C

    @staticmethod
    def coordinates(masses):
        """The inverse of [R C] (`basis`): a full state's reduced state (8 rows), then the
        centre of mass's place and velocity (4)."""
        m, M = masses, masses.sum()
        inv = np.zeros((12, 12))
        for k in range(2):
            for b in range(2):
                inv[2 * b + k, k:6:2] = -m / M
                inv[2 * b + k, 2 * b + k] += 1.0
                inv[4 + 2 * b + k, 6 + k::2] = -m[b] / M
                inv[4 + 2 * b + k, 6 + 2 * b + k] += 1.0
            inv[8 + k, k:6:2] = m / M
            inv[10 + k, 6 + k::2] = 1.0 / M
        return inv

    @property
    def ratios(self) -> tuple[float, float]:
        """m0/m2, m1/m2, which rebuild the third body (physics.system._lane_positions): the
        kernels' rb."""
        return float(self.masses[0] / self.masses[2]), float(self.masses[1] / self.masses[2])

    def reduce(self, y0s, n_tan):
        """Each job's orbit in its centre-of-mass frame, then bodies 0 and 1 of it and of
        its tangent vectors: (M, 8 (1 + n_tan))."""
        M = y0s.shape[0]
        blocks = y0s.reshape(M, 1 + n_tan, 2, 3, 2).copy()
        blocks[:, 0, 0] -= self.Q0[:, None]
        blocks[:, 0, 1] -= self.masses[None, :, None] * self.V[:, None]
        return np.ascontiguousarray(blocks[:, :, :, :2].reshape(M, -1))

    def full(self, z, at, t, t0):
        """Reduced rows z (..., 8 B: an orbit, then B - 1 tangent vectors) back to full ones
        (..., 12 B), compiled (`_rebuilt`, `_com_added`; numpy's temporaries were dear on
        large arrays): at, each row's job (along z's first axis), t its time (broadcast to
        z's rows). Samples need no rebuild: the kernel writes them in full."""
        lead = z.shape[:-1]
        rows = np.ascontiguousarray(z.reshape(-1, z.shape[-1]))
        out = np.empty((rows.shape[0], rows.shape[1] // 8 * 12))
        _rebuilt(rows, out, self.ratios)
        _com_added(out, self.masses, self.Q0, self.V, *self._rows(z, at, t), float(t0))
        return out.reshape(*lead, out.shape[1])

    @staticmethod
    def _rows(z, at, t):
        """Each row's job and time, z's rows flattened (at along its first axis)."""
        lead = z.shape[:-1]
        rows = int(np.prod(lead))
        job = np.repeat(np.asarray(at, dtype=np.int64), rows // max(len(at), 1))
        # a copy: a view of broadcast_to is read-only, a type of its own to the kernel
        return job, np.broadcast_to(t, lead).astype(np.float64).ravel()

    def restore(self, res, order, rows, t0, t_eval, t_fine):
        """The kernel's outcome with full states."""
        owner = np.empty((3, rows.shape[1]), dtype=np.int64)
        for k in range(3):
            owner[k, rows[k][rows[k] >= 0]] = np.flatnonzero(rows[k] >= 0)
        # samples are written in full by the kernel, but for the centre of mass's motion
        for z, owners, t in ((res.samples, owner[1], t_eval), (res.fine, owner[2], t_fine)):
            if z.size:
                _com_added(z.reshape(-1, z.shape[-1]), self.masses, self.Q0, self.V,
                           *self._rows(z, owners[:z.shape[0]], t[None, :]), float(t0))
        ev_y = res.ev_y
        if ev_y.size:   # (beyond each job's count: uninitialised, and never read)
            ev_y = self.full(ev_y, owner[0, :ev_y.shape[0]], res.ev_t, t0)
        return res._replace(y=self.full(res.y, order, res.t, t0), ev_y=ev_y)


@leaf
def _rebuilt(z, out, rb):
    """Reduced rows z (R, 8 B) to full ones out (R, 12 B), the third body rebuilt in each
    block of 8 (bodies 0 and 1) with numpy's operations in numpy's order (`put_sample`;
    rb: the mass ratios)."""
    for r in range(z.shape[0]):
        put_sample(out[r], z[r, ::1], z.shape[1], rb)


@leaf
def _com_added(y, masses, Q0, V, job, t, t0):
    """To the orbit (the first 12 components) of each full row of y, in place: the centre
    of mass of its job at its time."""
    for r in range(y.shape[0]):
        j = job[r]
        for c in range(2):
            s = Q0[j, c] + V[j, c] * (t[r] - t0)
            for b in range(3):
                y[r, 2 * b + c] += s
                y[r, 6 + 2 * b + c] += masses[b] * V[j, c]


PILOT = 1.0 / 400.0     # of the span: the step counts that order a batch's jobs


def _costliest_first(starts, model: Model, control: Control, L: int, rb) -> np.ndarray:
    """The order in which a batch's jobs take the lanes: costliest first, so that its last
    lanes to finish run orbits of about the same length, not the longest ones alone (the
    longest-first rule; orbits differ 4x in steps along a scan, and in grid order the costly
    chaotic ones come in a block). The cost: the steps each orbit takes over the first 1/400
    of the span (orbit alone, nothing recorded; along the equilateral scan their correlation
    with the whole run's is 0.9), ~0.3% of the run. Only the order changes: each orbit's
    bits are its own whatever its lane."""
    M, n = starts.shape
    t0, t1 = control.t0, control.t1
    pilot = dop853(np.ascontiguousarray(starts), np.full((3, M), -1, dtype=np.int64), model,
                   control._replace(t1=t0 + (t1 - t0) * PILOT, n_tan=0, megno=False, n_err=n),
                   Recording(events=encode_events((), None), max_events=0, n_sub=1,
                             t_eval=np.zeros(0), n_eval=n, t_fine=np.zeros(0)), L, rb)
    return np.argsort(-(pilot.counts[:, 0] + pilot.counts[:, 1]), kind="stable")


def _outcome(res, j, rows, n, n_tan, tan, megno, max_events, t_eval, n_eval, t_fine,
             sample_tangents) -> Outcome:
    y = res.y[j]
    tans = y[n:n * (1 + n_tan)].reshape(n_tan, n)
    re, rs, rf = rows
    samples = res.samples[rs] if rs >= 0 else np.zeros((0, n_eval))
    sample_norms = None
    if n_tan and sample_tangents and rs >= 0:
        sample_norms = portable.vnorm(samples[:, n:n * (1 + n_tan)].reshape(-1, n_tan, n))
    counts = res.counts[j]
    kept = min(int(counts[3]), int(max_events))
    crossings = Crossings(res.ev_index[re, :kept].copy(), res.ev_t[re, :kept].copy(),
                          res.ev_y[re, :kept].copy()) if re >= 0 else \
        Crossings(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, n)))
    return Outcome(
        status=Status(int(res.status[j])), t=float(res.t[j]), y=y[:n].copy(),
        tangents=tans.copy(), tangent_norms0=portable.vnorm(tan),
        n_steps=int(counts[0]), n_rejected=int(counts[1]), n_rhs=int(counts[2]),
        h_min=float(res.h_range[j, 0]), h_max=float(res.h_range[j, 1]), crossings=crossings,
        n_crossings=int(counts[3]), t_eval=t_eval, samples=samples,
        fine=res.fine[rf] if rf >= 0 else np.zeros((0, n)),
        near=res.near[j].copy() if res.near.size and re >= 0 else np.zeros(0),
        **outcome_fields(res.ends[j], res.sampled[rs] if rs >= 0 else None, n_tan,
                         portable.vnorm(tans), sample_norms, megno))


def flow_jacobian(system: System, y0, period: float, **options):
    """(the Outcome of y0 integrated over period with its full tangent block, the flow's
    Jacobian dy(T)/dy(0), n x n). Where the batch runs reduced (`Frame`), the tangents are
    the 8 columns of R, free of centre-of-mass motion, and the 4 of C are carried exactly (a
    translation stays, a boost adds its velocity times the period: the forces depend on
    relative places alone): the kernel is the one the orbit alone runs, not a second
    specialisation for full states (36 s of a cold first run's compiling)."""
    n = system.n
    y0 = np.asarray(y0, dtype=np.float64).ravel()
    if system.model.masses.size == 3 and n == 12:
        R, C = Frame.basis(system.model.masses)
        if Frame.of(system, y0[None], R.T[None], ()) is not None:
            out = integrate(system, y0, period, tangents=R.T, **options)
            carried = C.copy()
            carried[:, 2:] += period * C[:, :2]
            return out, linalg.dot(np.hstack([out.deviations.T, carried]),
                                   Frame.coordinates(system.model.masses))
    out = integrate(system, y0, period, tangents=np.eye(n), **options)
    return out, out.deviations.T


def integrate(system: System, y0, t_span, *, tangents=None, **options) -> Outcome:
    """Integrate an orbit of `system` (and optionally tangent vectors) over t_span.

    y0: orbit state (n,). t_span: t_final or (t0, t_final); backwards if t_final < t0.
    tangents: initial deviation vectors (n_tan, n). megno: also compute the MEGNO
    accumulators of the first tangent vector. control_tangents: include tangent vectors in
    the error norm. events: Event crossings to record (max_events kept, each step scanned in
    event_substeps parts). t_eval: output times sampled from the dense output (orbit only
    unless sample_tangents). t_fine: output times of the orbit alone, usually many (the
    torus analysis). renorm_interval: time between renormalisations of the tangent vectors.
    first_step, max_step, min_step: step sizes (0: chosen). max_steps: step attempts.
    time_limit: wall-clock seconds (0: none). Returns an `Outcome`.
    """
    y0 = np.asarray(y0, dtype=np.float64).ravel()
    if y0.size != system.n:
        raise ValueError(f"y0 must have {system.n} components (2 N d), got {y0.size}")
    tan = None if tangents is None else np.asarray(tangents, dtype=float).reshape(1, -1, y0.size)
    return integrate_batch(system, y0[None], t_span, tangents=tan, lanes=1, **options)[0]
