"""Surfaces of section as events: phi = phi0 of the Jacobi vectors (located as the zero of a
smooth quadratic form, no angle wrapping), sigma, eta, their turning points, side
combinations, the area, or a linear form of the state."""
from __future__ import annotations

import math

import numpy as np

from ..machine import portable
from ..physics.jacobi import jacobi_weights, phase_form, position_form
from ..physics.system import System
from .events import Area, Event, Linear, Quadratic, Sides

SIDE_WEIGHTS = {"a": (1, 0, 0), "b": (0, 1, 0), "c": (0, 0, 1), "perimeter": (1, 1, 1),
                "i_a": (-1, 1, 1), "i_b": (1, -1, 1), "i_c": (1, 1, -1)}


REDUCED_SURFACES = ("phi", "sigma", "eta", "p_sigma", "p_eta")


CARTESIAN = ("x", "y", "z")       # the centre of mass's coordinates: surfaces in a field


SURFACES = REDUCED_SURFACES + tuple(SIDE_WEIGHTS) + ("area", "linear") + CARTESIAN


def cartesian_form(system: System, axis: int) -> np.ndarray:
    """The state coefficients of the centre of mass's coordinate `axis` (sum m_i q_i / M)."""
    c = np.zeros(system.n)
    c[axis:system.n // 2:system.dim] = system.masses / system.masses.sum()
    return c


def section_event(system: System, coordinate="phi", value=math.pi / 2, direction=1,
                  triplet=(0, 1, 2), coefficients=None, max_crossings=None) -> Event:
    """The surface `coordinate = value`, crossed with the coordinate increasing (direction
    +1), decreasing (-1) or both (0).

    phi = phi0 is located as the zero of g = sigma eta sin(phi - phi0) = cos(phi0) s x h -
    sin(phi0) s . h (for pi/2: -s . h) where sigma eta cos(phi - phi0) > 0 -- smooth, with no
    angle wrapping. sigma, eta: |s|^2 - value^2, |h|^2 - value^2; p_sigma, p_eta (value 0
    only): s . p_s, h . p_h. a, b, c, perimeter, i_a, i_b, i_c: side combinations of
    `triplet`; area: the signed area (2-D) or |A| (3-D); linear: coefficients . y = value;
    x, y, z: the centre of mass's coordinate (one body's, in an external field: the
    section x = 0, p_x > 0 of Henon & Heiles).
    """
    if direction not in (-1, 0, 1):
        raise ValueError(f"section direction must be -1, 0 or +1, got {direction!r}")
    if coordinate in REDUCED_SURFACES:
        S, H, Ps, Ph = jacobi_weights(system)
        if coordinate == "phi":
            c, s_ = portable.cos(value), portable.sin(value)
            g = c * position_form(system, S, H, skew=True) - s_ * position_form(system, S, H)
            guard = c * position_form(system, S, H) + s_ * position_form(system, S, H, True)
            return Event(Quadratic(g), direction, guard=Quadratic(guard), name="phi")
        if coordinate in ("sigma", "eta"):
            if value <= 0:
                raise ValueError(f"section {coordinate} = {value}: the value must be > 0")
            W = S if coordinate == "sigma" else H
            return Event(Quadratic(position_form(system, W, W), offset=-value ** 2),
                         direction, name=coordinate)
        if value != 0:
            raise ValueError(f"section {coordinate} = {value}: only {coordinate} = 0 "
                             "(turning points) is a surface survey locates")
        W, Wp = (S, Ps) if coordinate == "p_sigma" else (H, Ph)
        return Event(Quadratic(phase_form(system, W, Wp)), direction, name=coordinate)
    if coordinate in SIDE_WEIGHTS:
        return Event(Sides(SIDE_WEIGHTS[coordinate], -value, tuple(triplet)), direction,
                     name=coordinate)
    if coordinate == "area":
        return Event(Area(-value, 1.0, tuple(triplet)), direction, name="area")
    if coordinate == "linear":
        if coefficients is None:
            raise ValueError("section coordinate 'linear' needs coefficients (one per state "
                             "component)")
        return Event(Linear(coefficients, -value), direction, name="linear")
    if coordinate in CARTESIAN:
        axis = CARTESIAN.index(coordinate)
        if axis >= system.dim:
            raise ValueError(f"section coordinate {coordinate!r} needs dim = 3")
        return Event(Linear(cartesian_form(system, axis), -value), direction, name=coordinate)
    raise ValueError(f"unknown section coordinate {coordinate!r}; choose one of "
                     f"{', '.join(SURFACES)}")
