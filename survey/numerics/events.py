"""Events: scalar functions g of the orbit state whose zeros the driver locates on the
dense output -- their compiled evaluation, screening, scanning and root refinement, and the
Python objects that describe them (`Event`, `Linear`, `Quadratic`, `Sides`, `SidesRate`,
`Area`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple, Sequence

import numpy as np

from ..physics.forces import cross, dot, norm, sub, vec
from ..machine.jit import leaf
from ..physics.system import System
from ..physics.terms import DISTANCE, TRIANGLE
from .dop853 import EPS, dense_eval

# ---------------------------------------------------------------- event functions
# An event function is a scalar g(orbit state); crossings of g = 0 are located on the dense
# output. Encoded as (code, triplet, float parameters) so the kernel stays one compiled
# function. EV_QUADRATIC covers every quadratic form of the state: s.h and s x h of the
# Jacobi vectors, squared sides, the 2-D area and its rate, the moment of inertia.
EV_LINEAR, EV_QUADRATIC, EV_SIDES, EV_SIDES_RATE, EV_AREA = 0, 1, 2, 3, 4


@leaf
def event_value(ep, f0, y, masses, d):
    """Value at orbit state y of the event function whose record starts at ep[f0]:
    [code, i, j, k, offset, parameters...] (i, j, k: the triplet of side/area functions)."""
    c = int(ep[f0])
    g = ep[f0 + 4]
    p = f0 + 5
    if c == EV_LINEAR or c == EV_QUADRATIC:
        # sparse: count, then (i, c_i)...; for quadratic forms also count, (i, j, Q_ij)...
        # with each pair i <= j once
        end = p + 1 + 2 * int(ep[p])
        for z in range(p + 1, end, 2):
            g += ep[z + 1] * y[int(ep[z])]
        if c == EV_QUADRATIC:
            for z in range(end + 1, end + 1 + 3 * int(ep[end]), 3):
                g += ep[z + 2] * y[int(ep[z])] * y[int(ep[z + 1])]
    else:
        i, j, k = int(ep[f0 + 1]), int(ep[f0 + 2]), int(ep[f0 + 3])
        u, v, w = vec(y, i * d, d), vec(y, j * d, d), vec(y, k * d, d)
        if c == EV_AREA:
            A = cross(sub(v, u), sub(w, u))
            g += ep[p] * (0.5 * A[2] if d == 2 else 0.5 * norm(A))
        else:
            wv, uw, vu = sub(w, v), sub(u, w), sub(v, u)
            a_, b_, c_ = norm(wv), norm(uw), norm(vu)
            if c == EV_SIDES:
                g += ep[p] * a_ + ep[p + 1] * b_ + ep[p + 2] * c_
            else:
                nq = masses.size * d
                pu, pv, pw = vec(y, nq + i * d, d), vec(y, nq + j * d, d), vec(y, nq + k * d, d)
                mu, mv, mw = 1.0 / masses[i], 1.0 / masses[j], 1.0 / masses[k]
                vu_ = (pu[0] * mu, pu[1] * mu, pu[2] * mu)
                vv_ = (pv[0] * mv, pv[1] * mv, pv[2] * mv)
                vw_ = (pw[0] * mw, pw[1] * mw, pw[2] * mw)
                g += (ep[p] * dot(wv, sub(vw_, vv_)) / a_ + ep[p + 1] * dot(uw, sub(vu_, vw_)) / b_
                      + ep[p + 2] * dot(vu, sub(vv_, vu_)) / c_)
    return g


@leaf
def _g_at(x, ep, f0, F, y, nd, yd, masses, d):
    dense_eval(F, y, x, nd, yd)
    return event_value(ep, f0, yd[::1], masses, d)


@leaf
def _brent(ep, f0, a, b, fa, fb, xtol, F, y, nd, yd, masses, d):
    """Root of g(dense(x)) bracketed by [a, b] (Brent 1973); g's record starts at ep[f0]."""
    c, fc = a, fa
    dd = ee = b - a
    for _ in range(200):
        if (fb > 0.0) == (fc > 0.0):
            c, fc = a, fa
            dd = ee = b - a
        if abs(fc) < abs(fb):
            a, b, c = b, c, b
            fa, fb, fc = fb, fc, fb
        tol = 2.0 * EPS * abs(b) + 0.5 * xtol
        m = 0.5 * (c - b)
        if abs(m) <= tol or fb == 0.0:
            return b
        if abs(ee) >= tol and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:
                p, q = 2.0 * m * s, 1.0 - s
            else:
                q, r = fa / fc, fb / fc
                p = s * (2.0 * m * q * (q - r) - (b - a) * (r - 1.0))
                q = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if p > 0.0:
                q = -q
            else:
                p = -p
            if 2.0 * p < min(3.0 * m * q - abs(tol * q), abs(ee * q)):
                ee, dd = dd, p / q
            else:
                dd = ee = m
        else:
            dd = ee = m
        a, fa = b, fb
        b += dd if abs(dd) > tol else (tol if m > 0.0 else -tol)
        fb = _g_at(b, ep, f0, F, y, nd, yd, masses, d)
    return b


@leaf
def event_slope(ep, f0, y, f, n, buf, masses, d, h):
    """dg/dt = grad g . f: exact for linear and quadratic forms, otherwise by a central
    difference along the flow (it only feeds the screening model)."""
    c = int(ep[f0])
    p = f0 + 5
    if c == EV_LINEAR or c == EV_QUADRATIC:
        end = p + 1 + 2 * int(ep[p])
        s = 0.0
        for z in range(p + 1, end, 2):
            s += ep[z + 1] * f[int(ep[z])]
        if c == EV_QUADRATIC:
            for z in range(end + 1, end + 1 + 3 * int(ep[end]), 3):
                i, j = int(ep[z]), int(ep[z + 1])
                s += ep[z + 2] * (f[i] * y[j] + y[i] * f[j])
        return s
    dt = 1e-4 * abs(h)
    for a in range(n):
        buf[a] = y[a] + dt * f[a]
    gp = event_value(ep, f0, buf[::1], masses, d)
    for a in range(n):
        buf[a] = y[a] - dt * f[a]
    return (gp - event_value(ep, f0, buf[::1], masses, d)) / (2.0 * dt)


@leaf
def may_cross(g0, s0, g1, s1, h):
    """How g may vanish on a step, from the cubic Hermite model of g through (g0, g0') and
    (g1, g1'): 0 not at all; 1 once (a sign change at the ends, the model monotone); 2
    possibly several times (the model has an extremum inside the step that changes sign or
    comes within 1% of the step's variation scale of zero) -- then the step is scanned."""
    a0, a1 = h * s0, h * s1
    margin = 0.01 * (abs(g0) + abs(g1) + abs(a0) + abs(a1))
    change = (g0 < 0.0) != (g1 < 0.0) or g0 == 0.0 or g1 == 0.0
    # G(x) = A x^3 + B x^2 + a0 x + g0 on [0, 1]; G'(x) = 3A x^2 + 2B x + a0
    A = 2.0 * (g0 - g1) + a0 + a1
    B = 3.0 * (g1 - g0) - 2.0 * a0 - a1
    disc = B * B - 3.0 * A * a0
    if disc >= 0.0:
        r = math.sqrt(disc)
        if A != 0.0:
            x1, x2 = (-B + r) / (3.0 * A), (-B - r) / (3.0 * A)
        else:
            x1 = x2 = -a0 / (2.0 * B)
        for x in (x1, x2):
            if 0.0 < x < 1.0:
                G = ((A * x + B) * x + a0) * x + g0
                if change or (G < 0.0) != (g0 < 0.0) or abs(G) < margin:
                    return 2
    return 1 if change else 0


@leaf
def scan_events(ep, f0, g0, g1, want, guard0, n_sub, h, xtol, F, y, n, yd, masses, d,
                found_x, found_e, e, n_found):
    """Crossings of one event on a step: sign changes between n_sub sub-interval points of
    the dense output, each refined by Brent's method, kept if in direction `want` (+1, -1,
    0: both) and the guard (record at ep[guard0], none if < 0) is > 0; appended as (x, e) to
    (found_x, found_e) in time order. Returns the new count."""
    ga = g0
    xa = 0.0
    for s in range(1, n_sub + 1):
        xb = s / n_sub
        gb = g1 if s == n_sub else _g_at(xb, ep, f0, F, y, n, yd, masses, d)
        crossed = (ga < 0.0 and gb >= 0.0) or (ga > 0.0 and gb <= 0.0)
        rising = (gb > ga) == (h > 0.0)
        if crossed and (want == 0 or (want > 0) == rising):
            xr = xb if gb == 0.0 else _brent(ep, f0, xa, xb, ga, gb, xtol, F, y, n, yd,
                                            masses, d)
            dense_eval(F, y, xr, n, yd)
            if guard0 < 0 or event_value(ep, guard0, yd[::1], masses, d) > 0.0:
                p = n_found
                while p > 0 and found_x[p - 1] > xr:
                    found_x[p] = found_x[p - 1]
                    found_e[p] = found_e[p - 1]
                    p -= 1
                found_x[p] = xr
                found_e[p] = e
                n_found += 1
        ga = gb
        xa = xb
    return n_found


class EventFunction:
    """A scalar function g of the orbit state; subclasses say how it is encoded."""

    def encode(self, system: System):  # -> (code, triplet, float parameters)
        raise NotImplementedError


@dataclass(frozen=True)
class Linear(EventFunction):
    """g = coefficients . y + offset (a hyperplane in phase space)."""

    coefficients: Sequence[float]
    offset: float = 0.0

    def vector(self, n):
        c = np.asarray(self.coefficients, dtype=np.float64).ravel()
        if c.size != n:
            raise ValueError(f"Linear event needs {n} coefficients, got {c.size}")
        return c

    def encode(self, system):
        c = self.vector(system.n)
        i = np.flatnonzero(c)
        return EV_LINEAR, (0, 0, 0), np.concatenate([[self.offset, i.size],
                                                     np.stack([i, c[i]], 1).ravel()])


@dataclass(frozen=True)
class Quadratic(EventFunction):
    """g = y^T Q y + linear . y + offset, Q of shape (n, n) (or (N d, N d) on positions)."""

    matrix: np.ndarray
    linear: Sequence[float] | None = None
    offset: float = 0.0

    def matrices(self, n):
        """Q (n, n) and the linear part (n)."""
        Q = np.asarray(self.matrix, dtype=np.float64)
        if Q.shape == (n // 2, n // 2):
            Q = np.pad(Q, ((0, n // 2), (0, n // 2)))
        if Q.shape != (n, n):
            raise ValueError(f"Quadratic event needs a ({n}, {n}) matrix, got {Q.shape}")
        return Q, np.zeros(n) if self.linear is None else np.asarray(self.linear, float).ravel()

    def encode(self, system):
        return _quadratic_record(*self.matrices(system.n), self.offset)


def _quadratic_record(Q, c, offset):
    lin = np.flatnonzero(c)
    upper = np.triu(Q + Q.T) - np.diag(np.diag(Q))   # y^T Q y = sum_{i<=j} upper_ij y_i y_j
    i, j = np.nonzero(upper)
    return EV_QUADRATIC, (0, 0, 0), np.concatenate([
        [offset, lin.size], np.stack([lin, c[lin]], 1).ravel(),
        [i.size], np.stack([i, j, upper[i, j]], 1).ravel()])


@dataclass(frozen=True, eq=False)
class _Relative(EventFunction):
    """A form of the full state y = R x + c as one of a reduced state x (`relative_events`)."""

    matrix: np.ndarray
    linear: np.ndarray
    offset: float

    def encode(self, system):
        return _quadratic_record(self.matrix, self.linear, self.offset)


def relative_events(events: Sequence[Event], system: System, R, C):
    """The events as functions of a reduced state x whose full state is R x + c, c in the
    span of C's columns (the centre of mass's place and motion; integrate.Frame): possible
    when every function and guard is a linear or quadratic form that c leaves alone (the
    Jacobi surfaces phi, sigma, eta, p_sigma, p_eta; forms of relative coordinates), to
    roundoff -- else None."""
    def relative(f):
        if isinstance(f, Linear):
            Q, c = np.zeros((system.n, system.n)), f.vector(system.n)
        elif isinstance(f, Quadratic):
            Q, c = f.matrices(system.n)
        else:
            return None
        Q = 0.5 * (Q + Q.T)
        scale = max(np.abs(Q).max(), np.abs(c).max()) * np.abs(C).max()
        if max(np.abs(Q @ C).max(), np.abs(c @ C).max()) > 1e-12 * scale:
            return None
        return _Relative(R.T @ Q @ R, R.T @ c, float(f.offset))

    out = []
    for ev in events:
        g = relative(ev.function)
        guard = None if ev.guard is None else relative(ev.guard)
        if g is None or (ev.guard is not None and guard is None):
            return None
        out.append(replace(ev, function=g, guard=guard))
    return out


@dataclass(frozen=True)
class Sides(EventFunction):
    """g = wa a + wb b + wc c + offset for the sides of one triplet: the perimeter is
    weights (1, 1, 1), the inequity i_a is (-1, 1, 1), side a is (1, 0, 0)."""

    weights: Sequence[float] = (1.0, 1.0, 1.0)
    offset: float = 0.0
    triplet: tuple[int, int, int] = (0, 1, 2)
    code = EV_SIDES

    def encode(self, system):
        _check_triplet(self.triplet, system)
        w = np.asarray(self.weights, dtype=np.float64)
        return self.code, tuple(self.triplet), np.concatenate([[self.offset], w])


@dataclass(frozen=True)
class SidesRate(Sides):
    """g = d/dt (wa a + wb b + wc c) + offset: zero at extrema of a side combination."""

    code = EV_SIDES_RATE


@dataclass(frozen=True)
class Area(EventFunction):
    """g = scale * A + offset with A the signed area (2-D) or |A| (3-D) of one triplet."""

    offset: float = 0.0
    scale: float = 1.0
    triplet: tuple[int, int, int] = (0, 1, 2)

    def encode(self, system):
        _check_triplet(self.triplet, system)
        return EV_AREA, tuple(self.triplet), np.array([self.offset, self.scale])


def _check_triplet(triplet, system):
    if len(set(triplet)) != 3 or not all(0 <= b < system.n_bodies for b in triplet):
        raise ValueError(f"triplet {triplet} must name three different bodies of "
                         f"0..{system.n_bodies - 1}")


@dataclass(frozen=True)
class Event:
    """Crossings of function = 0 in a direction (+1 rising, -1 falling, 0 both), kept only
    where guard > 0 (e.g. s x h > 0 on the section phi = pi/2); terminal stops the run."""

    function: EventFunction
    direction: int = 0
    terminal: bool = False
    guard: EventFunction | None = None
    name: str = ""


def encode_events(events: Sequence[Event], system: System):
    """The kernel's event tuple: monitored events first, then their guard functions."""
    funcs = [ev.function for ev in events]
    guards = []
    for ev in events:
        if ev.direction not in (-1, 0, 1):
            raise ValueError(f"event direction must be -1, 0 or +1, got {ev.direction!r}")
        if ev.guard is None:
            guards.append(-1)
        else:
            guards.append(len(funcs))
            funcs.append(ev.guard)
    records = [np.concatenate([[code, *triplet], params]) for code, triplet, params in
               (f.encode(system) for f in funcs)]
    m, k = len(funcs), len(events)
    offsets = np.concatenate([[0], np.cumsum([r.size for r in records])]).astype(np.int64)
    ep = np.concatenate(records) if records else np.zeros(0)
    pad = np.zeros(m - k, dtype=np.int64)
    direction = np.concatenate([[ev.direction for ev in events], pad]).astype(np.int64)
    terminal = np.concatenate([[int(ev.terminal) for ev in events], pad]).astype(np.int64)
    guard = np.concatenate([guards, pad - 1]).astype(np.int64)
    watch = np.concatenate([np.ones(k, dtype=np.int64), pad])
    return (offsets, ep.astype(np.float64), direction, terminal, guard, watch)


class Crossings(NamedTuple):
    """Recorded event crossings in time order: which event, when, and the orbit state."""

    index: np.ndarray
    t: np.ndarray
    y: np.ndarray


def escape_events(system: System, radius: float, binding: float = 0.0) -> list[Event]:
    """Terminal events, one per body, at which it escapes: in a system of bodies, body i's
    distance from the centre of mass of the others rises through `radius` while the
    kinetic energy of their relative motion, mu |v_i - V_rest|^2 / 2 (mu the reduced
    mass), exceeds `binding` (a bound on what the others can still pull back from there);
    in an external field, the body's distance from the origin rises through `radius`. Each
    a quadratic form of the state (of relative coordinates where the system is translation
    invariant: `relative_events` writes them for a reduced state)."""
    N, d, m = system.n_bodies, system.dim, system.masses
    n = system.n
    events = []
    for i in range(N):
        A = np.zeros((d, n))           # the relative position (first half) and velocity
        B = np.zeros((d, n))
        rest = m.sum() - m[i]
        for c in range(d):
            A[c, i * d + c] = 1.0
            B[c, N * d + i * d + c] = 1.0 / m[i]
            if system.translation_invariant:
                for j in range(N):
                    if j != i:
                        A[c, j * d + c] = -m[j] / rest
                        B[c, N * d + j * d + c] = -1.0 / rest
        guard = None
        if system.translation_invariant:
            mu = m[i] * rest / (m[i] + rest)
            guard = Quadratic(0.5 * mu * B.T @ B, offset=-float(binding))
        events.append(Event(Quadratic(A.T @ A, offset=-float(radius) ** 2), direction=1,
                            terminal=True, guard=guard, name=f"escape of body {i}"))
    return events


# escape defaults: |u| beyond the derived radius's half below this share of the well's depth
ESCAPE_TAIL = 1e-3


def escape_defaults(system: System, radius: float = 0.0) -> tuple[float, float] | None:
    """(radius, binding) of `escape_events` derived from the potential, for bodies whose
    interaction vanishes far apart (pair terms and the triple dipole only): from u(r), the
    energy of two bodies at distance r with the others far away, the radius (unless given)
    is twice the distance beyond which |u| stays below ESCAPE_TAIL of the depth of u's
    well, and binding is (N - 1) max |u| beyond half the radius -- what the others pull
    back at most while they keep within half the radius of their centre of mass. None for
    other systems, and with no radius given where u has no well."""
    N, d = system.n_bodies, system.dim
    if N < 2 or any(t.measure not in (DISTANCE, TRIANGLE) for t in system.terms):
        return None
    r = np.geomspace(1e-2, 1e4, 1201)
    q = np.zeros((N, d))
    q[2:, 1] = 1e9 * np.arange(1, N - 1)          # the others far apart and far away

    def u(x):
        q[1, 0] = x
        return system.potential_energy(system.state(q, np.zeros((N, d))))
    far = u(1e9)
    with np.errstate(all="ignore"):
        us = np.array([u(x) for x in r]) - far
    if radius <= 0.0:
        well = int(np.argmin(us))
        depth = -us[well]
        if not (np.all(np.isfinite(us[well:])) and depth > 0.0 and 0 < well < r.size - 1):
            return None
        beyond = np.flatnonzero(np.abs(us) >= ESCAPE_TAIL * depth)[-1] + 1
        if beyond >= r.size - 1:
            return None
        radius = 2.0 * float(r[beyond])
    tail = us[r >= radius / 2]
    binding = float((N - 1) * np.abs(tail).max()) if tail.size else 0.0
    return float(radius), binding
