"""The compiled driver's state: L lanes' variable-major buffers and per-lane scalars
(`Lanes`), the accepted steps whose orbit samples wait for their dense output
(`Deferred`), and what the driver returns (`RawOutcome`); allocated on cache lines, the
orbit samples in a buffer a thread reuses batch after batch."""
from __future__ import annotations

import mmap
import threading
from typing import NamedTuple

import numpy as np

from ..physics.lanes import SIMD_LANES, workspace_size


class RawOutcome(NamedTuple):
    """What the compiled driver returns, one row per job (`integrate_batch` turns it into
    Outcomes). Rows of the event, sample and fine arrays belong to the jobs that record
    them, in job order."""

    status: np.ndarray        # (M,)
    t: np.ndarray             # (M,) time reached
    y: np.ndarray             # (M, nf) full state at t
    counts: np.ndarray        # (M, 4) accepted steps, rejected, rhs evaluations, events found
    h_range: np.ndarray       # (M, 2) smallest and largest accepted step
    ev_index: np.ndarray      # (Me, max_events) recorded crossings: event, time, orbit state
    ev_t: np.ndarray
    ev_y: np.ndarray
    samples: np.ndarray       # (Ms, T, n_eval) states at t_eval
    fine: np.ndarray          # (Mf, Tf, n) orbit states at t_fine
    near: np.ndarray          # (M or 0, driver.near_width) the closest approaches of the
    #                           jobs that record crossings
    ends: np.ndarray          # (M, W) the step-end indicators at t (tangents.STEP_END; the
    #                           logs of vectors as rescaled: their norms are added outside)
    sampled: np.ndarray       # (Ms, T, Ws) those sampled at t_eval


class Deferred(NamedTuple):
    """Accepted steps whose orbit samples at t_fine wait for their dense output: P slots,
    variable-major like Lanes over the orbit's n components (slot p of component i at
    Y[i * P + p]), each with what `dense_prepare` reads -- the states at the step's ends and
    stages 1 and 6-13 -- and which samples it holds."""

    Y: np.ndarray             # (n P,) state at the step's start
    YN: np.ndarray            # (n P,) at its end
    K: np.ndarray             # (16, n P) stages (14-16 computed when the batch is built)
    F: np.ndarray             # (7, n P) dense-output coefficients
    HH: np.ndarray            # (n P,) each slot's step at each of its components
    YT: np.ndarray            # (n P,) stage states
    W: np.ndarray             # rhs_lanes workspace
    x: np.ndarray             # (P,) each slot's first sample time in units of its step
    XX: np.ndarray            # (n P,) the same at each of its components
    S: np.ndarray             # (n P,) the states there
    t: np.ndarray             # (P,) the step's start, size, end
    h: np.ndarray
    t_new: np.ndarray
    row: np.ndarray           # (P,) the job's row of the fine output
    first: np.ndarray         # (P,) its samples first .. end - 1
    end: np.ndarray
    count: np.ndarray         # (1,) slots filled


class Lanes(NamedTuple):
    """The driver's per-lane state: variable-major buffers of L orbits, and one entry (or
    row) per lane of every scalar the one-orbit driver keeps."""

    Y: np.ndarray             # (nf L,) states
    K: np.ndarray             # (16, nf L) stage derivatives
    YT: np.ndarray            # (nf L,) stage states
    YN: np.ndarray            # (nf L,) candidate states
    F: np.ndarray             # (7, nf L) dense-output coefficients
    HH: np.ndarray            # (nf L,) each lane's step at each of its components
    W: np.ndarray             # rhs_lanes workspace
    S: np.ndarray             # (2 (nf + 1) L,) the error norms' scratch
    err: np.ndarray           # (L,) error norms
    grow: np.ndarray          # (L,) the step's factor if it is accepted (`step_factors`)
    err_next: np.ndarray      # (L,) err_old's next value then
    cut: np.ndarray           # (L,) the step's factor if it is rejected
    NW: np.ndarray            # ((2 n_tan + 1) L,) tangent vectors' norms, their logs,
                              # the steps' Birkhoff weights; (L,) finiteness
    taken: np.ndarray         # (L,) int64 -1 (every bit set) where the lane takes its new
                              # state, 0 where it keeps its old one
    job: np.ndarray           # (L,) the job a lane runs, -1: idle
    t: np.ndarray
    h: np.ndarray
    h_max: np.ndarray
    err_old: np.ndarray       # (L,) max(err, 1e-4)^(1/128) of the last accepted step
    flags: np.ndarray         # (L, 4) rejected last, nonfinite last, last step, tried
    i_eval: np.ndarray        # (L,) next t_eval / t_fine sample
    i_fine: np.ndarray
    t_next_renorm: np.ndarray
    acc: np.ndarray           # (L, 4) MEGNO's running L at the last step end, int L, Y
    #                           (`tangents.accumulate`); the job's clock start
    g_old: np.ndarray         # (L, m) watched events at the last step end, and slopes
    s_old: np.ndarray
    g_new: np.ndarray         # (L, m) the same at the accepted step's end (`_screen`)
    s_new: np.ndarray
    todo: np.ndarray          # (L, m) may_cross of each: the events the step scans
    found_x: np.ndarray
    found_e: np.ndarray
    yd: np.ndarray            # (nf,) scratch of one lane
    y1: np.ndarray            # (nf,) contiguous copy of one lane (starts)
    k1: np.ndarray            # (2, nf)
    NX: np.ndarray            # (6 L,) reduced states' positions, rebuilt (driver.near_terms)
    NR: np.ndarray            # (pairs L,) each lane's pair distances at its step end, and
    NT: np.ndarray            # (3, triangles L) its triangles' P, |A|, |A|/P^2
    wait: Deferred


CACHE_LINE = 64


def aligned_zeros(shape, dtype=np.float64) -> np.ndarray:
    """np.zeros starting on a cache line (numpy's own start on 16 bytes): a lane row of
    the SIMD loops -- a multiple of 64 bytes -- is then never split across two lines, nor a
    vector load or store within it. numpy's start varies with the process's heap, and so
    did the speed: up to a tenth of a scan task from one process to the next, and once, in
    a profile, a split load in the tangent forces made a whole run a third slower."""
    size = int(np.prod(shape)) * np.dtype(dtype).itemsize
    raw = np.zeros(size + CACHE_LINE, dtype=np.uint8)
    start = -raw.ctypes.data % CACHE_LINE
    return raw[start:start + size].view(dtype).reshape(shape)


def lane_state(L, n, nf, n_tan, m, n_sub, registers=0, bodies=0) -> Lanes:
    """A driver's state for L lanes of orbits of n components with n_tan tangent vectors
    each (nf in all), m watched events scanned in n_sub parts of a step, the `registers` of
    the system's formula programs in every lane, and the closest approaches of `bodies`."""
    m1 = max(m, 1)
    pairs = bodies * (bodies - 1) // 2
    triangles = max(pairs * (bodies - 2) // 3, 1)
    return Lanes(
        Y=aligned_zeros(nf * L), K=aligned_zeros((16, nf * L)), YT=aligned_zeros(nf * L), YN=aligned_zeros(nf * L),
        F=aligned_zeros((7, nf * L)), HH=aligned_zeros(nf * L), W=aligned_zeros(workspace_size(L, nf, registers)),
        S=aligned_zeros(2 * (nf + 1) * L),
        err=aligned_zeros(L), grow=aligned_zeros(L), err_next=aligned_zeros(L), cut=aligned_zeros(L),
        NW=aligned_zeros((2 * n_tan + 1) * L), taken=aligned_zeros(L, dtype=np.int64),
        job=np.full(L, -1, dtype=np.int64), t=aligned_zeros(L), h=aligned_zeros(L), h_max=aligned_zeros(L),
        err_old=aligned_zeros(L), flags=aligned_zeros((L, 4), dtype=np.int64),
        i_eval=aligned_zeros(L, dtype=np.int64), i_fine=aligned_zeros(L, dtype=np.int64),
        t_next_renorm=aligned_zeros(L), acc=aligned_zeros((L, 4)),
        g_old=aligned_zeros((L, m1)), s_old=aligned_zeros((L, m1)), g_new=aligned_zeros((L, m1)),
        s_new=aligned_zeros((L, m1)), todo=aligned_zeros((L, m1), dtype=np.int64),
        found_x=aligned_zeros(max(1, m * n_sub)), found_e=aligned_zeros(max(1, m * n_sub), dtype=np.int64),
        yd=aligned_zeros(nf), y1=aligned_zeros(nf), k1=aligned_zeros((2, nf)),
        NX=aligned_zeros(6 * L), NR=aligned_zeros(max(pairs, 1) * L),
        NT=aligned_zeros((3, triangles * L)),
        wait=deferred_state(2 * max(L, SIMD_LANES), n, registers))


def deferred_state(P, n, registers=0) -> Deferred:
    return Deferred(
        Y=aligned_zeros(n * P), YN=aligned_zeros(n * P), K=aligned_zeros((16, n * P)), F=aligned_zeros((7, n * P)),
        HH=aligned_zeros(n * P), YT=aligned_zeros(n * P), W=aligned_zeros(workspace_size(P, n, registers)),
        x=aligned_zeros(P), XX=aligned_zeros(n * P), S=aligned_zeros(n * P), t=aligned_zeros(P), h=aligned_zeros(P),
        t_new=aligned_zeros(P), row=aligned_zeros(P, dtype=np.int64), first=aligned_zeros(P, dtype=np.int64),
        end=aligned_zeros(P, dtype=np.int64), count=aligned_zeros(1, dtype=np.int64))


_samples = threading.local()


def reused_samples(shape) -> np.ndarray:
    """A NaN-filled array of `shape` in this thread's buffer of orbit samples, kept for its
    next batch and grown as needed. A task's torus analysis samples ~100 MB: a fresh array
    faults that memory in at every task, in the huge pages numpy asks for, at a cost that
    varies with the state of the machine's memory (a few percent of a bench scan task).
    Anonymous private memory, in the kernel's default pages."""
    size = int(np.prod(shape))
    if size == 0:
        return np.zeros(shape)
    buf = getattr(_samples, "buf", None)
    if buf is None or buf.size < size:
        _samples.buf = None             # the old buffer freed before the new one is made
        flags = mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS
        buf = _samples.buf = np.frombuffer(mmap.mmap(-1, size * 8, flags=flags),
                                           dtype=np.float64)
    out = buf[:size].reshape(shape)
    out.fill(np.nan)
    return out
