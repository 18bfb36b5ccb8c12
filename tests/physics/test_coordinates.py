"""Reduced Jacobi coordinates, surfaces of section and energy-shell initial conditions."""
import math

import numpy as np
import pytest

from survey.catalog.errors import Inaccessible
from survey.numerics.integrate import integrate
from survey.numerics.sections import section_event
from survey.physics.families import initial_state
from survey.physics.geometry import area, inequities, perimeter, sides
from survey.physics.jacobi import jacobi, reduced, reduced_energy, to_cartesian
from survey.physics.system import System


def random_states(system, count, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(count, system.n))


@pytest.mark.parametrize("potential", ["perimetric_power", "areal_barrier", "perimetric_yukawa"])
def test_round_trip_and_reduced_hamiltonian(potential):
    system = System.create(masses=(1.0, 2.3, 0.6), potential=potential)
    y = random_states(system, 200)
    r = reduced(system, y)
    centre, momentum = system.centre_of_mass(y), system.momentum(y)
    back = to_cartesian(system, r, centre, momentum)
    np.testing.assert_allclose(back, y, atol=1e-12 * np.abs(y).max())
    # reduced H equals Cartesian H in the centre-of-mass frame
    com = to_cartesian(system, r)
    np.testing.assert_allclose(reduced_energy(system, r), system.energy(com), rtol=1e-12)
    np.testing.assert_allclose(system.momentum(com), 0, atol=1e-13)
    # J = p_theta is the angular momentum about the centre of mass
    np.testing.assert_allclose(r.J, system.angular_momentum(com), rtol=1e-12, atol=1e-13)


def test_area_and_sides_in_reduced_coordinates():
    system = System.create(masses=(1.0, 2.3, 0.6))
    y = random_states(system, 100, seed=1)
    r = reduced(system, y)
    np.testing.assert_allclose(area(*system.triangle(y)), 0.5 * r.sigma * r.eta * np.sin(r.phi),
                               rtol=1e-12)
    np.testing.assert_allclose(sides(*system.triangle(y))[:, 2], r.sigma, rtol=1e-14)
    s, h, ps, ph = jacobi(system, y)
    m = system.masses
    mu1, mu2 = m[0] * m[1] / (m[0] + m[1]), (m[0] + m[1]) * m[2] / m.sum()
    inertia = mu1 * r.sigma ** 2 + mu2 * r.eta ** 2
    np.testing.assert_allclose(inertia, system.moment_of_inertia(y), rtol=1e-12)


@pytest.fixture(scope="module")
def phi_section(paper_system):
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    out = integrate(paper_system, y0, 200.0, events=[section_event(paper_system)])
    return paper_system, y0, out


def test_phi_section_crossings_lie_on_the_surface_and_the_energy_shell(phi_section):
    system, y0, out = phi_section
    assert out.n_crossings > 100
    r = reduced(system, out.crossings.y)
    s, h, _, _ = jacobi(system, out.crossings.y)
    np.testing.assert_allclose(np.sum(s * h, axis=-1) / (r.sigma * r.eta), 0, atol=1e-12)
    np.testing.assert_allclose(r.phi, math.pi / 2, atol=1e-12)
    assert np.all(r.p_phi > 0)                                     # phi increasing
    np.testing.assert_allclose(system.energy(out.crossings.y) / system.energy(y0), 1,
                               atol=1e-11)
    # equal masses: phi = pi/2 is the isosceles set a = b
    a, b, c = np.moveaxis(sides(*system.triangle(out.crossings.y)), -1, 0)
    np.testing.assert_allclose(a, b, atol=1e-11)


def test_crossing_states_are_as_accurate_as_the_integration(phi_section):
    """Dense-output crossing states against integrations that land exactly on the crossing
    time, and crossing times between tolerances: errors scale with the tolerance."""
    system, y0, out = phi_section
    for t_c, y_c in list(zip(out.crossings.t, out.crossings.y))[:40:8]:
        landed = integrate(system, y0, t_c).y
        np.testing.assert_allclose(y_c, landed, atol=2e-11 * np.abs(landed).max())
    ev = [section_event(system)]
    t = {tol: integrate(system, y0, 50.0, events=ev, rtol=tol, atol=tol).crossings.t
         for tol in (1e-9, 1e-11, 1e-13)}
    assert t[1e-9].size == t[1e-11].size == t[1e-13].size
    e9, e11 = np.abs(t[1e-9] - t[1e-13]).max(), np.abs(t[1e-11] - t[1e-13]).max()
    assert e11 < 1e-9 and 10 < e9 / e11 < 1e4


@pytest.mark.parametrize("coordinate,value,measure", [
    ("sigma", 3.0, lambda s, y: reduced(s, y).sigma),
    ("eta", 3.2, lambda s, y: reduced(s, y).eta),
    ("phi", 1.2, lambda s, y: reduced(s, y).phi),
    ("perimeter", 9.0, lambda s, y: perimeter(*s.triangle(y))),
    ("i_a", 3.0, lambda s, y: inequities(*s.triangle(y))[..., 0]),
    ("c", 3.0, lambda s, y: sides(*s.triangle(y))[..., 2]),
    ("area", 3.0, lambda s, y: area(*s.triangle(y))),
    ("p_sigma", 0.0, lambda s, y: reduced(s, y).p_sigma),
])
@pytest.mark.parametrize("direction", [1, -1])
def test_named_surfaces_and_directions(paper_system, coordinate, value, measure, direction):
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    ev = section_event(paper_system, coordinate, value, direction)
    out = integrate(paper_system, y0, 100.0, events=[ev])
    assert out.n_crossings > 5
    np.testing.assert_allclose(measure(paper_system, out.crossings.y), value, atol=1e-11)
    dt = 1e-6     # the coordinate moves in the requested direction through the surface
    after = [integrate(paper_system, y, dt).y for y in out.crossings.y[:5]]
    moved = measure(paper_system, np.array(after)) - value
    assert np.all(np.sign(moved) == direction)


def test_bad_surfaces_are_rejected(paper_system):
    with pytest.raises(ValueError, match="unknown section coordinate"):
        section_event(paper_system, "psi", 1.0)
    with pytest.raises(ValueError, match="only p_sigma = 0"):
        section_event(paper_system, "p_sigma", 1.0)
    with pytest.raises(ValueError, match="three bodies in the plane"):
        section_event(System.create(dim=3), "phi")


def test_section_family_starts_on_the_shell_with_requested_E_and_J(paper_system):
    E, J = 84.45577136594005, 24.401923788646684
    made = 0
    for sigma in np.linspace(2.0, 5.0, 7):
        for p_sigma in np.linspace(-3, 3, 7):
            try:
                y = initial_state(paper_system, "section", energy=E, angular_momentum=J,
                                  sigma=sigma, p_sigma=p_sigma, eta=3.0, p_eta=0.5)
            except Inaccessible:
                continue
            made += 1
            assert paper_system.energy(y) == pytest.approx(E, rel=1e-13)
            assert paper_system.angular_momentum(y) == pytest.approx(J, rel=1e-13)
            r = reduced(paper_system, y)
            assert r.phi == pytest.approx(math.pi / 2, abs=1e-14) and r.p_phi > 0
            assert (r.sigma, r.p_sigma) == pytest.approx((sigma, p_sigma), abs=1e-12)
    assert 5 < made < 49      # part of the grid is inaccessible
    with pytest.raises(Inaccessible):
        initial_state(paper_system, "section", energy=1.0)


def test_energy_target_rescales_relative_velocities(paper_system):
    y = initial_state(paper_system, "sides", energy=50.0)
    assert paper_system.energy(y) == pytest.approx(50.0, rel=1e-14)
    np.testing.assert_allclose(paper_system.momentum(y), 0, atol=1e-14)
    q0 = paper_system.split(initial_state(paper_system, "sides"))[0]
    np.testing.assert_array_equal(paper_system.split(y)[0], q0)
    with pytest.raises(Inaccessible, match="exceeds the target energy"):
        initial_state(paper_system, "sides", energy=10.0)     # U(q0) = 22.445


def test_section_sample_fills_one_shell_in_the_liouville_measure(paper_system):
    """Seeded starts on the section phi = pi/2 at one (E, J): each on the shell and the
    surface, the same bits for the same seed, and together distributed as the section's
    invariant measure d sigma d p_sigma d eta d p_eta restricted to the shell -- the shapes
    with density E - U - J^2/2I (the area of their momentum ellipse; its marginals here
    by quadrature), the momenta uniform in the ellipse."""
    from survey.physics.families import _room
    from survey.physics.jacobi import JacobiMasses
    E, J, n = 84.45577136594005, 24.401923788646684, 240
    ys = np.array([initial_state(paper_system, "section_sample", energy=E,
                                 angular_momentum=J, seed=k) for k in range(n)])
    np.testing.assert_array_equal(ys[7], initial_state(paper_system, "section_sample",
                                                       energy=E, angular_momentum=J, seed=7))
    np.testing.assert_allclose(paper_system.energy(ys), E, rtol=1e-13)
    np.testing.assert_allclose(paper_system.angular_momentum(ys), J, rtol=1e-13)
    r = reduced(paper_system, ys)
    np.testing.assert_allclose(r.phi, math.pi / 2, atol=1e-13)
    assert np.all(r.p_phi > 0)
    # the marginals of sigma and eta against quadrature of the room (Kolmogorov-Smirnov
    # at the 0.1% level: a sampler that ignored the room's weight fails it)
    grid = np.linspace(1e-4, 7.0, 1401)
    room = np.clip(_room(paper_system, E, J, grid[:, None], grid[None, :], math.pi / 2),
                   0, None)
    for values, density in ((r.sigma, room.sum(axis=1)), (r.eta, room.sum(axis=0))):
        cdf = np.cumsum(density) / density.sum()
        gap = np.abs(np.searchsorted(np.sort(values), grid, side="right") / n - cdf).max()
        assert gap < 1.95 / math.sqrt(n)
    # the momenta: uniform in the ellipse p_sigma^2/2mu1 + p_eta^2/2mu2 <= room, so the
    # share of the room in p_sigma has mean 1/4 (the same for p_eta; p_phi takes the rest)
    m = JacobiMasses.of(paper_system)
    left = _room(paper_system, E, J, r.sigma, r.eta, math.pi / 2)
    share = r.p_sigma ** 2 / (2 * m.mu1) / left
    assert abs(share.mean() - 0.25) < 4 * 0.25 / math.sqrt(n)     # its variance: 1/16
    assert np.all(share + r.p_eta ** 2 / (2 * m.mu2) / left <= 1 + 1e-12)


@pytest.mark.parametrize("potential", ["areal_power", "areal_barrier"])
def test_section_sample_needs_bounds_where_the_shell_has_none(potential):
    """An areal potential does not confine: long thin triangles of any size reach the
    shell. The sampler says so, and samples the part a box bounds."""
    system = System.create(potential=potential)
    E, J = 10.0, 1.0
    with pytest.raises(ValueError, match="unbounded.*give sigma_max and eta_max"):
        initial_state(system, "section_sample", energy=E, angular_momentum=J)
    y = initial_state(system, "section_sample", energy=E, angular_momentum=J,
                      sigma_max=4.0, eta_max=4.0, seed=3)
    r = reduced(system, y)
    assert system.energy(y) == pytest.approx(E, rel=1e-13) and r.sigma <= 4 and r.eta <= 4


def test_section_sample_below_the_shells_minimum_is_inaccessible(paper_system):
    """Under P^2/2 at J = 24.40 the least of U + J^2/2I on the section is 60.157 (a
    spinning pair collision, sigma -> 0; the rotating triangle's 3 J = 73.2 is not the
    least): below it the shell is empty, which makes the cell inaccessible, not the survey
    wrong; just above it the sampler finds the thin region near sigma = 0."""
    J = 24.401923788646684
    with pytest.raises(Inaccessible, match="the shell is empty"):
        initial_state(paper_system, "section_sample", energy=60.0, angular_momentum=J)
    y = initial_state(paper_system, "section_sample", energy=62.0, angular_momentum=J)
    assert reduced(paper_system, y).sigma < 1.0


def test_compiled_passes_give_the_bits_of_the_array_formulas():
    """reduced, moment_of_inertia and the torus analysis' pair-distance sum run as compiled
    loops over states; each gives the bits of its formula on arrays (the formulas the
    archives in results/ were made with), for any leading shape, and a scalar for one
    state."""
    from survey.numerics.torus import observable
    from survey.machine import portable
    from survey.physics.geometry import cross
    from survey.physics.system import centre_of_mass, weighted_sum
    from survey.physics.terms import make_potential

    def same(a, b):
        return np.shape(a) == np.shape(b) and np.asarray(a).tobytes() == np.asarray(b).tobytes()

    system = System.create(masses=(1.0, 2.3, 0.6))
    y = random_states(system, 120, seed=4).reshape(4, 30, -1)
    y[0, 0, 6:] = -0.0                                  # signed zeros: sums start from 0.0
    s, h, ps, ph = jacobi(system, y)
    m = system.masses
    mu1, mu2 = m[0] * m[1] / (m[0] + m[1]), (m[0] + m[1]) * m[2] / m.sum()
    sigma, eta = np.linalg.norm(s, axis=-1), np.linalg.norm(h, axis=-1)
    Ls, Lh = cross(s, ps), cross(h, ph)
    a, b = mu1 * sigma ** 2, mu2 * eta ** 2
    arrays = dict(sigma=sigma, eta=eta, phi=portable.vatan2(cross(s, h), np.sum(s * h, axis=-1)),
                  theta=portable.vatan2(s[..., 1], s[..., 0]),
                  p_sigma=np.sum(ps * s, axis=-1) / sigma, p_eta=np.sum(ph * h, axis=-1) / eta,
                  p_phi=(a * Lh - b * Ls) / (a + b), J=Ls + Lh)
    r = reduced(system, y)
    assert [f for f in r._fields if not same(getattr(r, f), arrays[f])] == []
    one = reduced(system, y[1, 2])
    assert all(isinstance(v, float) and v == arrays[f][1, 2] for f, v in one._asdict().items())
    for sys_ in (system, System(np.array([1.0, 1.3, 0.7, 2.1]), 3,
                                make_potential("perimetric_power"))):
        states = random_states(sys_, 60, seed=5).reshape(3, 20, -1)
        q, _ = sys_.split(states)
        rel = q - centre_of_mass(sys_.masses, q)[..., None, :]
        inertia = weighted_sum(sys_.masses, np.sum(rel * rel, axis=-1)[..., None])[..., 0]
        assert same(sys_.moment_of_inertia(states), inertia)
        assert sys_.moment_of_inertia(states[0, 0]) == inertia[0, 0]
        i, j = np.triu_indices(sys_.n_bodies, 1)
        flat = states.reshape(-1, sys_.n)
        qf = sys_.split(flat)[0]
        assert same(observable("perimeter", sys_, flat),
                    np.linalg.norm(qf[:, i, :] - qf[:, j, :], axis=-1).sum(axis=-1))
