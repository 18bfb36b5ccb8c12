"""Mass-weighted pair terms against exact solutions of Newtonian gravity: two-body Kepler
orbits with unequal masses (period from Kepler's third law, energy -G m1 m2 / 2a), and
Lagrange's equilateral relative equilibrium, whose linear stability is Routh's criterion
27 (m1 m2 + m2 m3 + m3 m1) < (m1 + m2 + m3)^2."""
import math

import numpy as np
import pytest
from conftest import (
    assert_forces_are_minus_the_gradient,
    assert_tangent_forces_are_the_derivative,
    spread_state,
)

from survey import integrate
from survey.physics.system import System
from survey.physics.terms import PAIR_NAMES, make_potential

G = 0.7


def kepler(m1, m2, a, e):
    """Two bodies at pericentre of a relative orbit with semi-major axis a and eccentricity
    e, centre of mass at rest at the origin."""
    M = m1 + m2
    r = a * (1 - e)
    v = math.sqrt(G * M * (1 + e) / r)            # vis-viva at pericentre
    q = np.array([[-m2 / M * r, 0.0], [m1 / M * r, 0.0]])
    mu = m1 * m2 / M
    p = np.array([[0.0, -mu * v], [0.0, mu * v]])   # p_1 = -p_2 = reduced mass x relative v
    return q, p


@pytest.mark.parametrize("m1,m2,e", [(1.0, 0.3, 0.0), (1.0, 0.3, 0.6), (2.5, 0.01, 0.3)])
def test_a_kepler_orbit_closes_after_the_period_of_keplers_third_law(m1, m2, e):
    s = System(np.array([m1, m2]), 2, make_potential("gravity", {"G": G}, "pair"))
    a = 1.3
    q, p = kepler(m1, m2, a, e)
    y0 = s.state(q, p)
    assert s.energy(y0) == pytest.approx(-G * m1 * m2 / (2 * a), rel=1e-14)
    period = 2 * math.pi * math.sqrt(a ** 3 / (G * (m1 + m2)))
    out = integrate(s, y0, period, rtol=1e-13, atol=1e-13)
    assert out.status.name == "OK"
    assert np.max(np.abs(out.y - y0)) < 1e-9 * a
    # half a period later the bodies are at apocentre, a (1 + e) apart
    half = integrate(s, y0, period / 2, rtol=1e-13, atol=1e-13)
    qh, _ = s.split(half.y)
    assert np.linalg.norm(qh[1] - qh[0]) == pytest.approx(a * (1 + e), rel=1e-10)


def lagrange(masses, side=1.0):
    """The equilateral relative equilibrium of three gravitating bodies: rotation rate
    Omega^2 = G M / side^3 about the centre of mass."""
    m = np.asarray(masses, dtype=float)
    corners = side / math.sqrt(3) * np.array(
        [[math.cos(a), math.sin(a)] for a in (0.3, 0.3 + 2 * math.pi / 3, 0.3 + 4 * math.pi / 3)])
    q = corners - m @ corners / m.sum()
    omega = math.sqrt(G * m.sum() / side ** 3)
    p = m[:, None] * omega * np.stack([-q[:, 1], q[:, 0]], axis=1)
    return q, p, 2 * math.pi / omega


def gravity(masses):
    return System(np.asarray(masses, dtype=float), 2, make_potential("gravity", {"G": G}, "pair"))


def test_lagranges_triangle_returns_to_itself_after_one_rotation():
    masses = (1.0, 0.001, 0.0001)
    s = gravity(masses)
    q, p, period = lagrange(masses)
    y0 = s.state(q, p)
    out = integrate(s, y0, period, rtol=1e-13, atol=1e-13)
    assert np.max(np.abs(out.y - y0)) < 1e-10
    # not a coincidence of the period: a quarter turn later the triangle has turned by pi/2
    quarter = integrate(s, y0, period / 4, rtol=1e-13, atol=1e-13)
    turned = np.stack([-q[:, 1], q[:, 0]], axis=1)
    assert np.max(np.abs(s.split(quarter.y)[0] - turned)) < 1e-10


@pytest.mark.parametrize("masses,stable", [((1.0, 0.001, 0.0001), True),
                                           ((1.0, 1.0, 1.0), False)])
def test_rouths_criterion_decides_whether_the_lagrange_triangle_survives(masses, stable):
    m = np.array(masses)
    assert (27 * (m[0] * m[1] + m[1] * m[2] + m[2] * m[0]) < m.sum() ** 2) == stable
    s = gravity(masses)
    q, p, period = lagrange(masses)
    y0 = s.state(q, p)
    kick = np.zeros_like(y0)
    kick[s.n // 2 + 2] = 1e-8 * m[1]                # body 1's velocity, by 1e-8
    times = np.linspace(0.0, 20 * period, 201)
    out = integrate(s, y0 + kick, times[-1], t_eval=times, rtol=1e-12, atol=1e-12)
    # the triangle's shape: its side ratios stay within a few kicks of 1 only if the
    # equilibrium is stable (an unstable one leaves by orders of magnitude, or collides)
    q = s.split(out.samples)[0]
    sides = np.stack([np.linalg.norm(q[:, i] - q[:, j], axis=-1)
                      for i, j in ((0, 1), (1, 2), (2, 0))])
    drift = np.nanmax(sides.max(0) / sides.min(0) - 1)
    if stable:
        assert out.status.name == "OK" and drift < 1e-5, drift
    else:
        assert drift > 1e-2, drift


def test_mass_weighted_pair_terms_are_the_masses_times_the_unweighted():
    rng = np.random.default_rng(5)
    m = rng.uniform(0.5, 2.0, 4)
    for name in PAIR_NAMES:
        plain = System(m, 3, make_potential(name, {}, "pair"))
        weighted = System(m, 3, make_potential(name, {}, "pair", mass_weighted=True))
        y = spread_state(plain, rng)
        q, _ = plain.split(y)
        ones = System(np.ones(4), 3, plain.terms)
        single = [System(np.ones(2), 3, plain.terms).potential_energy(
            np.concatenate([q[[i, j]].ravel(), np.zeros(6)]))
            for i in range(4) for j in range(i + 1, 4)]
        weights = [m[i] * m[j] for i in range(4) for j in range(i + 1, 4)]
        assert ones.potential_energy(y) == pytest.approx(sum(single), rel=1e-14)
        assert weighted.potential_energy(y) == pytest.approx(
            sum(w * u for w, u in zip(weights, single)), rel=1e-14)
        assert_forces_are_minus_the_gradient(weighted, y)
        assert_tangent_forces_are_the_derivative(weighted, y, rng)


def test_gravity_is_minus_g_m_m_over_r():
    s = System(np.array([2.0, 3.0]), 2, make_potential("gravity", {"G": G}, "pair"))
    y = s.state([[0.0, 0.0], [0.0, 1.7]], np.zeros((2, 2)))
    assert s.potential_energy(y) == pytest.approx(-G * 6.0 / 1.7, rel=1e-15)


def test_mass_weighting_is_refused_where_it_has_no_meaning():
    with pytest.raises(ValueError, match="applies to pair terms"):
        make_potential("perimetric_power", {}, "triplet", mass_weighted=True)
    with pytest.raises(ValueError, match="true or false"):
        make_potential("power", {}, "pair", mass_weighted=1)
    with pytest.raises(ValueError, match="N >= 3"):
        System(np.ones(2), 2, make_potential("perimetric_power"))
    assert "times m_i m_j" in make_potential("power", {}, "pair", True).describe()
