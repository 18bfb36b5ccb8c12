"""Families of periodic orbits by pseudo-arclength continuation, checked against closed
forms and scaling laws: the rotating triangle's Lyapunov families under U = P^2/2 (the
breathing family is the homographic one: an isotropic oscillator in the size), the
figure-eight along its energy (Kepler's law), and a fold and a period doubling of the
lowest mode's family confirmed by independent shooting."""
import json
import math

import numpy as np
import pytest
import xarray as xr

from conftest import BREATHING
from survey.cli import main
from survey.numerics.periodic import lyapunov_start, periodic_family, periodic_orbit
from survey.physics.equilibria import relative_equilibrium
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.physics.terms import make_potential

PAPER = System.create()            # U = P^2/2, unit masses


@pytest.fixture(scope="module")
def triangle():
    """The rotating equilateral triangle of side 2 sqrt3 (J = 36, Omega = 3) and its modes
    f = Omega (1 -+ 1/sqrt2) / 2 pi and 2 Omega / 2 pi."""
    y0 = initial_state(PAPER, "equilateral", delta=0.0)
    eq = relative_equilibrium(PAPER, PAPER.split(y0)[0], angular_momentum=36.0)
    assert eq.rotation_rate == pytest.approx(3.0, rel=1e-12)
    np.testing.assert_allclose(eq.frequencies, 3.0 * np.array(
        [1 - 1 / math.sqrt(2), 1 + 1 / math.sqrt(2), 2.0]) / (2 * math.pi), rtol=1e-10)
    return eq


def lyapunov(eq, mode, system=PAPER):
    start, period = lyapunov_start(system, eq, mode)
    return periodic_orbit(system, start, period, rotating=True)


def test_lyapunov_orbits_start_at_the_normal_modes(triangle):
    """At amplitude 1e-3 each mode's orbit returns after ~1 / f_k (to amplitude^2), and its
    multipliers are those of the linearisation over that time, exp(+-2 pi i f_j / f_k):
    stability indices cos(2 pi f_j / f_k)."""
    f = triangle.frequencies
    for k in (1, 2, 3):
        orbit = lyapunov(triangle, k)
        assert orbit.period == pytest.approx(1 / f[k - 1], rel=1e-5)
        assert orbit.return_error < 1e-12 and orbit.stable
        expected = np.sort([math.cos(2 * math.pi * f[j] / f[k - 1]) for j in range(3)
                            if j != k - 1])
        np.testing.assert_allclose(np.sort(orbit.indices.real), expected, atol=1e-4)


def test_the_breathing_family_is_the_homographic_closed_form(triangle):
    """Mode 3's family in energy at fixed J: the triangle stays equilateral while its size
    z(t) obeys z'' = -Omega^2 z (U is homogeneous of degree 2 and the triangle central), so
    every member returns after pi / Omega = pi / 3 turned by exactly pi; the shape modes see
    the Hessian rotated, not rescaled, so their multipliers stay exp(+-2 pi i f_1 / f_3):
    both indices cos(pi (1 - 1/sqrt2)) at every energy, up to 300 = 2.8 times the
    equilibrium's."""
    orbit = lyapunov(triangle, 3)
    family = periodic_family(lambda p: PAPER, orbit, orbit.energy, 300.0, steps=8,
                             rotating=True, pinned="energy")
    assert family.complete and family.parameters[-1] == 300.0
    assert family.members[-1].energy == pytest.approx(300.0, rel=1e-12)
    assert np.all(np.diff(family.parameters) > 0) and not family.bifurcations
    for member in family.members:
        assert member.period == pytest.approx(math.pi / 3, rel=1e-11)
        assert member.rotation == pytest.approx(math.pi, rel=1e-11)
        assert member.angular_momentum == pytest.approx(orbit.angular_momentum, rel=1e-12)
        np.testing.assert_allclose(member.indices.real, math.cos(math.pi * (1 - 2 ** -0.5)),
                                   atol=1e-9)


def test_a_potential_parameter_moves_the_breathing_period_as_its_closed_form(triangle):
    """The same family continued in the coupling c at fixed E and J (the parameter's column
    by finite differences): Omega scales as sqrt(c), so the period is pi / (3 sqrt c)."""
    orbit = lyapunov(triangle, 3)
    family = periodic_family(
        lambda c: System.create(potential="perimetric_power", coupling=c, exponent=2.0),
        orbit, 1.0, 0.5, steps=5, rotating=True)
    assert family.complete and family.parameters[-1] == 0.5
    for c, member in zip(family.parameters, family.members):
        assert member.period == pytest.approx(math.pi / (3 * math.sqrt(c)), rel=1e-9)
        assert member.rotation == pytest.approx(math.pi, rel=1e-9)
        assert member.energy == pytest.approx(orbit.energy, rel=1e-12)


@pytest.mark.parametrize("to, steps", [(2.0, 3), (0.5 / 1.287141992, 1)])
def test_the_figure_eight_along_its_energy_keeps_keplers_law(to, steps):
    """Under gravity (degree -1) a family in energy is one orbit rescaled: T |E|^(3/2) is
    constant and the multipliers do not move, for every member from E to 2 E, and from E
    to -0.5 in one nominal step -- where the corrector once landed on a neighbouring
    family and a bifurcation that cannot exist was reported; a member is at the energy it
    is labelled with, the last one at the end."""
    gravity = System(np.ones(3), 2, make_potential("gravity", {"G": 1.0}, "pair"))
    x1, v3 = np.array([0.97000436, -0.24308753]), np.array([-0.93240737, -0.86473146])
    start = gravity.state(np.array([x1, -x1, [0.0, 0.0]]), [-v3 / 2, -v3 / 2, v3])
    eight = periodic_orbit(gravity, start, 6.33)
    family = periodic_family(lambda p: gravity, eight, eight.energy, to * eight.energy,
                             steps=steps, pinned="energy")
    assert family.complete and len(family.members) >= 4 and not family.bifurcations
    assert family.parameters[-1] == to * eight.energy
    for p, member in zip(family.parameters, family.members):
        assert member.energy == pytest.approx(p, rel=1e-10)
        assert member.period * abs(member.energy) ** 1.5 == pytest.approx(
            eight.period * abs(eight.energy) ** 1.5, rel=1e-9)
        np.testing.assert_allclose(member.indices.real, eight.indices.real, atol=1e-7)


def test_a_family_parameter_left_at_its_default_reaches_the_system(tmp_path, capsys):
    """[equilibria]/[periodic] parameter along a term's parameter that [system] leaves at
    its default: the rotating triangle's Omega = 3 sqrt(c) from c = 1 to 1/4 (1.5 at the
    end, not 3 at every member), its breathing family's period pi / (3 sqrt c); a name that
    is no parameter of the terms is refused."""
    cfg = tmp_path / "triangle.toml"
    cfg.write_text('[initial]\nfamily = "equilateral"\ndelta = 0.0\n[equilibria]\n'
                   'parameter = "perimetric_power_coupling"\nto = 0.25\nsteps = 2\n')
    assert main(["equilibria", str(cfg), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["complete"] and found["perimetric_power_coupling"][-1] == 0.25
    for c, member in zip(found["perimetric_power_coupling"], found["family"]):
        assert member["rotation_rate"] == pytest.approx(3 * math.sqrt(c), rel=1e-10)
    cfg.write_text('[initial]\nfamily = "equilateral"\ndelta = 0.0\n[periodic]\nmode = 3\n'
                   'parameter = "perimetric_power_coupling"\nto = 0.5\nsteps = 2\n')
    assert main(["periodic", str(cfg), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["complete"] and found["perimetric_power_coupling"][-1] == 0.5
    for c, member in zip(found["perimetric_power_coupling"], found["family"]):
        assert member["period"] == pytest.approx(math.pi / (3 * math.sqrt(c)), rel=1e-9)
    from survey.pipeline.build import build_system
    from survey.pipeline.config import parse_config
    table = parse_config('[initial]\nfamily = "equilateral"\n').tables["system"]
    assert build_system(table, {"perimetric_power_coupling": 0.5}).terms[0].params[0] == 0.5
    with pytest.raises(ValueError, match="'perimetric_power_strength' is no parameter"):
        build_system(table, {"perimetric_power_strength": 0.5})


def test_a_fold_brings_a_pair_through_plus_one_and_is_a_fold(triangle):
    """Mode 1 (Krein sign -) runs down in energy, its indices swinging to +-1 and back
    (the steps refined there), folds at E ~ 105.0 and returns unstable. A fold in energy
    at fixed J puts a pair of multipliers at +1: both are found at the same energy, the
    family's lowest. Shot independently at 0.05 above the fold from the members either
    side of its lowest, two orbits: an elliptic and a hyperbolic one, their periods either
    side of the lowest member's -- the two branches that meet there. (Steps that crossed
    an index's edge unrefined once landed on a neighbouring family and reported its fold
    at 103.6.)"""
    orbit = lyapunov(triangle, 1)
    family = periodic_family(lambda p: PAPER, orbit, orbit.energy, 90.0, steps=20,
                             rotating=True, pinned="energy")
    kinds = {b.kind: b for b in family.bifurcations}
    fold, plus = kinds["fold"], kinds["through +1"]
    assert fold.parameter == pytest.approx(plus.parameter, abs=1e-6)
    assert 104.5 < fold.parameter < 105.5 and not family.complete
    assert family.parameters.min() >= fold.parameter - 1e-6
    assert family.parameters.min() == pytest.approx(fold.parameter, abs=0.05)
    low = int(np.argmin(family.parameters))
    assert family.members[0].stable and not family.members[low + 1].stable
    sides = [periodic_orbit(PAPER, family.members[k].state, family.members[k].period,
                            rotating=True, energy=fold.parameter + 0.05)
             for k in (low - 1, low + 1)]
    assert sorted(o.kind for o in sides) == ["elliptic", "hyperbolic"]
    periods = sorted(o.period for o in sides)
    assert periods[0] < family.members[low].period < periods[1]


def test_periodic_family_command(tmp_path, capsys):
    """`python -m survey periodic` with [periodic] mode and parameter prints the family and
    its bifurcations, writes it with --output as a labelled NetCDF Dataset carrying its
    config and provenance, and refuses a family asked to run the wrong way or without an
    end."""
    cfg = tmp_path / "breathing.toml"
    cfg.write_text(BREATHING)
    out = tmp_path / "family.nc"
    assert main(["periodic", str(cfg), "--output", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Lyapunov family of normal mode 3" in text and "reaching energy = 150" in text
    with xr.open_dataset(out) as ds:
        assert ds.attrs["family"] == "periodic" and "mode = 3" in ds.attrs["config"]
        assert "git_commit" in ds.attrs and "machine" in ds.attrs
        assert float(ds["energy"][-1]) == 150.0
        np.testing.assert_allclose(ds["period"], math.pi / 3, rtol=1e-11)
        assert ds["index_real"].dims == ("member", "pair") and ds["stable"].all()
    assert main(["verify", str(out)]) == 0
    assert "members and 0 bifurcations computed again agree bit for bit" in \
        capsys.readouterr().out
    with xr.open_dataset(out) as ds:        # a tampered member is found
        tampered = ds.load()
    tampered["period"][1] = np.nextafter(tampered["period"][1], 0.0)    # one ulp
    tampered.to_netcdf(tmp_path / "tampered.nc")
    assert main(["verify", str(tmp_path / "tampered.nc")]) == 1
    assert "period: differs by 2.1e-16 of its scale" in capsys.readouterr().out
    assert main(["periodic", str(cfg), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["complete"] and found["bifurcations"] == [] and len(found["energy"]) >= 4
    cfg.write_text(cfg.read_text().replace("mode = 3", "mode = 1"))
    assert main(["periodic", str(cfg)]) == 2
    assert "[periodic].to: mode 1's family leaves the equilibrium toward lower energy" \
        in capsys.readouterr().err
    cfg.write_text(cfg.read_text().replace("mode = 1", "mode = 5"))
    assert main(["periodic", str(cfg)]) == 2
    assert "[periodic].mode: 5: the start's relative equilibrium has 3 normal modes" in \
        capsys.readouterr().err
    cfg.write_text(cfg.read_text().replace("mode = 5", "mode = 1").replace("to = 150.0\n", ""))
    assert main(["periodic", str(cfg)]) == 2
    assert "[periodic].to: is required with a parameter" in capsys.readouterr().err


def test_families_in_the_angular_momentum_keep_the_closed_forms(triangle):
    """J as the parameter. The rotating triangle under P^2/2 from J = 36 to 72: Omega = 3
    at every size, so every member has E = Omega J exactly and the same modes. The breathing
    family's member at E = 110 from J = 36 to 30 (E held): still period pi/3, turning pi."""
    from survey.numerics.continuation import equilibrium_family
    members, found, complete, _ = equilibrium_family(
        lambda p: PAPER, triangle.positions, 36.0, 72.0, steps=4, angular_momentum=36.0,
        spin_parameter=True)
    assert complete and members[-1][0] == 72.0 and not found
    for j, eq in members:
        assert eq.angular_momentum == pytest.approx(j, rel=1e-12)
        assert eq.rotation_rate == pytest.approx(3.0, rel=1e-10)
        assert eq.energy == pytest.approx(3.0 * j, rel=1e-10)
        np.testing.assert_allclose(eq.frequencies, triangle.frequencies, rtol=1e-9)
    start, period = lyapunov_start(PAPER, triangle, 3)
    orbit = periodic_orbit(PAPER, start, period, rotating=True, energy=110.0)
    family = periodic_family(lambda p: PAPER, orbit, orbit.angular_momentum, 30.0, steps=4,
                             rotating=True, pinned="angular_momentum")
    assert family.complete and family.members[-1].angular_momentum == pytest.approx(30.0)
    for member in family.members:
        assert member.energy == pytest.approx(110.0, rel=1e-12)
        assert member.period == pytest.approx(math.pi / 3, rel=1e-11)
        assert member.rotation == pytest.approx(math.pi, rel=1e-11)


def test_a_lyapunov_start_keeps_the_equilibriums_angular_momentum(triangle):
    """The displacement along a mode moves J at second order; the start takes it back, so
    a family in energy runs at the J asked for (36), not at 36 +- 3e-5."""
    J0 = float(PAPER.angular_momentum(triangle.state(PAPER)))
    assert J0 == pytest.approx(36.0, rel=1e-14)
    for mode in (1, 2, 3):
        start, _ = lyapunov_start(PAPER, triangle, mode, amplitude=1e-2)
        assert float(PAPER.angular_momentum(start)) == pytest.approx(J0, abs=1e-12)
        assert np.allclose(PAPER.momentum(start), 0.0, atol=1e-12)
