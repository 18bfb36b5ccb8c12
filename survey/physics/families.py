"""Initial-condition families, each a function of named parameters that a survey may turn
into grid axes: the paper's (three bodies in the plane) and three for any N and d
(`explicit`, `equilibrium`, `microcanonical`).

A three-body family builds positions and velocities of shape (3, 2) (in 3-D the plane
z = 0), an N-body family of shape (N, d); `initial_state` turns them into the flat state of
a `System` (momenta p = m v). The paper's printed
numbers decide where its text has typos: in the equilateral example the printed
dv/dt(0) = V_rot/2 (-sqrt3, 1) does not give E = 84.45577, J = 24.40192; (-sqrt3, -1) does,
and it is the uniformly rotating velocity.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..catalog.errors import Inaccessible
from ..machine import linalg, portable
from .equilibria import equilibrium_positions, forces
from .forces import profile
from .jacobi import (
    JacobiMasses,
    Reduced,
    phi_momentum_coefficient,
    reduced_potential,
    to_cartesian,
)
from .system import System, centre_of_mass
from .terms import AREA, PERIMETER

SQ3 = math.sqrt(3.0)


def rotation(angle: float) -> np.ndarray:
    c, s = portable.cos(angle), portable.sin(angle)
    return np.array([[c, -s], [s, c]])


def triangle_from_sides(a: float, b: float, c: float, masses=(1.0, 1.0, 1.0)) -> np.ndarray:
    """Vertices (u, v, w) with |w - v| = a, |u - w| = b, |v - u| = c, v - u along +x, w above
    (counter-clockwise, positive area), centre of mass at the origin."""
    if min(a, b, c) <= 0 or a >= b + c or b >= c + a or c >= a + b:
        raise ValueError(f"sides (a, b, c) = ({a:g}, {b:g}, {c:g}) do not make a "
                         "non-degenerate triangle: each side must be shorter than the sum "
                         "of the other two")
    x = (b * b + c * c - a * a) / (2.0 * c)
    q = np.array([[0.0, 0.0], [c, 0.0], [x, math.sqrt(b * b - x * x)]])
    return q - centre_of_mass(np.asarray(masses, dtype=float), q)


def _central_pull(system: System, q: np.ndarray) -> float:
    """Magnitude of the force on body 0 towards the centre of mass (the origin) at
    positions q (3, 2): the centripetal force of a uniformly rotating special solution,
    for any sum of terms."""
    force = forces(system, np.pad(q, ((0, 0), (0, system.dim - 2))))
    return -float(portable.vdot(force[:2], q[0])) / float(portable.vnorm(q[0]))


def _dU(system: System, q: np.ndarray) -> float:
    """U'(x) of the (single) triplet at positions q (3, 2)."""
    u, v, w = q
    if system.potential.measure == PERIMETER:
        x = float(portable.vnorm(v - u) + portable.vnorm(w - v) + portable.vnorm(u - w))
    else:
        x = 0.5 * abs((v - u)[0] * (w - u)[1] - (v - u)[1] * (w - u)[0])
    # profile's Python, which compiles only the branch the system takes: compiled, it
    # compiled the transcendental profiles for an array of parameters, which no kernel
    # passes (they pass a tuple), serially before a first run's workers start (1 s)
    return profile.py_func(system.potential.profile, system.potential.pair, x)[1]


def _equal_masses(system: System, family: str):
    m = system.masses
    if not np.allclose(m, m[0], rtol=0, atol=0):
        raise ValueError(f"family {family!r} is a special solution for equal masses only")


def _vec2(value, key):
    v = np.asarray(value, dtype=float)
    if v.shape != (2,):
        raise ValueError(f"{key} must be a 2-vector, got {value!r}")
    return v


def _sides(system, a, b, c, velocities, delta, delta_direction):
    """Paper Fig. 1: triangle with sides (a, b, c) = (2.9, 2.0, 1.8), du/dt = -dw/dt = (1, 3),
    dv/dt = 0 (E = 32.445, J = 2.94842); delta moves along delta_direction, so the default
    gives the paper's Lyapunov family du/dt = -dw/dt = (1 + delta, 3)."""
    q = triangle_from_sides(a, b, c, system.masses)
    vel = np.asarray(velocities, float) + delta * np.asarray(delta_direction, float)
    return q, vel


def _equilateral(system, side, v_rot, delta, delta_direction):
    """Paper Fig. 5: equilateral triangle u = (side/sqrt3, 0) rotated by 2pi/3, velocities
    du/dt = V_rot (0, 1) + delta dir, dv/dt = V_rot/2 (-sqrt3, -1), dw/dt = -du/dt - dv/dt.
    v_rot = 0 (the default) means the uniformly rotating value sqrt(r F/m) for this
    potential (F the pull towards the centre, r = side/sqrt3; = 6 for U = P^2/2, side
    2 sqrt3): delta = 0 is the rotating equilateral solution, delta = 3 the paper's regular
    orbit (E = 84.45577, J = 24.40192)."""
    _equal_masses(system, "equilateral")
    r = side / SQ3
    q = np.array([[r, 0.0], rotation(2 * math.pi / 3) @ [r, 0.0], rotation(4 * math.pi / 3) @ [r, 0.0]])
    if v_rot == 0:
        if not system.is_paper_kind:
            speed2 = r * _central_pull(system, q) / system.masses[0]
        elif system.potential.measure == AREA:   # |grad_u |A|| = side/2 on the altitude
            speed2 = r * _dU(system, q) * side / (2.0 * system.masses[0])
        else:                                    # |grad_u P| = sqrt3 towards the centre
            speed2 = r * _dU(system, q) * SQ3 / system.masses[0]
        if speed2 <= 0:
            raise ValueError("v_rot = 0 asks for the rotating speed, but this potential "
                             "does not pull the equilateral triangle inwards")
        v_rot = math.sqrt(speed2)
    du = v_rot * np.array([0.0, 1.0]) + delta * _vec2(delta_direction, "delta_direction")
    dv = 0.5 * v_rot * np.array([-SQ3, -1.0])
    return q, np.array([du, dv, -du - dv])


def _linear(system, half_length, velocity_u, delta, delta_direction):
    """Paper eq. (LinearIC): u = (-L, 0), v = 0, w = (L, 0), du/dt = (1.5, -10.0711),
    dv/dt = -delta (0.5, 1.0), dw/dt = -du/dt - dv/dt."""
    _equal_masses(system, "linear")
    q = np.array([[-half_length, 0.0], [0.0, 0.0], [half_length, 0.0]])
    du = _vec2(velocity_u, "velocity_u")
    dv = -delta * _vec2(delta_direction, "delta_direction")
    return q, np.array([du, dv, -du - dv])


def _rotating_line(system, radius, angle):
    """Collinear special solution: v = 0 at the centre, u = -w at distance r, rotating
    uniformly at omega = sqrt(F / (m r)), F the pull on u towards the centre
    (= sqrt(2 U'(4r) / (m r)) for perimetric potentials, paper Sec. 3.3; an areal potential
    exerts no force on a line)."""
    _equal_masses(system, "rotating_line")
    if system.is_paper_kind and system.potential.measure != PERIMETER:
        raise ValueError("family 'rotating_line' needs a perimetric potential (or pair "
                         "terms): an areal potential does not act on a line")
    q = np.array([[radius, 0.0], [0.0, 0.0], [-radius, 0.0]]) @ rotation(angle).T
    omega2 = (2.0 * _dU(system, q) if system.is_paper_kind
              else _central_pull(system, q)) / (system.masses[0] * radius)
    if omega2 <= 0:
        raise ValueError("the rotating line needs a pull towards the centre (U'(P) > 0)")
    vel = math.sqrt(omega2) * np.array([[-q[0, 1], q[0, 0]], [0.0, 0.0], [q[0, 1], -q[0, 0]]])
    return q, vel


def _isosceles(system, base, height, base_rate, height_rate, apex):
    """Paper Sec. 3.3: u = (-b/2, -h/3), v = (0, 2h/3), w = (b/2, -h/3) with the matching
    velocities; the shape stays isosceles for equal masses. apex = 2 puts w at the apex
    (u = (-b/2, -h/3), v = (b/2, -h/3)): then the reduced coordinates are the plane's own,
    sigma = |b|, eta = |h|, p_sigma = sgn(b) p_b, p_eta = sgn(h) p_h (p_b = db/dt / 2,
    p_h = 2 dh/dt / 3; H = p_b^2 + 3/4 p_h^2 + U)."""
    _equal_masses(system, "isosceles")
    if apex not in (1, 2):
        raise ValueError(f"isosceles apex must be 1 (v, the paper's) or 2 (w), got {apex!r}")
    corner = (1, 2) if apex == 1 else (2, 1)        # (apex, the base's right end)
    q, vel = np.zeros((3, 2)), np.zeros((3, 2))
    q[0], vel[0] = (-base / 2, -height / 3), (-base_rate / 2, -height_rate / 3)
    q[corner[0]], vel[corner[0]] = (0.0, 2 * height / 3), (0.0, 2 * height_rate / 3)
    q[corner[1]], vel[corner[1]] = (base / 2, -height / 3), (base_rate / 2, -height_rate / 3)
    return q, vel


def _areal_example(system, velocity_u):
    """Paper Fig. 7 (U = 2/|A| + |A|^2): equilateral u = (1, 0), v = (-1, sqrt3)/2,
    w = (-1, -sqrt3)/2 with du/dt = -dw/dt = (1, 3), dv/dt = 0. These caption velocities
    give E = 13.227, not the printed 5.51067 (which the printed area limits do follow from):
    ask for a target energy to put the start on the printed shell."""
    q = np.array([[1.0, 0.0], [-0.5, SQ3 / 2], [-0.5, -SQ3 / 2]])
    du = _vec2(velocity_u, "velocity_u")
    return q, np.array([du, [0.0, 0.0], -du])


def _section(system, energy, angular_momentum, sigma, p_sigma, eta, p_eta, phi, theta,
             direction):
    """A start on the surface phi = phi0 (default pi/2) on the energy shell H = E with
    angular momentum J: from (sigma, p_sigma, eta, p_eta), p_phi solves the reduced
    Hamiltonian, its sign the crossing direction (p_phi has the sign of dphi/dt). Where no
    real p_phi exists the point is inaccessible. Centre of mass at rest at the origin."""
    if sigma <= 0 or eta <= 0:
        raise ValueError(f"section start needs sigma > 0 and eta > 0, got {sigma}, {eta}")
    if direction not in (-1, 1):
        raise ValueError(f"section start direction must be +1 or -1, got {direction}")
    m = JacobiMasses.of(system)
    inertia = m.mu1 * sigma ** 2 + m.mu2 * eta ** 2
    rest = (energy - float(reduced_potential(system, sigma, eta, phi))
            - p_sigma ** 2 / (2 * m.mu1) - p_eta ** 2 / (2 * m.mu2)
            - angular_momentum ** 2 / (2 * inertia))
    if not rest >= 0:
        raise Inaccessible(f"no real p_phi: E - U - (other kinetic terms) = {rest:.6g} < 0")
    p_phi = direction * math.sqrt(rest / phi_momentum_coefficient(system, sigma, eta))
    r = Reduced(*(np.float64(v) for v in (sigma, eta, phi, theta, p_sigma, p_eta, p_phi,
                                          angular_momentum)))
    y = to_cartesian(system, r)
    q, p = system.split(y)
    return q, p / system.masses[:, None]


def _room(system, energy, angular_momentum, sigma, eta, phi):
    """E - U - J^2/(2 I) on the section phi: the kinetic energy left for (p_sigma, p_eta,
    p_phi) at the shape (sigma, eta); negative where the shape is out of reach."""
    m = JacobiMasses.of(system)
    inertia = m.mu1 * sigma ** 2 + m.mu2 * eta ** 2
    return (energy - reduced_potential(system, sigma, eta, phi)
            - angular_momentum ** 2 / (2 * inertia))


def _fine_axis() -> np.ndarray:
    """Points on (0, 1]: 128 even steps, and 24 more geometric down to 1e-9 -- a
    perimetric shell may reach a pair collision (sigma -> 0) only in a thin strip."""
    return np.concatenate([np.geomspace(1e-9, 1 / 128, 24, endpoint=False),
                           np.arange(1, 129) / 128])


def _reachable_box(system, energy, angular_momentum, phi):
    """(sigma_max, eta_max) of the shapes reachable on the section: a coarse grid over
    (0, L]^2, L doubled from 1e-3 until the reachable points stop short of its outer edges,
    then a fine grid, the box two of its steps beyond them. Unbounded shells (an areal
    potential's long thin triangles) are caught on the box's far edges, sampled down to
    1e-9 of its size, where no shape may be reachable; an empty shell is Inaccessible."""
    size, seen = 1e-3, False
    for _ in range(60):
        axis = size * np.arange(1, 33) / 32
        ok = _room(system, energy, angular_momentum, axis[:, None], axis[None, :], phi) >= 0
        seen |= bool(ok.any())
        if ok.any() and not (ok[-1].any() or ok[:, -1].any()):
            axis = size * _fine_axis()
            ok = _room(system, energy, angular_momentum, axis[:, None], axis[None, :], phi) >= 0
            i, j = (min(axis.size - 1, np.flatnonzero(ok.any(axis=k)).max() + 2)
                    for k in (1, 0))
            box = float(axis[i]), float(axis[j])
            edge = np.geomspace(1e-9, 1.0, 400)
            if (_room(system, energy, angular_momentum, box[0], box[1] * edge, phi) >= 0).any() \
                    or (_room(system, energy, angular_momentum, box[0] * edge, box[1],
                              phi) >= 0).any():
                break
            return box
        size *= 2.0
    if not seen:
        raise Inaccessible(f"no shape reaches E = {energy:g} at J = {angular_momentum:g} on "
                           "the section (the shell is empty)")
    raise ValueError(f"the shapes reachable on the section at E = {energy:g}, J = "
                     f"{angular_momentum:g} are unbounded (a potential that does not confine, "
                     "such as an areal one's long thin triangles): give sigma_max and eta_max "
                     "to sample a bounded part of the shell")


def _section_sample(system, energy, angular_momentum, seed, sigma_max, eta_max, phi, theta,
                    direction):
    """A seeded start drawn uniformly (in the section's Liouville measure d sigma d p_sigma
    d eta d p_eta) from everything the (E, J) shell reaches on the surface phi = phi0: a
    grid of seeds fills one shell of the 4-D section, for a Poincare plot of it. Rejection
    sampling of the shape against the room E - U - J^2/2I (the volume of momenta at a
    shape), then momenta uniform in that ellipse; p_phi as in `section`. The shapes are
    drawn from (0, sigma_max] x (0, eta_max]: found (0, the default) where the shell is
    bounded, given where it is not."""
    m = JacobiMasses.of(system)
    if sigma_max < 0 or eta_max < 0 or (sigma_max == 0) != (eta_max == 0):
        raise ValueError("sigma_max and eta_max bound the shapes drawn: both > 0, or both 0 "
                         "(found from the shell)")
    if sigma_max == 0:
        sigma_max, eta_max = _reachable_box(system, energy, angular_momentum, phi)
    grid = _fine_axis()
    most = float(np.max(_room(system, energy, angular_momentum, sigma_max * grid[:, None],
                              eta_max * grid[None, :], phi)))
    if not most > 0:
        raise Inaccessible(f"no shape in sigma <= {sigma_max:g}, eta <= {eta_max:g} reaches "
                           f"E = {energy:g} at J = {angular_momentum:g}")
    rng = np.random.default_rng(int(seed))
    for _ in range(100000):
        sigma, eta, level, r2, angle = rng.random(5)
        sigma, eta = sigma_max * (1.0 - sigma), eta_max * (1.0 - eta)    # in (0, max]
        room = float(_room(system, energy, angular_momentum, sigma, eta, phi))
        if room >= 1.25 * most * level:      # 1.25: the grid's maximum is not the maximum
            radius = math.sqrt(r2)
            p_sigma = math.sqrt(2 * m.mu1 * room) * radius * portable.cos(2 * math.pi * angle)
            p_eta = math.sqrt(2 * m.mu2 * room) * radius * portable.sin(2 * math.pi * angle)
            return _section(system, energy, angular_momentum, sigma, p_sigma, eta, p_eta, phi,
                            theta, direction)
    raise Inaccessible("no start drawn on the section in 100000 tries")


def _one_body_in_plane(system: System, family: str):
    if system.n_bodies != 1 or system.dim != 2 or system.translation_invariant:
        raise ValueError(f"family {family!r} starts one body in the plane in an external "
                         "field ([system] bodies = 1, dim = 2, an external term)")


def _field_room(system: System, energy, x, y):
    """2 m (E - U(x, y)): the p_x^2 + p_y^2 a body of mass m has left at (x, y)."""
    y = np.asarray(y, dtype=float)
    q = np.stack([np.full(y.shape, float(x)), y], axis=-1)
    states = np.concatenate([q, np.zeros_like(q)], axis=-1)
    return 2.0 * system.masses[0] * (energy - system.potential_energy(states))


def _field_section(system, energy, x, y, p_y, direction):
    """One body in the plane on the surface x = x0 (default 0) at energy E, the
    two-degree-of-freedom section of Henon & Heiles (1964): (y, p_y) given, p_x from
    H = E, its sign the crossing direction (+1: x increasing). Where no real p_x exists the
    point is inaccessible."""
    _one_body_in_plane(system, "field_section")
    if direction not in (-1, 1):
        raise ValueError(f"field_section direction must be +1 or -1, got {direction}")
    room = float(_field_room(system, energy, x, y)) - p_y * p_y
    if not room >= 0:
        raise Inaccessible(f"no real p_x: 2m(E - U) - p_y^2 = {room:.6g} < 0")
    p_x = direction * math.sqrt(room)
    return np.array([[x, y]], dtype=float), np.array([[p_x, p_y]]) / system.masses[0]


def _field_interval(system, energy, x):
    """The interval of y on the line x = x0 that the energy reaches around the line's
    lowest point: a grid over [-L, L], L doubled from 1 until the reachable run of points
    about the minimum stops short of both ends, its ends then bisected to 1e-12. An open
    shell (reachable out to 2^40) is an error naming the bounds to give."""
    size = 1.0
    for _ in range(40):
        axis = np.linspace(-size, size, 4097)
        room = _field_room(system, energy, x, axis)
        ok = room > 0
        if ok.any():
            lo = hi = int(np.argmax(room))
            while lo > 0 and ok[lo - 1]:
                lo -= 1
            while hi < axis.size - 1 and ok[hi + 1]:
                hi += 1
            if lo > 0 and hi < axis.size - 1:
                ends = []
                for inside, outside in ((axis[lo], axis[lo - 1]), (axis[hi], axis[hi + 1])):
                    for _ in range(60):
                        mid = 0.5 * (inside + outside)
                        if _field_room(system, energy, x, mid) > 0:
                            inside = mid
                        else:
                            outside = mid
                    ends.append(float(inside))
                return ends[0], ends[1], float(room[lo:hi + 1].max())
        size *= 2.0
    raise ValueError(f"the line x = {x:g} is reachable without bound at E = {energy:g} (an "
                     "open shell): give y_min and y_max to sample a bounded part")


def _field_section_sample(system, energy, seed, x, y_min, y_max, direction):
    """A seeded start drawn uniformly in (y, p_y) -- the section's invariant (Liouville)
    measure -- from the region the energy reaches on the surface x = x0: a grid of seeds is
    a random sample of the section, whose regular share estimates the share of its area
    on tori (Henon & Heiles' relative area). y is drawn from the reachable interval about
    the line's lowest point (found where y_min = y_max = 0, the default; or given), p_y uniform under the
    largest |p_y| there, rejected where p_y^2 > 2m(E - U); p_x as in `field_section`."""
    _one_body_in_plane(system, "field_section_sample")
    if (y_min, y_max) != (0.0, 0.0) and not y_min < y_max:
        raise ValueError("y_min and y_max bound the y drawn: y_min < y_max, or both 0 "
                         "(found from the shell)")
    if (y_min, y_max) == (0.0, 0.0):
        y_min, y_max, most = _field_interval(system, energy, x)
    else:
        most = float(np.max(_field_room(system, energy, x, np.linspace(y_min, y_max, 4097))))
    if not most > 0:
        raise Inaccessible(f"no point of x = {x:g}, {y_min:g} <= y <= {y_max:g} reaches "
                           f"E = {energy:g}")
    top = math.sqrt(1.25 * most)      # 1.25: the grid's maximum is not the maximum
    rng = np.random.default_rng(int(seed))
    for _ in range(100000):
        u, v = rng.random(2)
        y = y_min + (y_max - y_min) * u
        p_y = top * (2.0 * v - 1.0)
        if p_y * p_y < float(_field_room(system, energy, x, y)):
            return _field_section(system, energy, x, y, p_y, direction)
    raise Inaccessible("no start drawn on the section in 100000 tries")


def _positions(system: System, value, key: str) -> np.ndarray:
    if value is None:
        raise ValueError(f"{key} is required: {system.n_bodies} rows of {system.dim} numbers")
    q = np.asarray(value, dtype=float)
    if q.shape != (system.n_bodies, system.dim) or not np.all(np.isfinite(q)):
        raise ValueError(f"{key} must be {system.n_bodies} rows (one per body) of "
                         f"{system.dim} finite numbers, got shape {q.shape}")
    dist = np.linalg.norm(q[:, None] - q[None], axis=-1)[np.triu_indices(len(q), 1)]
    if dist.size and dist.min() <= 1e-12 * max(dist.max(), 1e-300):
        raise ValueError(f"{key}: two bodies start at the same place")
    return q


def _explicit(system, positions, velocities):
    """Positions and velocities given as arrays of N rows of d numbers (any N, d)."""
    q = _positions(system, positions, "positions")
    v = np.zeros_like(q) if velocities is None else np.asarray(velocities, dtype=float)
    if v.shape != q.shape or not np.all(np.isfinite(v)):
        raise ValueError(f"velocities must be {system.n_bodies} rows of {system.dim} finite "
                         f"numbers, got shape {v.shape}")
    return q, v


def _random_motion(system: System, q: np.ndarray, rng, angular_momentum: float):
    """Seeded Gaussian velocities (in an external field: as drawn) with zero total momentum
    and zero angular momentum about the centre of mass, and the rigid rotation that carries `angular_momentum` (about z):
    (internal, rotation) velocities. Sums body by body and the inertia tensor inverted
    through linalg.symmetric_eigen: the same bits on every machine."""
    m = system.masses[:, None]
    r = q - centre_of_mass(system.masses, q)
    v = rng.normal(size=q.shape)
    if not system.translation_invariant:     # an external field: momentum is not conserved
        if angular_momentum:
            raise ValueError("in an external field the angular momentum is not conserved: "
                             "give angular_momentum = 0")
        return v, np.zeros_like(v)
    v -= centre_of_mass(system.masses, v)
    # remove the rigid rotations: L = I omega, with the inertia tensor of the body
    r3 = np.pad(r, ((0, 0), (0, 3 - system.dim)))
    v3 = np.pad(v, ((0, 0), (0, 3 - system.dim)))
    inertia = (m[:, :, None] * r3[:, :, None] * r3[:, None, :]).sum(axis=0)
    inertia = (inertia[0, 0] + inertia[1, 1] + inertia[2, 2]) * np.eye(3) - inertia
    L = np.sum(m * np.cross(r3, v3), axis=0)
    axes = [2] if system.dim == 2 else [0, 1, 2]
    w, V = linalg.symmetric_eigen(np.ascontiguousarray(inertia[np.ix_(axes, axes)]))
    # the least-squares omega: eigenvalues below 1e-12 of the largest (a line's own axis)
    # carry none of it
    rank = w > 1e-12 * w.max()
    omega, spin = np.zeros(3), np.zeros(3)
    omega[axes] = (V[:, rank] * (np.sum(V[:, rank] * L[axes][:, None], axis=0)
                                 / w[rank])).sum(axis=1)
    v = v - np.cross(omega, r3)[:, :system.dim]
    if angular_momentum:     # the rigid rotation omega with I omega = (0, 0, J)
        if not rank.all():
            raise ValueError("a collinear configuration cannot carry this angular momentum")
        J = np.array([0.0, 0.0, angular_momentum])[axes]
        spin[axes] = (V * (np.sum(V * J[:, None], axis=0) / w)).sum(axis=1)
    return v, np.cross(spin, r3)[:, :system.dim]


def _shell(system, q, internal, rotation, energy):
    """Velocities rotation + s internal with K + U = energy (s >= 0), or Inaccessible."""
    m = system.masses[:, None]
    u = float(system.potential_energy(np.concatenate([q.ravel(), np.zeros(q.size)])))
    k_rot = 0.5 * np.sum(m * rotation ** 2)
    k_int = 0.5 * np.sum(m * internal ** 2)
    room = energy - u - k_rot
    if not room >= 0:
        raise Inaccessible(f"U(q0) + J^2/2I = {u + k_rot:.6g} exceeds the target energy "
                           f"{energy:.6g}")
    return rotation + math.sqrt(room / k_int) * internal


def _equilibrium(system, positions, displacement, speed, seed):
    """The equilibrium reached from `positions` (N rows of d numbers) by minimising the
    potential (e.g. the equilateral or linear trimer, the LJ7 pentagonal bipyramid), each
    body then moved by `displacement` times a seeded Gaussian, with seeded random velocities
    of rms `speed` at zero momentum and angular momentum. With a target energy the velocities
    are rescaled to it (any speed > 0 then does). displacement = speed = 0 is the
    equilibrium at rest."""
    q = equilibrium_positions(system, _positions(system, positions, "positions"))
    rng = np.random.default_rng(int(seed))
    q = q + displacement * rng.normal(size=q.shape)
    v, _ = _random_motion(system, q, rng, 0.0)
    rms = math.sqrt(np.mean(np.sum(v * v, axis=1)))
    return q, v * (speed / rms if rms > 0 else 0.0)


def _microcanonical(system, positions, displacement, angular_momentum, seed, energy):
    """A seeded random start on the energy shell H = energy at zero total momentum and
    angular momentum J (about z): the bodies at `positions` each moved by `displacement`
    times a Gaussian (redrawn, up to 100 times, until U + J^2/2I < energy), Gaussian
    velocities with no momentum or rigid rotation, scaled to the kinetic energy left over
    after the rotation that carries J."""
    q0 = _positions(system, positions, "positions")
    rng = np.random.default_rng(int(seed))
    for _ in range(100):
        q = q0 + displacement * rng.normal(size=q0.shape)
        internal, rotation = _random_motion(system, q, rng, angular_momentum)
        try:
            return q, _shell(system, q, internal, rotation, energy)
        except Inaccessible as exc:
            last = exc
        if displacement == 0:
            break
    raise last


@dataclass(frozen=True)
class Family:
    name: str
    build: Callable
    defaults: dict
    any_n: bool = False     # builds (N, d) arrays for any system, not three bodies in a plane

    @property
    def doc(self) -> str:
        return " ".join((self.build.__doc__ or "").split())


FAMILIES = {f.name: f for f in [
    Family("sides", _sides, dict(a=2.9, b=2.0, c=1.8,
                                 velocities=((1.0, 3.0), (0.0, 0.0), (-1.0, -3.0)),
                                 delta=0.0, delta_direction=((1.0, 0.0), (0.0, 0.0), (-1.0, 0.0)))),
    Family("equilateral", _equilateral, dict(side=2 * SQ3, v_rot=0.0, delta=0.0,
                                             delta_direction=(0.5, -1.0))),
    Family("linear", _linear, dict(half_length=2.5, velocity_u=(1.5, -10.0711), delta=0.0,
                                   delta_direction=(0.5, 1.0))),
    Family("rotating_line", _rotating_line, dict(radius=2.5, angle=0.0)),
    Family("isosceles", _isosceles, dict(base=2.0, height=1.5, base_rate=0.0, height_rate=0.0,
                                         apex=1)),
    Family("areal_example", _areal_example, dict(velocity_u=(1.0, 3.0))),
    Family("section", _section, dict(energy=84.45577136594005, angular_momentum=24.401923788646684,
                                     sigma=2 * SQ3, p_sigma=0.0, eta=3.0, p_eta=0.0,
                                     phi=math.pi / 2, theta=0.0, direction=1)),
    Family("section_sample", _section_sample,
           dict(energy=84.45577136594005, angular_momentum=24.401923788646684, seed=0,
                sigma_max=0.0, eta_max=0.0, phi=math.pi / 2, theta=0.0, direction=1)),
    Family("field_section", _field_section, dict(energy=None, x=0.0, y=0.0, p_y=0.0,
                                                 direction=1), any_n=True),
    Family("field_section_sample", _field_section_sample,
           dict(energy=None, seed=0, x=0.0, y_min=0.0, y_max=0.0, direction=1), any_n=True),
    Family("explicit", _explicit, dict(positions=None, velocities=None), any_n=True),
    Family("equilibrium", _equilibrium, dict(positions=None, displacement=0.0, speed=1.0,
                                             seed=0), any_n=True),
    Family("microcanonical", _microcanonical, dict(positions=None, displacement=0.05,
                                                   angular_momentum=0.0, seed=0,
                                                   energy=None), any_n=True),
]}


def family_parameters(name: str) -> dict:
    """Parameter names and defaults of a family (KeyError-free: unknown names raise)."""
    if name not in FAMILIES:
        raise ValueError(f"unknown family {name!r}; choose one of {', '.join(FAMILIES)}")
    return dict(FAMILIES[name].defaults)


def initial_state(system: System, family: str, energy=None, **params) -> np.ndarray:
    """Flat state (positions, momenta) of a family member; parameters not given take the
    family's defaults. With a target `energy`, the centre-of-mass-frame velocities are
    rescaled so that K + U = energy (raises Inaccessible where U(q0) > energy, or where
    there is no relative motion to rescale); a family with its own energy parameter
    (`section`) starts on the shell directly."""
    defaults = family_parameters(family)
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise ValueError(f"family {family!r} has no parameter {unknown[0]!r}; "
                         f"its parameters are {', '.join(defaults)}")
    spec = FAMILIES[family]
    if system.n_bodies != 3 and not spec.any_n:
        raise ValueError(f"family {family!r} is a three-body family; the system has "
                         f"{system.n_bodies} bodies")
    own_energy = "energy" in defaults
    if energy is not None and own_energy:
        params["energy"] = energy
    if own_energy and {**defaults, **params}["energy"] is None:
        raise ValueError(f"family {family!r} needs a target energy")
    q, vel = spec.build(system, **{**defaults, **params})
    if system.dim == 3 and not spec.any_n:
        q, vel = (np.pad(x, ((0, 0), (0, 1))) for x in (q, vel))
    y = system.state(q, vel * system.masses[:, None])
    if energy is not None and not own_energy:
        y = with_energy(system, y, energy)
    return y


def with_energy(system: System, y, energy: float) -> np.ndarray:
    """Rescale the velocities relative to the centre of mass so that H = energy (in an
    external field, where the centre of mass is not free, every velocity)."""
    q, p = system.split(y)
    m = system.masses[:, None]
    v_cm = p.sum(axis=0) / system.masses.sum() if system.translation_invariant \
        else np.zeros(system.dim)
    rel = p / m - v_cm
    k_rel = 0.5 * np.sum(m * rel ** 2)
    k_cm = 0.5 * system.masses.sum() * np.sum(v_cm * v_cm)
    u = system.potential_energy(y)
    room = energy - u - k_cm
    if not room >= 0:
        raise Inaccessible(f"U(q0) = {u:.6g} exceeds the target energy {energy:.6g}")
    if k_rel == 0 and room > 0:
        raise Inaccessible("the start has no relative motion to rescale to the target energy")
    scale = math.sqrt(room / k_rel) if k_rel > 0 else 0.0
    return system.state(q, m * (v_cm + scale * rel))
