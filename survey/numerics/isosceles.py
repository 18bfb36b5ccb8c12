"""The isosceles plane (paper, Special Solutions): three equal masses u = (-b/2, -h/3),
v = (0, 2h/3), w = (b/2, -h/3) stay isosceles, a two-degree-of-freedom subsystem with
H = p_b^2 + 3/4 p_h^2 + U (p_b = db/dt / 2, p_h = 2 dh/dt / 3), whose classical Poincare
section -- (b, p_b) where the height crosses a level h0 upwards -- shows invariant curves,
islands and chaos.

Under a perimetric potential every orbit of the plane passes through the pair collision
b = 0, where u and w change places and the force jumps (b'' = -2 U'(P) (sgn b + b/r)): a
step across the jump costs the integrator its order (energy errors of 1e-8 at rtol 1e-12,
half the steps rejected). So the plane is integrated as the three-body system it is,
segment by segment, and no step straddles the jump: a first run finds the collision (a
terminal event on w_x - u_x), a second one ends 1e-8 before it, and a second-order Taylor
step on the near side's smooth force -- its error ~1e-24 -- reaches b = 0 exactly; there
the next segment starts on the far side. The plane's reflection symmetry holds bit for
bit in the integration (u and w get mirrored operations), so at the start of a segment
u and w are put 1e-150 either side of the axis, on the side the orbit goes to: the side
vector's direction is then exact.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..catalog.status import Status
from ..physics.system import System, rhs
from .events import Event, Linear
from .integrate import integrate

# u, v, w in the flat state: positions (x, y) of bodies 0, 1, 2, then their momenta
UX, UY, VX, VY, WX, WY = range(6)
APART = 1e-150          # half the base at a restart: its square is still a normal number
LEAD = 1e-8             # the time before a collision the integration hands over to a Taylor step


def plane_state(b, h, p_b, p_h) -> np.ndarray:
    """The three-body state (unit masses) of the plane's point (b, h, p_b, p_h)."""
    q = [-b / 2, -h / 3, 0.0, 2 * h / 3, b / 2, -h / 3]
    p = [-p_b, -p_h / 2, 0.0, p_h, p_b, -p_h / 2]
    return np.array(q + p, dtype=np.float64)


def plane_coordinates(y) -> tuple[np.ndarray, ...]:
    """(b, h, p_b, p_h) of three-body states (..., >= 12) in the plane."""
    y = np.asarray(y, dtype=np.float64)
    b = y[..., WX] - y[..., UX]
    h = y[..., VY] - y[..., UY]
    p_b = 0.5 * (y[..., 6 + WX] - y[..., 6 + UX])
    p_h = (2.0 / 3.0) * (y[..., 6 + VY] - y[..., 6 + UY])
    return b, h, p_b, p_h


def plane_start(system: System, energy: float, height: float, b: float,
                p_b: float) -> tuple[float, float, float, float] | None:
    """The point (b, height, p_b, p_h) of the section h = height on the energy shell,
    crossing upwards (p_h > 0 from H = E), or None where the shell does not reach (b, p_b)
    there."""
    room = energy - p_b * p_b - system.potential_energy(plane_state(b, height, 0.0, 0.0))
    if not room > 0:
        return None
    return float(b), float(height), float(p_b), float(np.sqrt(room / 0.75))


class PlaneSection(NamedTuple):
    """Where an orbit of the isosceles plane crossed the section h = h0 upwards."""

    t: np.ndarray           # crossing times
    b: np.ndarray
    p_b: np.ndarray
    passages: int           # times the orbit passed the pair collision b = 0
    status: Status          # of the last segment (OK: reached t_final or the crossings)
    t_end: float
    energy_error: float     # |E/E0 - 1| at the end


def plane_section(system: System, start, t_final: float, height: float = 0.0,
                  crossings: int = 1000, rtol: float = 1e-12, atol: float = 1e-12,
                  max_passages: int = 1_000_000) -> PlaneSection:
    """The section h = height (crossed upwards) of the orbit of the plane's point `start`
    = (b, h, p_b, p_h): its first `crossings` points or those up to t_final, whichever
    come first; the pair collision b = 0 passed exactly (see the module's note)."""
    if system.n_bodies != 3 or system.dim != 2 or not np.all(system.masses == 1.0):
        raise ValueError("the isosceles plane is of three unit masses in the plane")
    y = plane_state(*start)
    E0 = system.energy(y)
    base = np.zeros(system.n)
    base[WX], base[UX] = 1.0, -1.0
    rise = np.zeros(system.n)
    rise[VY], rise[UY] = 1.0, -1.0
    section = Event(Linear(rise, offset=-float(height)), direction=+1)
    t, ts, bs, pbs, passages = 0.0, [], [], [], 0
    status = Status.OK
    run = dict(rtol=rtol, atol=atol)
    while True:
        side = 1.0 if y[WX] - y[UX] > 0 or (y[WX] == y[UX] and y[6 + WX] >= y[6 + UX]) else -1.0
        kink = Event(Linear(base), direction=-int(side), terminal=True)
        out = integrate(system, y, (t, t_final), events=[section, kink],
                        max_events=crossings - len(ts) + 1, **run)
        hit = out.status == Status.EVENT and out.t - t > 2 * LEAD
        if hit:     # again, to just before the collision: no step across the jump
            out = integrate(system, y, (t, out.t - LEAD), events=[section],
                            max_events=crossings - len(ts) + 1, **run)
        keep = out.crossings.index == 0
        b, _, p_b, _ = plane_coordinates(out.crossings.y[keep])
        ts += out.crossings.t[keep].tolist()
        bs += b.tolist()
        pbs += p_b.tolist()
        status, t, y = out.status, out.t, out.y.copy()
        if hit and status == Status.OK:
            status = Status.EVENT
            t, y = _to_collision(system, t, y)
        if status != Status.EVENT or len(ts) >= crossings or passages >= max_passages:
            break
        passages += 1
        # the other side of b = 0, mirrored exactly about the axis
        y[WX], y[UX] = -side * APART, side * APART
    n = min(len(ts), crossings)
    return PlaneSection(np.array(ts[:n]), np.array(bs[:n]), np.array(pbs[:n]), passages,
                        Status.OK if status == Status.EVENT else status, t,
                        abs(system.energy(y) / E0 - 1.0))


def _to_collision(system: System, t: float, y: np.ndarray) -> tuple[float, np.ndarray]:
    """From a state just before the pair collision to the collision: the time tau at
    which b + b' tau + b'' tau^2 / 2 vanishes, and the state a second-order Taylor step of
    the near side's (smooth) motion reaches there."""
    dy = np.zeros_like(y)
    rhs(t, y, dy, *system.kernel_args, 0)       # unit masses: dq/dt = p, dp/dt = F
    b, v, a = y[WX] - y[UX], dy[WX] - dy[UX], dy[6 + WX] - dy[6 + UX]
    disc = v * v - 2.0 * a * b
    tau = -b / v if a == 0.0 or disc < 0.0 else 2.0 * b / (-v + np.copysign(
        np.sqrt(disc), -v))                     # the root nearest 0, without cancellation
    tau = max(tau, 0.0)
    out = y.copy()
    out[:6] += tau * dy[:6] + 0.5 * tau * tau * dy[6:]
    out[6:] += tau * dy[6:]
    return t + tau, out
