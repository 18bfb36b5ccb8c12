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
SLIDING = 100           # passages of b = 0 in a row with p_b below GRAZING of the momentum:
GRAZING = 1e-9          # the orbit slides along the collision line


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
                  max_passages: int = 1_000_000, backward: bool = False) -> PlaneSection:
    """The section h = height (crossed upwards) of the orbit of the plane's point `start`
    = (b, h, p_b, p_h): its first `crossings` points or those up to t_final, whichever
    come first; the pair collision b = 0 passed exactly (see the module's note). An orbit
    that meets b = 0 with p_b below GRAZING of its momentum SLIDING times in a row stays
    on the collision line (a start at the triple collision with p_b = 0): it stops there
    with status COLLISION.

    backward: the crossings of its past instead (the inverse section map), at times
    -t: the time-reversed orbit (momenta negated) crosses the level downwards where the
    orbit crossed it upwards."""
    if system.n_bodies != 3 or system.dim != 2 or not np.all(system.masses == 1.0):
        raise ValueError("the isosceles plane is of three unit masses in the plane")
    way = -1 if backward else 1
    b0, h0, p_b0, p_h0 = start
    y = plane_state(b0, h0, way * p_b0, way * p_h0)
    if y[WX] == y[UX]:      # a start at the pair collision: on the side p_b goes to
        y[WX], y[UX] = np.copysign(APART, way * p_b0), -np.copysign(APART, way * p_b0)
    E0 = system.energy(y)
    base = np.zeros(system.n)
    base[WX], base[UX] = 1.0, -1.0
    rise = np.zeros(system.n)
    rise[VY], rise[UY] = 1.0, -1.0
    t, ts, bs, pbs, passages, sliding = 0.0, [], [], [], 0, 0
    status = Status.OK
    run = dict(rtol=rtol, atol=atol)
    while True:
        side = 1.0 if y[WX] - y[UX] > 0 or (y[WX] == y[UX] and y[6 + WX] >= y[6 + UX]) else -1.0
        need = crossings - len(ts)         # the last one asked for ends the integration
        section = Event(Linear(rise, offset=-float(height)), direction=way,
                        terminal=need == 1)
        kink = Event(Linear(base), direction=-int(side), terminal=True)
        out = integrate(system, y, (t, t_final), events=[section, kink], max_events=need + 1,
                        **run)
        collided = out.status == Status.EVENT and out.crossings.index[-1] == 1
        hit = collided and out.t - t > 2 * LEAD
        if hit:     # again, to just before the collision: no step across the jump
            out = integrate(system, y, (t, out.t - LEAD), events=[section], max_events=need,
                            **run)
        keep = out.crossings.index == 0
        b, _, p_b, _ = plane_coordinates(out.crossings.y[keep])
        ts += out.crossings.t[keep].tolist()
        bs += b.tolist()
        pbs += p_b.tolist()
        t, y = out.t, out.y.copy()
        if hit and out.status == Status.OK and len(ts) < crossings:
            t, y, crossing = _to_collision(system, t, y, height, way)
            if crossing is not None:            # h passed the level in the Taylor step
                ts.append(crossing[0])
                bs.append(crossing[1])
                pbs.append(crossing[2])
        status = Status.EVENT if hit and out.status == Status.OK else out.status
        # meeting b = 0 with p_b ~ 0, again and again: it slides along the pair collision
        # (or sits at the triple one), passing it ever faster
        grazing = abs(y[6 + WX] - y[6 + UX]) <= GRAZING * np.sqrt(np.sum(y[6:] * y[6:]))
        sliding = sliding + 1 if collided and grazing else 0
        if sliding >= SLIDING:
            status = Status.COLLISION
            break
        if not collided or status != Status.EVENT or len(ts) >= crossings or \
                passages >= max_passages:
            break
        passages += 1
        # the other side of b = 0, mirrored exactly about the axis
        y[WX], y[UX] = -side * APART, side * APART
    n = min(len(ts), crossings)
    return PlaneSection(way * np.array(ts[:n]), np.array(bs[:n]), way * np.array(pbs[:n]),
                        passages,
                        Status.OK if status == Status.EVENT else status, way * t,
                        abs(system.energy(y) / E0 - 1.0))


def _to_collision(system: System, t: float, y: np.ndarray, height: float, way: int):
    """From a state just before the pair collision to the collision: the time tau at
    which b + b' tau + b'' tau^2 / 2 vanishes, the state a second-order Taylor step of the
    near side's (smooth) motion reaches there, and (t, b, p_b) where the same step crosses
    h = height upwards (way = 1) or downwards (-1) (None if it does not)."""
    dy = np.zeros_like(y)
    rhs(t, y, dy, system.model, 0)       # unit masses: dq/dt = p, dp/dt = F
    b, v, a = y[WX] - y[UX], dy[WX] - dy[UX], dy[6 + WX] - dy[6 + UX]
    tau = max(_first_root(b, v, a), 0.0)
    h, w, c = y[VY] - y[UY] - height, dy[VY] - dy[UY], dy[6 + VY] - dy[6 + UY]
    crossing = None
    if way * h < 0.0 <= way * (h + w * tau + 0.5 * c * tau * tau):
        s = min(max(_first_root(h, w, c), 0.0), tau)
        crossing = (t + s, b + v * s + 0.5 * a * s * s,
                    0.5 * (y[6 + WX] - y[6 + UX] + a * s))
    out = y.copy()
    out[:6] += tau * dy[:6] + 0.5 * tau * tau * dy[6:]
    out[6:] += tau * dy[6:]
    return t + tau, out, crossing


def _first_root(x, v, a) -> float:
    """The root of x + v s + a s^2 / 2 nearest s = 0 (x and v of opposite signs), without
    cancellation."""
    disc = v * v - 2.0 * a * x
    if a == 0.0 or disc < 0.0:
        return -x / v
    return 2.0 * x / (-v + np.copysign(np.sqrt(disc), -v))


class PlaneOrbit(NamedTuple):
    """A periodic orbit of the isosceles plane as a fixed point of the k-th power of its
    section map (b, p_b) -> (b, p_b): its k points on the section, and the map's Jacobian
    there, whose trace says how nearby orbits go round it."""

    b: np.ndarray           # its points on the section, in the order the orbit meets them
    p_b: np.ndarray
    crossings: int          # k: the points it has on the section (its least period there)
    period: float           # the time it takes to close
    residual: float         # |P^k(x) - x| at the last point Newton reached
    residuals: np.ndarray   # the same before each Newton step
    jacobian: np.ndarray    # dP^k/dx (2, 2) at (b[0], p_b[0]), by central differences
    #                         (its determinant is 1 where they are accurate: area kept)
    converged: bool

    @property
    def trace(self) -> float:
        return float(np.trace(self.jacobian))

    @property
    def kind(self) -> str:
        """elliptic (|trace| < 2: nearby orbits circle it on islands), hyperbolic
        (trace > 2) or inverse hyperbolic (trace < -2: they leave it, flipping sides)."""
        tr = self.trace
        return "elliptic" if abs(tr) < 2 else "hyperbolic" if tr > 2 else "inverse hyperbolic"

    @property
    def multipliers(self) -> np.ndarray:
        """The eigenvalues of the Jacobian (the orbit's non-trivial Floquet multipliers):
        e^(+-2 pi i nu) with nu the rotation number if elliptic, lambda and 1/lambda if
        not."""
        return np.linalg.eigvals(self.jacobian)

    def same_as(self, other: "PlaneOrbit", tol: float = 1e-7) -> bool:
        """Whether two converged orbits are one: the other's first point is one of ours."""
        return self.converged and other.converged and self.crossings == other.crossings \
            and bool(np.min(np.hypot(self.b - other.b[0], self.p_b - other.p_b[0])) <= tol)


def plane_periodic(system: System, energy: float, height: float, guess, crossings: int = 1,
                   t_final: float = 1000.0, tol: float = 1e-10, max_iter: int = 30,
                   rtol: float = 1e-13, step: float = 1e-5) -> PlaneOrbit:
    """The periodic orbit with `crossings` points on the section h = height of the energy
    shell nearest the guess (b, p_b): Newton's method on P^k(x) - x = 0 for the section
    map P, its Jacobian by central differences of width `step` (the map is not smooth
    enough at the pair collision for variational equations without jump terms; at the
    end step / max|J| where the orbit stretches its neighbourhood; one-sided at the
    shell's edge), each correction halved until it stays on the shell and lowers the
    residual. converged: |P^k(x) - x| <= tol (absolute; b and p_b are of order one on the
    shells drawn); an orbit that does not come back k times by t_final ends the search."""
    def image(x):       # P(x), ..., P^k(x) and their times, or None
        start = plane_start(system, energy, height, x[0], x[1])
        if start is None:
            return None
        sec = plane_section(system, start, t_final, height, crossings, rtol, rtol)
        if sec.b.size < crossings:
            return None
        return np.column_stack((sec.b, sec.p_b)), sec.t

    def residual(x):
        out = image(x)
        return (np.inf, None) if out is None else (float(np.hypot(*(out[0][-1] - x))), out)

    def jacobian(x, centre):        # centre: P^k(x)
        J = np.empty((2, 2))
        for j in range(2):
            e = np.zeros(2)
            e[j] = step
            ends = [image(x + s * e) for s in (1, -1)]
            ok = [end is not None for end in ends]
            if not any(ok):
                return None
            hi = ends[0][0][-1] if ok[0] else centre
            lo = ends[1][0][-1] if ok[1] else centre
            J[:, j] = (hi - lo) / (step * (ok[0] + ok[1]))
        return J

    x = np.array(guess, dtype=np.float64)
    r, out = residual(x)
    history = []
    J = None
    while out is not None and r > tol and len(history) < max_iter:
        history.append(r)
        J = jacobian(x, out[0][-1])
        if J is None:
            break
        dx = np.linalg.lstsq(J - np.eye(2), out[0][-1] - x, rcond=None)[0]
        for _ in range(30):                 # halve the correction until it helps
            r_new, out_new = residual(x - dx)
            if r_new < r:
                break
            dx = dx / 2
        else:
            break
        x, r, out = x - dx, r_new, out_new
    converged = out is not None and r <= tol
    if out is None:
        return PlaneOrbit(np.array([x[0]]), np.array([x[1]]), crossings, np.nan, np.inf,
                          np.array(history), np.full((2, 2), np.nan), False)
    points, t = out
    least = next((k + 1 for k in range(crossings - 1)
                  if np.hypot(*(points[k] - x)) <= max(100 * tol, 1e-8)), crossings)
    if converged and least == crossings:
        J = jacobian(x, points[-1])
        stretch = np.abs(J).max() if J is not None else 1.0
        if stretch > 1.0:                   # an unstable orbit: a narrower difference
            step /= stretch
            J = jacobian(x, points[-1])
    if least < crossings:                   # a fixed point of a lower power
        return plane_periodic(system, energy, height, x, least, t_final, tol, max_iter, rtol,
                              step)
    return PlaneOrbit(np.concatenate(([x[0]], points[:-1, 0])),
                      np.concatenate(([x[1]], points[:-1, 1])), crossings, float(t[-1]), r,
                      np.array(history), J if J is not None else np.full((2, 2), np.nan),
                      converged)


class PlaneManifolds(NamedTuple):
    """The stable and unstable manifolds of a hyperbolic periodic orbit of the plane at
    its first point on the section (branches unstable +, unstable -, stable +, stable -),
    and each unstable branch's first crossing with each stable one."""

    orbit: PlaneOrbit
    branches: list
    homoclinic: list


def plane_manifolds(system: System, energy: float, height: float, orbit: PlaneOrbit,
                    length: float, gap: float, t_final: float = 1000.0,
                    rtol: float = 1e-13, precision: float = 1e-11) -> PlaneManifolds:
    """The manifolds of a converged hyperbolic orbit (survey.numerics.manifolds) under its
    section map P^k and its inverse (the time-reversed orbit's downward crossings), each
    branch to arclength `length` with points at most `gap` apart, from the eigenvectors of
    the orbit's Jacobian. A homoclinic point's accuracy is the larger of its chords' error
    and how far it moves when the integration's tolerance is 10 times looser."""
    from .manifolds import Homoclinic, first_homoclinic, grow
    if not orbit.converged or orbit.kind == "elliptic":
        raise ValueError("manifolds belong to a converged hyperbolic orbit")
    made = manifold_seeds(system, energy, height, orbit, t_final, rtol)
    branches = [grow(seeds, kind, side, length, gap) for seeds, (kind, side) in
                zip(made, BRANCHES)]
    looser = manifold_seeds(system, energy, height, orbit, t_final, 10 * rtol)
    homoclinic = []
    for u in (0, 1):
        for s in (2, 3):
            found = first_homoclinic(branches, u, s, made, precision)
            if found is None:
                continue
            moved = first_homoclinic(branches, u, s, looser, precision)
            shift = np.inf if moved is None else float(np.sqrt(np.sum(
                (moved.point - found.point) ** 2)))
            homoclinic.append(Homoclinic(*found[:1], max(found.accuracy, shift), *found[2:]))
    return PlaneManifolds(orbit, branches, homoclinic)


BRANCHES = (("unstable", 1), ("unstable", -1), ("stable", 1), ("stable", -1))


def manifold_seeds(system: System, energy: float, height: float, orbit: PlaneOrbit,
                   t_final: float = 1000.0, rtol: float = 1e-13) -> list:
    """The Seeds of the four BRANCHES of a hyperbolic orbit's manifolds: its section map
    P^k (one crossing at a time, each from its point on the section) forward for the
    unstable ones, backward for the stable ones, from the eigenvectors of the orbit's
    Jacobian (portable 2 x 2 algebra: the same bits on every machine)."""
    from .manifolds import seeds
    k = orbit.crossings

    def mapping(backward):
        def step(x):
            start = plane_start(system, energy, height, x[0], x[1])
            if start is None:
                return None
            sec = plane_section(system, start, t_final, height, k, rtol, rtol,
                                backward=backward)
            return np.array([sec.b[-1], sec.p_b[-1]]) if sec.b.size == k else None
        return step

    (mu_u, v_u), (mu_s, v_s) = eigen2(orbit.jacobian)
    fixed = (orbit.b[0], orbit.p_b[0])
    return [seeds(mapping(False), fixed, v_u, mu_u, side) for side in (1, -1)] + \
        [seeds(mapping(True), fixed, v_s, 1.0 / mu_s, side) for side in (1, -1)]


def eigen2(J) -> tuple:
    """The eigenpairs (mu, v) of a real 2 x 2 matrix with real eigenvalues, the larger
    |mu| first, in closed form (only +, *, /, sqrt: portable bits): mu = t/2 +- sqrt(t^2/4
    - det), without cancellation; v = (b, mu - a) or (mu - d, c), whichever is longer."""
    (a, b), (c, d) = J
    t, det = a + d, a * d - b * c
    disc = t * t / 4 - det
    if not disc > 0:
        raise ValueError("not hyperbolic: complex or equal eigenvalues")
    big = t / 2 + np.copysign(np.sqrt(disc), t)
    pairs = []
    for mu in (big, det / big):
        v1, v2 = np.array([b, mu - a]), np.array([mu - d, c])
        v = v1 if v1 @ v1 >= v2 @ v2 else v2
        pairs.append((float(mu), v / np.sqrt(v @ v)))
    return pairs
