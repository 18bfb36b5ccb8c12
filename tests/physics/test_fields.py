"""One body in an external field (a two-degree-of-freedom Hamiltonian such as Henon-Heiles):
its starts on the section x = 0 at an energy, the section as an event, the torus analysis
of its coordinates -- each checked against what is known without survey: the energy, the
section's analytic boundary, a separable oscillator's frequencies."""
import math

import numpy as np
import pytest

from survey.catalog.errors import Inaccessible
from survey.numerics.integrate import integrate
from survey.numerics.sections import section_event
from survey.numerics.torus import frequency_analysis
from survey.physics.families import initial_state, with_energy
from survey.physics.system import System
from survey.physics.terms import make_expression

HENON_HEILES = "(x**2 + y**2)/2 + x**2*y - y**3/3"


def field(formula=HENON_HEILES, mass=1.0, **params):
    return System(np.array([mass]), 2, make_expression("external", formula, params))


@pytest.mark.parametrize("mass", [1.0, 2.5])
def test_a_start_on_the_section_has_the_energy_and_the_crossing_direction(mass):
    system = field(mass=mass)
    for direction in (1, -1):
        y = initial_state(system, "field_section", energy=0.125, y=0.2, p_y=-0.1,
                          direction=direction)
        assert system.energy(y) == pytest.approx(0.125, rel=1e-14)
        assert y[0] == 0.0 and y[1] == 0.2 and y[3] == -0.1
        assert np.sign(y[2]) == direction
    with pytest.raises(Inaccessible, match="no real p_x"):
        initial_state(system, "field_section", energy=0.125, y=0.2, p_y=0.9)


def test_section_samples_are_uniform_on_the_reachable_region():
    """At E = 1/8 the line x = 0 is reached where y^2/2 - y^3/3 < 1/8 (roots of the cubic,
    found by numpy here); the samples fill that region of (y, p_y) uniformly: their mean of
    y is the region's centroid, computed by quadrature."""
    system, energy = field(), 0.125
    roots = np.sort(np.roots([-1 / 3, 0.5, 0.0, -energy]).real)
    lo, hi = roots[0], roots[1]
    ys = np.array([initial_state(system, "field_section_sample", energy=energy, seed=s)
                   for s in range(2000)])
    assert np.allclose(system.energy(ys), energy, rtol=1e-13)
    assert np.all(ys[:, 0] == 0.0) and np.all(ys[:, 2] > 0)
    assert lo - 1e-9 <= ys[:, 1].min() and ys[:, 1].max() <= hi + 1e-9
    grid = np.linspace(lo, hi, 20001)
    width = np.sqrt(np.maximum(2 * (energy - grid ** 2 / 2 + grid ** 3 / 3), 0.0))
    centroid = np.trapezoid(grid * width, grid) / np.trapezoid(width, grid)
    sd = ys[:, 1].std() / math.sqrt(len(ys))
    assert abs(ys[:, 1].mean() - centroid) < 4 * sd
    again = initial_state(system, "field_section_sample", energy=energy, seed=7)
    np.testing.assert_array_equal(again, ys[7])


def test_an_open_shell_asks_for_bounds():
    system = field()
    with pytest.raises(ValueError, match="give y_min and y_max"):
        initial_state(system, "field_section_sample", energy=0.2, seed=0)
    y = initial_state(system, "field_section_sample", energy=0.2, seed=0, y_min=-0.5,
                      y_max=0.9)
    assert -0.5 <= y[1] <= 0.9 and system.energy(y) == pytest.approx(0.2, rel=1e-13)


def test_a_section_family_needs_one_body_in_a_field():
    free = System.create()
    with pytest.raises(ValueError, match="one body in the plane in an external field"):
        initial_state(free, "field_section", energy=1.0)


def test_with_energy_in_a_field_rescales_every_velocity():
    """No centre of mass is free in a field: a lone body's velocity is what is rescaled."""
    system = field()
    y = with_energy(system, np.array([0.1, -0.2, 0.3, 0.4]), 0.1)
    assert system.energy(y) == pytest.approx(0.1, rel=1e-14)
    assert y[2] / y[3] == pytest.approx(0.75, rel=1e-14)


def test_the_section_x_is_crossed_at_x_zero_upwards():
    system = field()
    y0 = initial_state(system, "field_section", energy=0.125, y=0.1, p_y=0.1)
    event = section_event(system, "x", 0.0, 1, max_crossings=50)
    out = integrate(system, y0, 200.0, rtol=1e-12, atol=1e-12, events=[event])
    assert out.ok and out.n_crossings >= 20
    ys = out.crossings.y
    assert np.abs(ys[:, 0]).max() < 1e-12
    assert ys[:, 2].min() > 0
    assert np.allclose(system.energy(ys[:, :4]), 0.125, rtol=1e-9)


def test_the_frequencies_of_a_separable_field_are_its_oscillators():
    """V = (x^2 + w^2 y^2)/2 is two uncoupled oscillators: frequencies 1/(2 pi) and
    w/(2 pi), found by the torus analysis of x and y."""
    w = 1.5
    system = field("(x**2 + w**2*y**2)/2", w=w)
    y0 = np.array([0.3, 0.2, 0.1, 0.25])
    dt = 0.1
    times = np.arange(4096) * dt
    out = integrate(system, y0, times[-1], rtol=1e-12, atol=1e-12, t_eval=times)
    nu = frequency_analysis(system, out.samples, dt)
    found = np.sort(nu.frequency[np.isfinite(nu.frequency)])
    np.testing.assert_allclose(found, [1 / (2 * np.pi), w / (2 * np.pi)], rtol=1e-7)
