"""Tangent vectors over lanes: their norms (and logs) at a step's end, from which the driver
renormalises them and accumulates their growth -- the FLI, MEGNO, and the weighted
Birkhoff average's weights (growth_terms) -- each lane's sums in its components' order, as
one orbit sums them; a reduced state's third body rebuilt in its squares (rb)."""
from __future__ import annotations

import math


from ..machine import portable
from ..machine.jit import helper, lanes
from .dop853 import norm_block


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
    if rb is None:
        return norm_block(y, off, n)
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
