"""DOP853 kernel: accuracy, events, dense output, tangent flow and typed outcomes."""
import math

import numpy as np
import pytest

from survey.catalog.status import Status
from survey.numerics.events import Area, Event, Linear, Sides
from survey.numerics.integrate import integrate
from survey.physics.families import initial_state
from survey.physics.geometry import perimeter
from survey.physics.system import System

OMEGA = math.sqrt(8.0)   # u = -w = (-r, 0), v = 0, U = P^2/2: P = 4|r|, r'' = -8 r
R, T_STAR = 1.0, 0.3     # r(t) = R cos(OMEGA (t - T_STAR))


def harmonic_state(system, t_star=T_STAR):
    r0 = R * math.cos(-OMEGA * t_star)
    rdot0 = R * OMEGA * math.sin(OMEGA * t_star)
    return system.state([[-r0, 0], [0, 0], [r0, 0]], [[-rdot0, 0], [0, 0], [rdot0, 0]])


@pytest.fixture(scope="module")
def harmonic():
    system = System.create()
    return system, harmonic_state(system)


def r_exact(t, t_star=T_STAR):
    return R * np.cos(OMEGA * (np.asarray(t) - t_star))


def r_event(level, **kw):
    """g = r - level, with r = -u_x."""
    c = np.zeros(12)
    c[0] = -1.0
    return Event(Linear(c, -level), **kw)


def crossing_times(level, t_final, t_star=T_STAR):
    """Exact times in (0, t_final] where r(t) = level."""
    a = math.acos(level / R) / OMEGA
    k = np.arange(-2, int(t_final * OMEGA / (2 * math.pi)) + 3)
    t = np.sort(np.concatenate([t_star + a + 2 * math.pi * k / OMEGA,
                                t_star - a + 2 * math.pi * k / OMEGA]))
    return t[(t > 0) & (t <= t_final)]


def test_dense_output_matches_exact_solution(harmonic):
    system, y0 = harmonic
    t = np.linspace(0, 20, 2001)
    out = integrate(system, y0, 20.0, t_eval=t)
    assert out.status == Status.OK and out.t == 20.0
    np.testing.assert_allclose(-out.samples[:, 0], r_exact(t), atol=2e-11)
    np.testing.assert_allclose(out.samples[:, [1, 2, 3, 5]], 0.0, atol=1e-13)
    np.testing.assert_array_equal(out.samples[:, 4], -out.samples[:, 0])


def test_event_times_match_exact_crossings(harmonic):
    system, y0 = harmonic
    out = integrate(system, y0, 20.0, events=[r_event(0.5)])
    exact = crossing_times(0.5, 20.0)
    assert out.n_crossings == exact.size > 10
    np.testing.assert_allclose(out.crossings.t, exact, atol=1e-10, rtol=0)
    np.testing.assert_allclose(-out.crossings.y[:, 0], 0.5, atol=1e-12)


def test_two_crossings_inside_one_step_are_both_found(harmonic):
    """Steps are capped at 0.06 (the controller would take ~0.077); the turning point r = R
    is at t = 0.33 and the level R(1 - 2e-4) is crossed at 0.33 -+ 0.007. Scanning only the
    steps' end points sees neither crossing -- so both lie inside one step; the default scan
    of sub-intervals finds both, to 1e-10."""
    system = harmonic[0]
    y0 = harmonic_state(system, t_star=0.33)
    level = R * (1 - 2e-4)
    kw = dict(first_step=0.06, max_step=0.06, events=[r_event(level)])
    ends_only = integrate(system, y0, 0.6, event_substeps=1, **kw)
    assert ends_only.n_crossings == 0
    out = integrate(system, y0, 0.6, **kw)
    exact = crossing_times(level, 0.6, t_star=0.33)
    assert exact.size == 2 and 0.30 < exact[0] < exact[1] < 0.36
    np.testing.assert_allclose(out.crossings.t, exact, atol=1e-10, rtol=0)


def test_direction_guard_and_terminal(harmonic):
    system, y0 = harmonic
    exact = crossing_times(0.5, 20.0)
    rising = exact[np.sin(OMEGA * (exact - T_STAR)) < 0]      # r increasing
    up = integrate(system, y0, 20.0, events=[r_event(0.5, direction=+1)])
    np.testing.assert_allclose(up.crossings.t, rising, atol=1e-10)
    c = np.zeros(12)
    c[6] = -1.0                                               # guard: dr/dt = -p_u,x > 0
    guarded = integrate(system, y0, 20.0, events=[r_event(0.5, guard=Linear(c))])
    np.testing.assert_allclose(guarded.crossings.t, rising, atol=1e-10)
    stop = integrate(system, y0, 20.0, events=[r_event(0.5, terminal=True)],
                     t_eval=np.linspace(0, 20, 101))
    assert stop.status == Status.EVENT and stop.t == pytest.approx(exact[0], abs=1e-10)
    assert -stop.y[0] == pytest.approx(0.5, abs=1e-12)
    later = stop.t_eval > stop.t
    assert np.all(np.isnan(stop.samples[later])) and not np.any(np.isnan(stop.samples[~later]))


def test_several_events_are_merged_in_time_order(harmonic):
    system, y0 = harmonic
    events = [r_event(0.5), r_event(-0.25), Event(Sides(offset=-3.0))]   # P = 4|r| = 3
    out = integrate(system, y0, 10.0, events=events)
    assert np.all(np.diff(out.crossings.t) > 0)
    for k, level in enumerate([0.5, -0.25]):
        np.testing.assert_allclose(out.crossings.t[out.crossings.index == k],
                                   crossing_times(level, 10.0), atol=1e-10)
    t_p = out.crossings.t[out.crossings.index == 2]
    np.testing.assert_allclose(np.abs(r_exact(t_p)), 0.75, atol=1e-12)
    capped = integrate(system, y0, 10.0, events=events, max_events=5)
    assert capped.n_crossings == out.n_crossings and capped.crossings.t.size == 5
    np.testing.assert_array_equal(capped.crossings.t, out.crossings.t[:5])


def test_crossing_states_lie_on_the_surface_and_energy_shell(paper_system):
    """Perimeter = 9 on the paper's regular orbit, and the 3-D area |A| = 3 (planar orbit
    embedded in 3-D)."""
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    out = integrate(paper_system, y0, 200.0, events=[Event(Sides(offset=-9.0))])
    P = perimeter(*paper_system.triangle(out.crossings.y))
    assert out.n_crossings > 50
    np.testing.assert_allclose(P, 9.0, atol=1e-12)
    E = paper_system.energy(out.crossings.y)
    np.testing.assert_allclose(E / paper_system.energy(y0), 1.0, atol=1e-12)
    system3 = System.create(dim=3)
    y3 = initial_state(system3, "equilateral", delta=3.0)
    out3 = integrate(system3, y3, 200.0, events=[Event(Area(offset=-3.0))])
    assert out3.n_crossings > 50
    from survey.physics.geometry import area_magnitude
    np.testing.assert_allclose(area_magnitude(*system3.triangle(out3.crossings.y)), 3.0,
                               atol=1e-12)


def test_backward_integration_returns_to_the_start(paper_system):
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    fwd = integrate(paper_system, y0, 50.0)
    back = integrate(paper_system, fwd.y, (50.0, 0.0))
    assert back.status == Status.OK and back.t == 0.0
    np.testing.assert_allclose(back.y, y0, atol=1e-9)


def test_tangent_vector_is_the_derivative_of_the_flow(paper_system):
    """w(t) from the variational equations equals (phi_t(y0 + eps w0) - phi_t(y0 - eps w0))
    / (2 eps) -- end to end, including the renormalisation bookkeeping."""
    y0 = initial_state(paper_system, "sides")
    w0 = np.random.default_rng(0).normal(size=12)
    w0 /= np.linalg.norm(w0)
    out = integrate(paper_system, y0, 5.0, tangents=w0, renorm_interval=0.5, rtol=1e-13,
                    atol=1e-13)
    eps = 1e-6
    plus = integrate(paper_system, y0 + eps * w0, 5.0, rtol=1e-13, atol=1e-13).y
    minus = integrate(paper_system, y0 - eps * w0, 5.0, rtol=1e-13, atol=1e-13).y
    fd = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(out.deviations[0], fd, rtol=1e-6, atol=1e-7 * np.abs(fd).max())
    assert np.linalg.norm(out.tangents[0]) < 1.2 < np.linalg.norm(fd)     # renormalised


def test_homothetic_collapse_returns_collision_at_the_free_fall_time():
    """Equilateral triangle at rest under the attractive U = -1/P (exponent -1) falls into a
    triple collision: r'' = -mu / r^2 with mu = 1/(9 sqrt3), t_ff = pi/2 sqrt(r0^3 / (2 mu))."""
    system = System.create(potential="perimetric_power", coupling=1.0, exponent=-1.0)
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), v_rot=1e-300)
    y0[6:] = 0.0
    mu = 1 / (9 * math.sqrt(3))
    t_ff = math.pi / 2 * math.sqrt(1.0 / (2 * mu))
    out = integrate(system, y0, 10.0)
    assert out.status == Status.COLLISION
    assert out.t == pytest.approx(t_ff, abs=1e-6)
    assert out.n_steps < 100_000


def test_step_limit_and_nonfinite_outcomes(paper_system):
    y0 = initial_state(paper_system, "sides")
    out = integrate(paper_system, y0, 100.0, max_steps=10)
    assert out.status == Status.STEP_LIMIT and 0 < out.t < 100.0
    bad = y0.copy()
    bad[3] = np.nan
    assert integrate(paper_system, bad, 1.0).status == Status.NONFINITE
    areal = System.create(potential="areal_barrier")   # collinear start: U' = -alpha/0
    line = areal.state([[-1, 0], [0, 0], [1, 0]], [[0, 1], [0, 0], [0, -1]])
    out = integrate(areal, line, 1.0)
    assert out.status == Status.NONFINITE and out.t == 0.0
