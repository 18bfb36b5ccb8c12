"""Tangent vectors over lanes and the indicators the driver accumulates from them at every
accepted step's end. Their norms (and logs) come from SIMD loops over the lanes, each
lane's sums in its components' order, as one orbit sums them (a reduced state's third body
rebuilt in its squares, rb). The step-end indicators are declared once, in STEP_END, with
their arithmetic beside them (`begin`, `accumulate`, `sample_at`) and what they become in
an Outcome (`outcome_fields`): a new one touches this module and the Outcome's field, and
tests/numerics/test_stepend.py fails for an entry it does not check against an
independent computation."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..machine import portable
from ..machine.jit import helper, lanes, leaf
from .dop853 import norm_block


class StepEnd(NamedTuple):
    """A step-end indicator: its Outcome field (and that of its values at t_eval, or ''),
    its slots in a job's row of the driver's `ends` (per tangent vector, or a fixed
    count) and of a sample's row of `sampled`, and where it comes from."""

    name: str
    sample_name: str
    per_tangent: bool
    slots: int
    sample_slots: int
    reference: str


STEP_END = (
    StepEnd("log_growth", "sample_log_growth", True, 1, 1,
            "ln(|w(t)|/|w(t0)|) per tangent vector, its logs summed at renormalisations "
            "(Benettin, Galgani, Giorgilli & Strelcyn 1980): the FTLE's numerator"),
    StepEnd("fli", "", True, 1, 0,
            "max over step ends of ln(|w|/|w0|) per tangent vector (Froeschle, Lega & "
            "Gonczi 1997)"),
    StepEnd("ftle_wba", "", False, 2, 0,
            "sum g dL / sum g dt over the steps, first vector, g = exp(-1/(s(1-s))) at the "
            "step's mid-time s: the weighted Birkhoff average of the growth rate (Das, "
            "Sander, Yorke & Meiss 2017; Sander & Meiss 2025)"),
    StepEnd("megno_sums", "sample_megno", False, 2, 2,
            "(s L - int L, int Y) of the first vector, s = t - t0, L = ln(|w|/|w0|): their "
            "ratios to s are Y/2 and <Y> (Cincotta & Simo 2000; by parts, from L alone)"),
)


def layout(n_tan: int, sampled: bool = False) -> dict[str, slice]:
    """Each STEP_END entry's slots in a row of `ends` (or of `sampled`), in order."""
    at, out = 0, {}
    for e in STEP_END:
        width = (e.sample_slots if sampled else e.slots) * (n_tan if e.per_tangent else 1)
        out[e.name] = slice(at, at + width)
        at += width
    return out


def width(n_tan: int, sampled: bool = False) -> int:
    return max([s.stop for s in layout(n_tan, sampled).values()])


@helper
def offsets(n_tan):
    """Where the compiled code finds each entry (`layout`, which a test holds it to): in
    `ends` log_growth, fli, wba, megno; in `sampled` log_growth, megno."""
    return 0, n_tan, 2 * n_tan, 2 * n_tan + 2, n_tan


@helper
def begin(ends, acc, y, n, n_tan, rb):
    """A job's accumulators at its start: the logs from -ln|w(t0)|, MEGNO's from zero
    (acc: L at the last step end, int L, Y)."""
    for tt in range(n_tan):
        ends[tt] = -portable.log(tangent_norm(y, n * (1 + tt), n, rb))
    acc[0] = acc[1] = acc[2] = 0.0


@helper
def accumulate(ends, acc, NW, L, k, n_tan, t0, t_old, t, megno):
    """Lane k's accepted step [t_old, t] (its state the new one): FLI, WBA and MEGNO from
    its tangent vectors' norms, logs and the step's Birkhoff weight in NW (`growth_terms`),
    before any renormalisation."""
    _, FLI, WBA, MEGNO, _ = offsets(n_tan)
    L_prev, int_L, Y_prev = acc[0], acc[1], acc[2]
    for tt in range(n_tan):
        Lw = ends[tt] + NW[(n_tan + tt) * L + k]
        ends[FLI + tt] = max(ends[FLI + tt], Lw)
        if tt == 0:
            g = NW[2 * n_tan * L + k]
            ends[WBA] += g * (Lw - L_prev)
            ends[WBA + 1] += g * (t - t_old)
            if megno:
                int_L += 0.5 * (t - t_old) * (L_prev + Lw)
                elapsed = t - t0
                Y_new = 2.0 * (elapsed * Lw - int_L) / elapsed
                ends[MEGNO] = elapsed * Lw - int_L
                ends[MEGNO + 1] += 0.5 * (t - t_old) * (Y_prev + Y_new)
                Y_prev = Y_new
            L_prev = Lw
    acc[0], acc[1], acc[2] = L_prev, int_L, Y_prev


@leaf
def sample_at(row, ends, acc, src, n, n_tan, rb, part, elapsed, megno):
    """The accumulators at an output time inside the step after the last step end (`part`
    of it past that end, `elapsed` since t0) into a sample's row: the logs as they stand
    (the sample's own tangent norms are added outside), MEGNO's sums continued over the
    part with L from the sampled state src (its first tangent vector, if megno)."""
    _, _, _, MEGNO, S_MEGNO = offsets(n_tan)
    for tt in range(n_tan):
        row[tt] = ends[tt]
    if megno:
        L_prev, int_L, Y_prev = acc[0], acc[1], acc[2]
        L_at = ends[0] + portable.log(tangent_norm(src, n, n, rb))
        int_at = int_L + 0.5 * part * (L_prev + L_at)
        Y_at = 2.0 * (elapsed * L_at - int_at) / elapsed if elapsed != 0.0 else 0.0
        row[S_MEGNO] = elapsed * L_at - int_at
        row[S_MEGNO + 1] = ends[MEGNO + 1] + 0.5 * part * (Y_prev + Y_at)


def outcome_fields(ends, sampled, n_tan, norms, sample_norms, megno) -> dict:
    """A job's STEP_END entries as Outcome fields, from its row of `ends`, its rows of
    `sampled` (None if it records no samples) and its tangent vectors' norms at the end
    and at the samples (None if samples carry no tangents: the sampled logs are NaN)."""
    at, s_at = layout(n_tan), layout(n_tan, sampled=True)
    log_g = ends[at["log_growth"]] + portable.vlog(norms)
    wba = ends[at["ftle_wba"]]
    T = 0 if sampled is None else sampled.shape[0]
    s_log = np.full((T, n_tan), np.nan)
    if sample_norms is not None and sampled is not None:
        s_log = sampled[:, s_at["log_growth"]] + portable.vlog(sample_norms)
    return dict(
        log_growth=log_g, fli=np.maximum(ends[at["fli"]], log_g),
        ftle_wba=float(wba[0] / wba[1]) if wba[1] != 0 else np.nan,
        megno_sums=ends[at["megno_sums"]] if megno else np.zeros(0),
        sample_log_growth=s_log,
        sample_megno=np.zeros((0, 2)) if sampled is None else sampled[:, s_at["megno_sums"]])


@lanes
def tangent_norms(Y, L, n, n_tan, NW, rb):
    """NW[t * L + k]: the norm of lane k's tangent vector t, summed in its components' order
    as `tangent_norm` does."""
    if L == 1:
        for t in range(n_tan):
            NW[t] = tangent_norm(Y, n * (1 + t), n, rb)
        return
    for t in range(n_tan):
        nw = NW[t * L:(t + 1) * L]
        for k in range(L):
            nw[k] = 0.0
        if rb is None:
            for i in range(n * (1 + t), n * (2 + t)):
                w = Y[i * L:]
                for k in range(L):
                    nw[k] += w[k] * w[k]
        else:           # positions, then momenta, each followed by the third body's
            for h in range(2):
                b = n * (1 + t) + 4 * h
                for i in range(b, b + 4):
                    w = Y[i * L:]
                    for k in range(L):
                        nw[k] += w[k] * w[k]
                _rebuilt_squares(Y, L, b, rb if h == 0 else (1.0, 1.0), nw)
        for k in range(L):
            nw[k] = math.sqrt(nw[k])


@helper
def _rebuilt_squares(Y, L, i0, c, nw):
    """Add to nw the squares of the third body's rebuilt components -(c0 a + c1 b) from
    rows i0, i0 + 1 (body 0) and i0 + 2, i0 + 3 (body 1)."""
    for r in range(2):
        a, b = Y[(i0 + r) * L:], Y[(i0 + 2 + r) * L:]
        for k in range(L):
            x = portable.fma(c[0], a[k], c[1] * b[k])
            nw[k] += x * x


@helper
def tangent_norm(y, off, n, rb):
    """|w| of the tangent vector at y[off:off + n]; of a reduced one (rb: the mass ratios)
    with the third body's rebuilt deviations, in the full vector's order: the norm FTLE,
    MEGNO and FLI measure whatever the state's form."""
    if rb is None:          # any layout (y[::1]): one compilation for every caller's
        return norm_block(y[::1], off, n)
    s = 0.0
    for h in range(2):                      # positions, then momenta
        b = off + 4 * h
        c = rb if h == 0 else (1.0, 1.0)
        for i in range(b, b + 4):
            s += y[i] * y[i]
        for r in range(2):
            x = portable.fma(c[0], y[b + r], c[1] * y[b + 2 + r])
            s += x * x
    return math.sqrt(s)


@lanes
def growth_terms(NW, t, h, flags, t0, t1, L, n_tan):
    """From the tangent vectors' norms NW[:n_tan L], what `_advance` needs of every lane at
    once: their logs (NW[n_tan L:2 n_tan L]) and each step's weight in the weighted
    Birkhoff average (NW[2 n_tan L:]): a log and an exp series per lane and step, in loops
    over the lanes that run as SIMD instructions (inside each lane's bookkeeping, one lane
    after another, their latency chains took ~8% of a 16-lane step)."""
    norms, logs, weights = NW[:n_tan * L], NW[n_tan * L:2 * n_tan * L], NW[2 * n_tan * L:]
    for i in range(n_tan * L):          # views: see dop853.error_norms
        logs[i] = portable.log(norms[i])
    for k in range(L):
        t_new = t1 if flags[k, 2] == 1 else t[k] + h[k]
        x = (0.5 * (t[k] + t_new) - t0) / (t1 - t0)
        weights[k] = portable.exp(-1.0 / (x * (1.0 - x))) if 0.0 < x < 1.0 else 0.0
