"""Batches of three bodies in the plane under one perimetric or areal term integrate the
relative motion alone (integrate.Frame: bodies 0 and 1 in each orbit's centre-of-mass
frame, the third rebuilt): checked against the full integration of the same orbits (the
general path of sums of terms, which integrates all 12 components; its bits are the full
planar path's, tests/physics/test_system.py) on starts whose centre of mass is off the
origin and moving, with unequal masses -- states, samples, section crossings, growth of
the tangent vectors, MEGNO -- and the cases that must run full."""
import numpy as np
import pytest

from survey.bench import GeneralPath as Full
from survey.numerics.events import Event, Linear
from survey.numerics.indicators import deviation_vectors
from survey.numerics.integrate import Frame, flow_jacobian, integrate_batch
from survey.numerics.sections import section_event
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.physics.terms import make_potential


def moving(system, starts):
    """The starts with their centre of mass moved off the origin and set moving."""
    out = starts.copy()
    m = system.masses
    out[:, 0:6:2] += 0.7
    out[:, 1:6:2] -= 0.3
    out[:, 6:12:2] += m * 0.05
    out[:, 7:12:2] -= m * 0.02
    return out


@pytest.mark.parametrize("potential, masses, family", [
    ("perimetric_power", (1.0, 1.0, 1.0), "equilateral"),
    ("perimetric_power", (1.0, 1.3, 0.8), "sides"),
    ("areal_power", (1.0, 1.0, 1.0), "equilateral")])
def test_the_relative_motion_gives_the_full_integrations_orbits(potential, masses, family):
    system = System(np.array(masses), 2, (make_potential(potential),))
    full = Full(system.masses, system.dim, system.terms)
    params = {"delta": [0.5, 2.0, 3.0]} if family == "equilateral" else {}
    if family == "equilateral":
        starts = np.array([initial_state(system, family, delta=d) for d in params["delta"]])
    else:
        starts = np.array([initial_state(system, family)])
    starts = moving(system, starts)
    w = np.array([deviation_vectors(system, y, 1, seed=3)[0] for y in starts])
    # the Jacobi surfaces, moved with the centre of mass: written anew for the reduced state
    events = (section_event(system), section_event(system, "sigma", 1.0, 0),
              section_event(system, "p_eta", 0.0, -1))
    assert Frame.of(system, starts, w[:, None], events) is not None
    assert Frame.of(full, starts, w[:, None], ()) is None
    T = 30.0
    kw = dict(tangents=w[:, None], megno=True, t_eval=np.linspace(0.0, T, 7),
              sample_tangents=True, t_fine=np.linspace(0.05, T - 0.05, 40), events=events)
    got, want = integrate_batch(system, starts, T, **kw), integrate_batch(full, starts, T, **kw)
    for a, b in zip(got, want):
        assert a.ok and b.ok
        assert a.n_crossings == b.n_crossings > 0
        assert np.array_equal(a.crossings.index, b.crossings.index)
        assert np.allclose(a.crossings.t, b.crossings.t, rtol=0, atol=1e-8)
        assert np.abs(a.crossings.y - b.crossings.y).max() <= 1e-8 * np.abs(b.y).max()
        scale = np.abs(b.y).max()          # (the chaotic "sides" orbit: 1e-9 of it)
        assert np.abs(a.y - b.y).max() <= 1e-8 * scale
        assert np.abs(a.fine - b.fine).max() <= 1e-8 * scale
        orbit = slice(0, 12)
        assert np.abs(a.samples[:, orbit] - b.samples[:, orbit]).max() <= 1e-8 * scale
        assert np.allclose(a.log_growth, b.log_growth, rtol=1e-7, atol=1e-9)
        assert np.allclose(a.sample_log_growth, b.sample_log_growth, rtol=1e-7, atol=1e-9)
        # MEGNO's integrals are trapezoid sums over the step ends, which differ
        assert np.allclose(a.megno_sums, b.megno_sums, rtol=1e-3)
        # the tangent vectors are renormalised at other step ends: the same directions
        u, v = a.tangents[0], b.tangents[0]
        assert abs(u @ v / np.linalg.norm(u) / np.linalg.norm(v) - 1.0) < 1e-9
        # and the third body is rebuilt with no centre-of-mass part in the deviations
        dq = u[:6].reshape(3, 2)
        assert np.abs(system.masses @ dq).max() <= 1e-13 * np.abs(dq).max()


def test_what_the_relative_motion_cannot_hold_runs_full():
    """A tangent vector with a centre-of-mass part (its motion is not integrated), events
    that are not forms the centre of mass leaves alone (a side combination, a hyperplane
    through body 0's place), other systems: the full path, bit for bit the general
    path's."""
    system = System.create()
    full = Full(system.masses, system.dim, system.terms)
    y0 = initial_state(system, "equilateral", delta=1.0)
    drift = np.zeros(12)
    drift[0] = drift[2] = drift[4] = 1.0              # every body moved the same way
    events = (section_event(system),)
    assert Frame.of(system, y0[None], drift[None, None], ()) is None
    none = np.zeros((1, 0, 12))
    assert Frame.of(system, y0[None], none, events) is not None
    sides = (section_event(system, "perimeter", 3.0),)
    absolute = (section_event(system, "linear", 0.0, coefficients=np.eye(12)[0]),)
    guarded = (Event(Linear(np.eye(12)[0] - np.eye(12)[2]), guard=sides[0].function),)
    for events in (sides, absolute, guarded):
        assert Frame.of(system, y0[None], none, events) is None
    four = System.create(masses=(1.0,) * 4)
    y4 = np.zeros((1, 16))
    assert Frame.of(four, y4, np.zeros((1, 0, 16)), ()) is None
    for kw in (dict(tangents=drift[None, None]), dict(events=sides), dict(events=absolute)):
        a = integrate_batch(system, y0[None], 20.0, **kw)[0]
        b = integrate_batch(full, y0[None], 20.0, **kw)[0]
        assert np.array_equal(a.y, b.y) and a.n_steps == b.n_steps


def test_the_flows_jacobian_from_the_relative_motion_is_the_full_ones():
    """A periodic orbit's monodromy from 8 tangent vectors of the relative motion and the 4
    centre-of-mass directions carried exactly (a translation stays, a boost moves): the
    general path's 12 tangent vectors give the same matrix, and it is symplectic --
    unequal masses, the centre of mass moving, backwards in time too."""
    system = System(np.array((1.0, 1.3, 0.8)), 2, (make_potential("perimetric_power"),))
    full = Full(system.masses, system.dim, system.terms)
    y0 = moving(system, initial_state(system, "sides")[None])[0]
    omega = np.block([[np.zeros((6, 6)), np.eye(6)], [-np.eye(6), np.zeros((6, 6))]])
    for T in (2.5, -1.5):
        kw = dict(rtol=1e-12, atol=1e-12, control_tangents=True)
        out, J = flow_jacobian(system, y0, T, **kw)
        ref, K = flow_jacobian(full, y0, T, **kw)
        assert out.tangents.shape == (8, 12) and ref.tangents.shape == (12, 12)
        assert np.abs(out.y - ref.y).max() <= 1e-10 * np.abs(ref.y).max()
        assert np.abs(J - K).max() <= 1e-9 * np.abs(K).max()
        assert np.abs(J.T @ omega @ J - omega).max() <= 1e-9 * np.abs(J).max() ** 2
