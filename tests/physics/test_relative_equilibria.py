"""Relative equilibria and their stability against closed forms and direct integration:
the paper's rotating triangle and rotating line under P^2/2, Lagrange's triangle under
gravity (Routh's criterion), the Lennard-Jones trimer at rest."""
import json
import math

import numpy as np
import pytest

from conftest import ROUTH
from survey import integrate
from survey.cli import main
from survey.numerics.continuation import equilibrium_family
from survey.physics.equilibria import (SHAPES, relative_equilibria, relative_equilibrium,
                                       shape_configuration, shape_sphere)
from survey.physics.system import System
from survey.physics.terms import make_potential

TRIANGLE = np.array([[1.0, 0.0], [-0.5, math.sqrt(3) / 2], [-0.5, -math.sqrt(3) / 2]])


def distances(q):
    return np.array([np.linalg.norm(q[0] - q[1]), np.linalg.norm(q[0] - q[2]),
                     np.linalg.norm(q[1] - q[2])])


def test_the_rotating_triangle_under_p2_has_the_closed_form_normal_modes():
    """U = P^2/2, unit masses: Omega = 3 at any size, E = J Omega / 2 + (3 s)^2 / 2 with
    J = 3 s^2; shape modes 2 Omega and Omega (1 +- 1/sqrt 2) in the rotating frame, stable."""
    system = System.create()
    rng = np.random.default_rng(3)
    J = 36.0
    eq = relative_equilibrium(system, 1.7 * TRIANGLE + 0.05 * rng.normal(size=(3, 2)),
                              angular_momentum=J)
    s = math.sqrt(J / 3)
    np.testing.assert_allclose(distances(eq.positions), s, rtol=1e-12)
    assert eq.rotation_rate == pytest.approx(3.0, rel=1e-13)
    assert eq.energy == pytest.approx(J * 3 / 2 + (3 * s) ** 2 / 2, rel=1e-13)
    modes = 3.0 * np.array([1 - 2 ** -0.5, 1 + 2 ** -0.5, 2.0]) / (2 * math.pi)
    np.testing.assert_allclose(eq.frequencies, modes, rtol=1e-10)
    assert eq.stable and eq.eigenvalues.size == 6
    # the slow mode has the negative Krein sign: gyroscopically stabilised
    assert list(eq.krein[eq.krein != 0]) == [-1, 1, 1]


def test_a_relative_equilibrium_rotates_rigidly():
    """The found state, integrated: the mutual distances stay what they were to 1e-10."""
    system = System.create()
    eq = relative_equilibrium(system, 2 * TRIANGLE, angular_momentum=36.0)
    out = integrate(system, eq.state(system), (0.0, 10.0), t_eval=np.linspace(0, 10, 41))
    for y in out.samples:
        np.testing.assert_allclose(distances(system.split(y)[0]), distances(eq.positions),
                                   rtol=1e-10)


def test_the_rotating_line_is_unstable_at_the_rate_integration_finds():
    """The collinear solution under P^2/2: Omega^2 = 8, sides a, a, 2a with I = 2 a^2 =
    J / Omega; one real pair +- lambda. A start 1e-10 off it parts from the line like
    e^(lambda t) (its area, linear in the distance from the line): the fitted rate agrees
    with lambda to 2%."""
    system = System.create()
    J = 3.0
    eq = relative_equilibrium(system, [[-1.0, 0.01], [0.0, 0.0], [1.0, 0.0]],
                              angular_momentum=J)
    assert eq.rotation_rate ** 2 == pytest.approx(8.0, rel=1e-12)
    a = math.sqrt(J / eq.rotation_rate / 2)
    np.testing.assert_allclose(np.sort(distances(eq.positions)), [a, a, 2 * a], rtol=1e-12)
    assert not eq.stable
    rate = max(z.real for z in eq.eigenvalues)
    y0 = eq.state(system) + 1e-10 * np.random.default_rng(0).normal(size=system.n)
    times = np.linspace(0.0, 20.0, 401)
    out = integrate(system, y0, (0.0, 20.0), t_eval=times, rtol=1e-13, atol=1e-13)
    q = system.split(out.samples)[0]
    e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
    off = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])     # the area: linear off the line
    window = (off > 1e-8) & (off < 1e-4)
    slope = np.polyfit(times[window], np.log(off[window]), 1)[0]
    assert slope == pytest.approx(rate, rel=0.02)


@pytest.mark.parametrize("masses, stable", [((1.0, 1.0, 1.0), False),
                                            ((1.0, 1e-3, 1e-4), True),
                                            ((1.0, 0.04, 1e-3), False)])
def test_lagranges_triangle_follows_routhss_criterion(masses, stable):
    """Newtonian gravity (G = 1): the equilateral solution exists for any masses with
    Omega^2 r^3 = G M, and is linearly stable iff 27 (m1 m2 + m2 m3 + m3 m1) < M^2."""
    m = np.array(masses)
    system = System(m, 2, make_potential("gravity", {"G": 1.0}, "pair"))
    eq = relative_equilibrium(system, TRIANGLE, rotation_rate=1.0)
    r = distances(eq.positions)
    # the light bodies' distance is pinned by forces ~1e-4 of the rest: to ~1e-12, not eps
    np.testing.assert_allclose(r, r[0], rtol=5e-12)
    assert eq.rotation_rate ** 2 * r[0] ** 3 == pytest.approx(m.sum(), rel=1e-12)
    routh = 27 * (m[0] * m[1] + m[1] * m[2] + m[2] * m[0]) < m.sum() ** 2
    assert routh == stable and eq.stable == stable


def test_the_lennard_jones_trimer_at_rest():
    """Equilibria of U (J = 0): the equilateral triangle at E = -3 eps, stable, with the
    spring-triangle modes sqrt(3k) and, twice, sqrt(3k/2) over 2 pi (k = U''(r_m) = 72 eps /
    r_m^2); and the linear chain, unstable."""
    system = System(np.ones(3), 2, make_potential("lennard_jones",
                                                  {"epsilon": 1.0, "sigma": 1.0}, "pair"))
    tri = relative_equilibrium(system, 0.66 * TRIANGLE, angular_momentum=0.0)
    line = relative_equilibrium(system, [[-1.2, 0.0], [0.0, 0.05], [1.1, 0.0]],
                                angular_momentum=0.0)
    assert tri.energy == pytest.approx(-3.0, rel=1e-13) and tri.stable
    k = 72.0 / 2 ** (1 / 3)
    np.testing.assert_allclose(tri.frequencies, np.sqrt([1.5 * k, 1.5 * k, 3 * k])
                               / (2 * math.pi), rtol=1e-9)
    r = np.sort(distances(line.positions))
    assert r[2] == pytest.approx(r[0] + r[1], rel=1e-12) and not line.stable
    assert -2.04 < line.energy < -2.02


def test_equilibria_command(tmp_path, capsys):
    """`python -m survey equilibria` reads a survey's [system] and one [initial] start, and
    prints the rotating triangle and the rotating line with their stability (--json for
    scripts); a bad key is named before any work."""
    cfg = tmp_path / "eq.toml"
    cfg.write_text('[initial]\nfamily = "equilateral"\ndelta = 0.0\n[equilibria]\nstarts = 20\n')
    assert main(["equilibria", str(cfg), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)["equilibria"]
    assert [e["stable"] for e in found] == [False, True]
    assert found[1]["energy"] == pytest.approx(108.0) and \
        found[1]["angular_momentum"] == pytest.approx(36.0)
    assert main(["equilibria", str(cfg)]) == 0
    assert "linearly stable" in capsys.readouterr().out
    cfg.write_text('[initial]\nfamily = "equilateral"\n[equilibria]\nstart = 6\n')
    assert main(["equilibria", str(cfg)]) == 2
    assert "[equilibria].start: unknown key (did you mean 'starts'?)" in \
        capsys.readouterr().err


def test_lagranges_family_loses_stability_where_routh_says():
    """Continued in the second mass mu (masses 1, mu, 1e-4, rotation rate 1), Lagrange's
    triangle is stable below Routh's root of 27 (mu + m3 + mu m3) = (1 + mu + m3)^2 and
    unstable above it, where two elliptic modes of opposite Krein sign collide: the
    bisection finds the root to 1e-9 (pseudo-arclength continuation in mu)."""
    m3 = 1e-4

    def systems(mu):
        return System(np.array([1.0, mu, m3]), 2, make_potential("gravity", {"G": 1.0},
                                                                  "pair"))
    members, found, complete, _ = equilibrium_family(systems, TRIANGLE, 0.01, 0.06, steps=5,
                                                  rotation_rate=1.0)
    assert complete and members[-1][0] == 0.06 and np.all(np.diff([p for p, _ in members]) > 0)
    # 27 (mu + m3 + mu m3) = (1 + mu + m3)^2: mu^2 + (2 (1 + m3) - 27 (1 + m3)) mu
    # + (1 + m3)^2 - 27 m3 = 0, the smaller root
    b = -25.0 * (1 + m3)
    c = (1 + m3) ** 2 - 27 * m3
    root = (-b - math.sqrt(b * b - 4 * c)) / 2
    assert [eq.stable for _, eq in members] == [p < root for p, _ in members]
    assert len(found) == 1
    assert found[0].parameter == pytest.approx(root, abs=1e-9)
    assert found[0].kind.startswith("complex quartet")
    before = [eq for p, eq in members if p < root][-1]
    assert sorted(before.krein[before.krein != 0]) == [-1, 1, 1]


def test_equilibria_command_continues_a_family(tmp_path, capsys):
    """[equilibria] parameter/to/steps: the family of the start's equilibrium, its table,
    the stability change, and with --output a NetCDF family archive; a parameter the system
    does not have is named."""
    import xarray as xr
    cfg = tmp_path / "routh.toml"
    cfg.write_text(ROUTH)
    out = tmp_path / "family.nc"
    assert main(["equilibria", str(cfg), "--output", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Stability changes at mass_1 = 0.03995987" in text and "Krein collision" in text
    with xr.open_dataset(out) as ds:
        mu, stable = ds["mass_1"].values, ds["stable"].values
        assert mu[0] == 0.01 and mu[-1] == 0.06 and np.all(np.diff(mu) > 0)
        assert list(stable) == [int(m < 0.03995987) for m in mu]
        assert float(ds["bifurcation_parameter"][0]) == pytest.approx(0.03995987, abs=1e-8)
        assert "Krein" in str(ds["bifurcation_kind"].values[0]) and "mass_1" in ds.attrs["config"]
        members = ds.sizes["member"]
    assert main(["verify", str(out)]) == 0
    assert f"{members} members and 1 bifurcations computed again agree" in \
        capsys.readouterr().out
    cfg.write_text(cfg.read_text().replace('"mass_1"', '"gravity_H"'))
    assert main(["equilibria", str(cfg)]) == 2
    assert "[equilibria].parameter: 'gravity_H' is neither angular_momentum, mass_K nor a " \
        "parameter" in \
        capsys.readouterr().err


def test_the_shape_sphere_points_are_the_triangles_they_name():
    """shape_configuration puts the point w of the shape sphere back as three positions:
    centre of mass at the origin, the radius of gyration asked for, and the mass-weighted
    Jacobi vectors' (|z1|^2 - |z2|^2, 2 z1 conj z2) / (|z1|^2 + |z2|^2) equal to w."""
    m = np.array([1.0, 0.3, 2.0])
    for w in shape_sphere(16):
        q = shape_configuration(m, w, 1.7)
        assert np.allclose(m @ q, 0.0, atol=1e-12)
        assert np.sqrt(np.sum(m[:, None] * q ** 2) / m.sum()) == pytest.approx(1.7)
        z1 = np.sqrt(m[0] * m[1] / (m[0] + m[1])) * complex(*(q[1] - q[0]))
        pair = (m[0] * q[0] + m[1] * q[1]) / (m[0] + m[1])
        z2 = np.sqrt((m[0] + m[1]) * m[2] / m.sum()) * complex(*(q[2] - pair))
        both = abs(z1) ** 2 + abs(z2) ** 2
        c = 2 * z1 * np.conj(z2) / both
        np.testing.assert_allclose([(abs(z1) ** 2 - abs(z2) ** 2) / both, c.real, c.imag],
                                   w, atol=1e-12)


def test_the_default_search_finds_every_relative_equilibrium_of_three_bodies():
    """Equal masses under gravity at J = sqrt 3, from a generic start: Euler's collinear
    solution and Lagrange's triangle (which seeded starts alone missed), each reached
    more than once, with their Morse indices on the amended potential -- Euler's a saddle
    (1), Lagrange's the shape sphere's maximum (2: it minimises the normalised potential
    sqrt(I) sum m m / r). For masses 1, 0.001, 0.0001 at Omega = 1: all three collinear
    solutions (one per body in the middle) and the triangle, nothing missed."""
    gravity = make_potential("gravity", {"G": 1.0}, "pair")
    start = np.array([[1.0, 0.0], [-0.3, 0.7], [-0.6, -0.9]])
    search = relative_equilibria(System(np.ones(3), 2, gravity), start, math.sqrt(3.0))
    euler, lagrange = search.equilibria
    assert euler.energy == pytest.approx(-25.0 / 12.0, rel=1e-10)
    assert lagrange.energy == pytest.approx(-1.5, rel=1e-10)
    assert (euler.morse, lagrange.morse) == (1, 2)
    assert min(search.hits) >= 2 and search.missed == 0
    assert search.shapes == SHAPES and search.tries == 1 + 2 * SHAPES
    unequal = relative_equilibria(System(np.array([1.0, 0.001, 0.0001]), 2, gravity),
                                  start, rotation_rate=1.0)
    sides = [np.sort(np.linalg.norm(e.positions[[0, 0, 1]] - e.positions[[1, 2, 2]],
                                    axis=1)) for e in unequal.equilibria]
    equilateral = [s for s in sides if s[2] - s[0] < 1e-6 * s[2]]
    collinear = [s for s in sides if abs(s[0] + s[1] - s[2]) < 1e-9 * s[2]]
    assert (len(equilateral), len(collinear), len(unequal.equilibria)) == (1, 3, 4)
