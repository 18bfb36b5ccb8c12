"""Sums of terms -- pair potentials, the Axilrod-Teller-Muto triple dipole and the paper's
terms mixed: forces and tangent forces against finite differences (N = 3, 4, 7; d = 2, 3;
unequal masses), closed forms derived here, and the conservation laws on LJAT orbits. Each
term alone passes the battery of tests/physics/test_terms.py."""
import math

import numpy as np
import pytest
from conftest import (assert_forces_are_minus_the_gradient,
                      assert_tangent_forces_are_the_derivative, full_rhs, spread_state)

from survey.catalog.status import Status
from survey.numerics.integrate import integrate
from survey.physics.system import System
from survey.physics.terms import make_potential as term

LJ = term("lennard_jones", {}, "pair")
MIXES = {
    "ljat": [LJ, term("axilrod_teller", dict(strength=0.3))],
    # the paper's term need not come first; two triplet terms and a pair
    "colloid": [term("yukawa", {}, "pair"), term("areal_barrier"),
                term("perimetric_yukawa", dict(gamma=0.2))],
}
CASES = [(name, N, d) for name in MIXES for N in (3, 4, 7) for d in (2, 3)]


def make_case(name, N, d, seed):
    rng = np.random.default_rng(seed + 10 * N + d)
    system = System(rng.uniform(0.5, 2.0, N), d, tuple(MIXES[name]))
    return system, spread_state(system, rng)


@pytest.mark.parametrize("name,N,d", CASES)
def test_forces_are_minus_gradient_of_energy(name, N, d):
    assert_forces_are_minus_the_gradient(*make_case(name, N, d, seed=0))


@pytest.mark.parametrize("name,N,d", CASES)
def test_tangent_forces_are_derivative_of_forces(name, N, d):
    assert_tangent_forces_are_the_derivative(*make_case(name, N, d, seed=1),
                                             np.random.default_rng(2))


def test_terms_add_up():
    """A mix's energy and forces are the sums of its terms' (no term is lost or doubled
    whichever comes first)."""
    system, y = make_case("colloid", 4, 3, seed=5)
    parts = [System(system.masses, 3, (t,)) for t in system.terms]
    assert system.potential_energy(y) == pytest.approx(
        sum(p.potential_energy(y) for p in parts), rel=1e-14)
    nq = system.n // 2
    np.testing.assert_allclose(full_rhs(system, y)[nq:],
                               sum(full_rhs(p, y)[nq:] for p in parts), rtol=1e-13)


# ---------------------------------------------------------------- closed forms

def trimer(positions, terms, d=2):
    system = System(np.ones(3), d, tuple(terms))
    q = np.asarray(positions, dtype=float)
    return system, system.state(q, np.zeros_like(q))


def equilateral(r):
    return [[0.0, 0.0], [r, 0.0], [r / 2, r * math.sqrt(3) / 2]]


@pytest.mark.parametrize("r,Z", [(1.0, 1.0), (1.3, 0.25), (0.7, -2.0)])
def test_atm_energy_of_equilateral_and_collinear_triplets(r, Z):
    """Equilateral: all cosines 1/2, U = Z (1 + 3/8) / r^9 = 11 Z / (8 r^9). Collinear,
    equally spaced: cosines 1, 1, -1 and sides r, r, 2r, U = Z (1 - 3) / (2 r^3)^3
    = -Z / (4 r^9)."""
    atm = [term("axilrod_teller", dict(strength=Z))]
    s, y = trimer(equilateral(r), atm)
    assert s.potential_energy(y) == pytest.approx(11 * Z / (8 * r ** 9), rel=1e-14)
    s, y = trimer([[-r, 0.0], [0.0, 0.0], [r, 0.0]], atm)
    assert s.potential_energy(y) == pytest.approx(-Z / (4 * r ** 9), rel=1e-14)
    # in 3-D, rotated out of the plane: the same
    rot = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    s, y = trimer(np.pad(equilateral(r), ((0, 0), (0, 1))) @ rot.T, atm, d=3)
    assert s.potential_energy(y) == pytest.approx(11 * Z / (8 * r ** 9), rel=1e-13)


def test_atm_forces_stay_accurate_near_collinear():
    """A triangle of height 1e-9 gets the forces of the straight line to ~1e-12: on the
    line U = -2 Z / (r12 r23 r13)^3, whose x-gradient is exact; the perpendicular forces
    are of order the height. A chain rule through the angles would lose the digits."""
    Z = 0.7
    x = np.array([-1.0, 0.3, 1.0])
    s, y = trimer(np.stack([x, [0.0, 1e-9, 0.0]], axis=1), [term("axilrod_teller",
                                                                  dict(strength=Z))])
    F = full_rhs(s, y)[6:].reshape(3, 2)
    r12, r23, r13 = x[1] - x[0], x[2] - x[1], x[2] - x[0]
    U = -2 * Z / (r12 * r23 * r13) ** 3
    # dU/dx_i = -3 U sum over the sides touching i of d(log r)/dx_i
    dU = -3 * U * np.array([-1 / r12 - 1 / r13, 1 / r12 - 1 / r23, 1 / r23 + 1 / r13])
    np.testing.assert_allclose(F[:, 0], -dU, rtol=1e-12)
    assert np.all(np.abs(F[:, 1]) < 1e-7 * np.abs(F[:, 0]).max())


def _minimise(f, lo, hi):
    """Golden-section minimum of a unimodal f on [lo, hi]: (x, f(x))."""
    g = (math.sqrt(5) - 1) / 2
    for _ in range(120):
        c, d = hi - g * (hi - lo), lo + g * (hi - lo)
        if f(c) < f(d):
            hi = d
        else:
            lo = c
    x = 0.5 * (lo + hi)
    return x, f(x)


@pytest.mark.parametrize("epsilon,sigma", [(1.0, 1.0), (0.3, 2.5)])
def test_lennard_jones_minimum_is_at_two_to_the_sixth_sigma_with_depth_epsilon(epsilon, sigma):
    """Two bodies (the third 1e4 sigma away): U(r) = 4 eps ((s/r)^12 - (s/r)^6) has
    U'(r) = 0 at r = 2^(1/6) s with U = -eps; found here by minimising survey's energy, and
    the force there vanishes."""
    lj = [term("lennard_jones", dict(epsilon=epsilon, sigma=sigma), "pair")]

    def energy(r):
        s, y = trimer([[0.0, 0.0], [r, 0.0], [0.0, 1e4 * sigma]], lj)
        return s.potential_energy(y)
    r, u = _minimise(energy, 0.9 * sigma, 2.0 * sigma)
    assert r == pytest.approx(2 ** (1 / 6) * sigma, rel=1e-7)
    assert u == pytest.approx(-epsilon, rel=1e-12)
    s, y = trimer([[0.0, 0.0], [2 ** (1 / 6) * sigma, 0.0], [0.0, 1e4 * sigma]], lj)
    assert np.abs(full_rhs(s, y)[6:]).max() < 1e-12 * epsilon / sigma


def test_critical_Z_where_the_linear_ljat_trimer_becomes_lower_than_the_equilateral():
    """Minimise each shape's energy over its size (survey's energies), then bisect on Z.
    Closed forms (eps = sigma = 1): equilateral 3 LJ(r) + 11 Z / (8 r^9), line
    2 LJ(r) + LJ(2r) - Z / (4 r^9). At Z = 0 the equilateral trimer (-3 eps) is far below
    the line (-2.03 eps); the triple dipole raises the first and lowers the second, and they
    cross at Z_c = 1.9225 (the crossover of Halicioglu 1980)."""
    def lowest(shape, Z):
        terms = [LJ, term("axilrod_teller", dict(strength=Z))]
        return _minimise(lambda r: (lambda s, y: s.potential_energy(y))(*trimer(shape(r), terms)),
                         0.9, 1.6)[1]
    line = lambda r: [[-r, 0.0], [0.0, 0.0], [r, 0.0]]
    lj = lambda r: 4 * (r ** -12 - r ** -6)
    r_eq, u_eq = _minimise(lambda r: 3 * lj(r) + 11 * 0.5 / (8 * r ** 9), 0.9, 1.6)
    assert lowest(equilateral, 0.5) == pytest.approx(u_eq, rel=1e-12)
    r_li, u_li = _minimise(lambda r: 2 * lj(r) + lj(2 * r) - 0.5 / (4 * r ** 9), 0.9, 1.6)
    assert lowest(line, 0.5) == pytest.approx(u_li, rel=1e-12)
    assert lowest(equilateral, 0.0) == pytest.approx(-3.0, rel=1e-12)
    lo, hi = 0.0, 3.0
    for _ in range(40):
        Z = 0.5 * (lo + hi)
        lo, hi = (lo, Z) if lowest(line, Z) < lowest(equilateral, Z) else (Z, hi)
    assert 0.5 * (lo + hi) == pytest.approx(1.92252, abs=2e-5)


# ---------------------------------------------------------------- orbits

def ljat(Z=0.4, masses=(1.0, 1.3, 0.8), d=2):
    return System(np.asarray(masses), d, (LJ, term("axilrod_teller", dict(strength=Z))))


@pytest.mark.parametrize("d", [2, 3])
def test_ljat_orbit_conserves_energy_momentum_and_angular_momentum(d):
    """The paper's standard (tests/test_paper.py): relative errors of E and J below 5e-10
    over t = 500 at the default tolerance, momentum to 1e-12 -- here on a bound LJAT trimer
    of unequal masses, about 400 vibrations long."""
    s = ljat(d=d)
    rng = np.random.default_rng(3)
    q = np.array(equilateral(1.12)) + rng.normal(scale=0.05, size=(3, 2))
    q = np.pad(q, ((0, 0), (0, d - 2)))
    v = rng.normal(scale=0.3, size=(3, d))
    v -= (s.masses @ v) / s.masses.sum()
    y0 = s.state(q, v * s.masses[:, None])
    out = integrate(s, y0, 500.0, t_eval=np.linspace(0, 500, 501))
    assert out.status == Status.OK
    ys = out.samples
    assert np.abs(s.energy(ys) / s.energy(y0) - 1).max() < 5e-10
    J, J0 = s.angular_momentum(ys), s.angular_momentum(y0)
    assert np.abs(J - J0).max() < 5e-10 * np.abs(J0).max()
    assert np.abs(s.momentum(ys)).max() < 1e-12
    assert s.moment_of_inertia(ys).max() < 10     # it stayed bound


def test_rotating_equilateral_ljat_trimer_stays_equilateral():
    """At the equilibrium side of the equilateral LJAT trimer, rotating at the speed that
    balances the pull, the triangle stays equilateral with that side (the centrifugal
    stretch makes the rotating side a little longer than the static minimum)."""
    from survey.physics.families import initial_state
    s = ljat(Z=0.4, masses=(1.0, 1.0, 1.0))
    y0 = initial_state(s, "equilateral", side=1.2)
    out = integrate(s, y0, 50.0, t_eval=np.linspace(0, 50, 26))
    u, v, w = s.triangle(out.samples)
    for a, b in ((u, v), (v, w), (w, u)):
        np.testing.assert_allclose(np.linalg.norm(b - a, axis=-1), 1.2, rtol=1e-10)
    J = s.angular_momentum(y0)
    assert J > 0


# ---------------------------------------------------------------- N-body starts

BIPYRAMID = np.array([[1.1 * math.cos(2 * math.pi * k / 5), 1.1 * math.sin(2 * math.pi * k / 5),
                       0.0] for k in range(5)] + [[0.0, 0.0, 0.9], [0.0, 0.0, -0.9]])


def test_equilibrium_finds_the_lj7_pentagonal_bipyramid():
    """From a rough, perturbed bipyramid the descent reaches the LJ7 global minimum,
    U = -16.505384 eps (Wales & Doye 1997), where every force vanishes."""
    from survey.physics.equilibria import forces
    from survey.physics.families import initial_state
    s = System(np.ones(7), 3, (LJ,))
    start = BIPYRAMID + np.random.default_rng(1).normal(scale=0.05, size=(7, 3))
    y = initial_state(s, "equilibrium", positions=start, speed=0.0)
    assert s.potential_energy(y) == pytest.approx(-16.505384, abs=5e-7)
    force, hess = forces(s, s.split(y)[0], hessian=True)
    assert np.abs(force).max() < 1e-12
    w = np.linalg.eigvalsh(hess)
    assert np.all(w[6:] > 1.0) and np.all(np.abs(w[:6]) < 1e-8)   # a minimum; 6 zero modes
    np.testing.assert_allclose(s.centre_of_mass(y), 0.0, atol=1e-14)
    assert np.all(y[21:] == 0.0)


def test_equilibrium_finds_the_centred_hexagon_of_2d_lj7():
    """In the plane the LJ7 ground state is the centred hexagon, U = -12.534867 eps: 12
    bonds near 2^(1/6) sigma, 6 at about sqrt3 times that and 3 at twice it, relaxed."""
    from survey.physics.families import initial_state
    s = System(np.ones(7), 2, (LJ,))
    hexagon = [[0.0, 0.0]] + [[1.1 * math.cos(k * math.pi / 3), 1.1 * math.sin(k * math.pi / 3)]
                              for k in range(6)]
    y = initial_state(s, "equilibrium", positions=hexagon, speed=0.0)
    assert s.potential_energy(y) == pytest.approx(-12.534867, abs=5e-7)


@pytest.mark.parametrize("Z,lower", [(1.0, "equilateral"), (2.5, "linear")])
def test_equilibrium_trimers_and_which_is_lower(Z, lower):
    """The descent from a triangle and from a line reaches the two trimers at the sizes
    that minimise the closed forms of test_critical_Z (the line stays a line), and the
    lower one is on the side of Z_c = 1.9225 the closed forms say."""
    from survey.physics.families import initial_state
    s = ljat(Z=Z, masses=(1.0, 1.0, 1.0))
    tri = initial_state(s, "equilibrium", positions=[[0, 0], [1.2, 0], [0.5, 1.0]], speed=0)
    line = initial_state(s, "equilibrium", positions=[[-1.2, 0], [0, 0], [1.1, 0]], speed=0)
    lj = lambda r: 4 * (r ** -12 - r ** -6)
    u_tri = _minimise(lambda r: 3 * lj(r) + 11 * Z / (8 * r ** 9), 0.9, 1.6)[1]
    u_line = _minimise(lambda r: 2 * lj(r) + lj(2 * r) - Z / (4 * r ** 9), 0.9, 1.6)[1]
    assert s.potential_energy(tri) == pytest.approx(u_tri, rel=1e-12)
    assert s.potential_energy(line) == pytest.approx(u_line, rel=1e-12)
    assert np.abs(s.split(line)[0][:, 1]).max() < 1e-12
    assert (s.potential_energy(tri) < s.potential_energy(line)) == (lower == "equilateral")


@pytest.mark.parametrize("N,d", [(4, 2), (7, 3)])
def test_microcanonical_start_is_on_the_shell_with_the_chosen_momenta(N, d):
    from survey.physics.families import initial_state
    s = System(np.linspace(0.7, 1.6, N), d, (LJ, term("axilrod_teller", dict(strength=0.2))))
    pos = BIPYRAMID[:N, :d] * 1.05
    y = initial_state(s, "microcanonical", positions=pos, energy=-1.0, angular_momentum=0.3,
                      seed=4)
    assert s.energy(y) == pytest.approx(-1.0, abs=1e-13)
    np.testing.assert_allclose(s.momentum(y), 0.0, atol=1e-14)
    np.testing.assert_allclose(s.angular_momentum(y), 0.3 if d == 2 else [0, 0, 0.3],
                               atol=1e-14)
    again = initial_state(s, "microcanonical", positions=pos, energy=-1.0,
                          angular_momentum=0.3, seed=4)
    other = initial_state(s, "microcanonical", positions=pos, energy=-1.0,
                          angular_momentum=0.3, seed=5)
    assert np.array_equal(y, again) and not np.allclose(y, other)


def test_n_body_families_fail_clearly_on_degenerate_or_misshaped_starts():
    from survey.catalog.errors import Inaccessible
    from survey.physics.families import initial_state
    s = System(np.ones(4), 2, (LJ,))
    square = [[0, 0], [1.1, 0], [1.1, 1.1], [0, 1.1]]
    with pytest.raises(ValueError, match="two bodies start at the same place"):
        initial_state(s, "explicit", positions=[[0, 0], [1, 0], [1, 0], [0, 1]])
    with pytest.raises(ValueError, match="4 rows"):
        initial_state(s, "equilibrium", positions=[[0, 0], [1, 0], [0, 1]])
    with pytest.raises(ValueError, match="positions is required"):
        initial_state(s, "explicit")
    with pytest.raises(ValueError, match="needs a target energy"):
        initial_state(s, "microcanonical", positions=square)
    with pytest.raises(Inaccessible, match="exceeds the target energy"):
        initial_state(s, "microcanonical", positions=square, energy=-10.0, displacement=0.0)
    y = initial_state(s, "explicit", positions=square, velocities=[[0, 1]] * 4)
    np.testing.assert_array_equal(s.split(y)[1], [[0, 1]] * 4)


# ---------------------------------------------------------------- surveys

LJAT_SURVEY = """
[survey]
name = "ljat"
output = "{out}"
[system]
interactions = [{{kind = "pair", potential = "lennard_jones", params = {{epsilon = 1.0, sigma = 1.0}}}},
                {{kind = "triplet", potential = "axilrod_teller", params = {{strength = [0.5, 2.5]}}}}]
[initial]
family = "equilibrium"
positions = [[0.0, 0.0], [1.2, 0.0], [0.5, 1.0]]
seed = 2
energy = [-1.8, -1.2]
[integration]
t_final = 20.0
[indicators]
history_points = 8
[section]
coordinate = "area"
max_crossings = 10
[dask]
workers = 1
"""


def test_a_survey_over_the_atm_strength_and_energy(tmp_path):
    """The (Z, energy) map of the LJAT trimer through the whole pipeline: the ATM strength
    is an archive dimension named after its term, and each cell's start lies on its energy
    shell under its own Z (not under the other's), so each cell ran its own system."""
    from survey.pipeline.sweep import run, verify
    cfg = tmp_path / "ljat.toml"
    cfg.write_text(LJAT_SURVEY.format(out=tmp_path / "ljat.nc"))
    ds = run(cfg)
    assert ds["status"].dims == ("axilrod_teller_strength", "energy")
    assert "triplet term axilrod_teller" in ds["axilrod_teller_strength"].attrs["long_name"]
    assert (ds["status"].values == Status.OK).all()
    for i, Z in enumerate(ds["axilrod_teller_strength"].values):
        for j, E in enumerate(ds["energy"].values):
            y0 = ds["initial_state"].values[i, j]
            assert ljat(Z, (1.0, 1.0, 1.0)).energy(y0) == pytest.approx(E, abs=1e-12)
            assert abs(ljat(2.5 if Z < 1 else 0.5, (1.0, 1.0, 1.0)).energy(y0) - E) > 1e-3
    ok, lines = verify(tmp_path / "ljat.nc", cells=4)
    assert ok, lines


def test_section_start_of_a_mixture_lies_on_its_energy_shell():
    """The `section` family solves the reduced Hamiltonian; for a sum of terms its potential
    is that of the triangle of the given shape (all terms are invariant under rotations),
    so the start lands on the target shell with the target angular momentum."""
    from survey.physics.families import initial_state
    from survey.physics.jacobi import reduced
    s = ljat(Z=0.5, masses=(1.0, 1.3, 0.8))
    y = initial_state(s, "section", energy=-1.5, angular_momentum=0.2, sigma=1.2, eta=1.0,
                      p_sigma=0.1, p_eta=0.0)
    assert s.energy(y) == pytest.approx(-1.5, abs=1e-13)
    assert s.angular_momentum(y) == pytest.approx(0.2, abs=1e-14)
    r = reduced(s, y)
    assert r.sigma == pytest.approx(1.2) and r.phi == pytest.approx(math.pi / 2)
