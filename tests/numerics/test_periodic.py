"""Periodic orbits by Newton shooting: the figure-eight choreography (Chenciner &
Montgomery; Simo's digits) and the areal barrier's rotating homographic orbit, whose
multipliers are checked against the growth of a perturbation along it."""
import json
import math

import numpy as np
import pytest

from survey import integrate
from survey.cli import main
from survey.numerics.periodic import periodic_orbit
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.physics.terms import make_potential

GRAVITY = System(np.ones(3), 2, make_potential("gravity", {"G": 1.0}, "pair"))
# Simo's figure-eight start (G = m = 1) to 8 digits, and its period to the same
X1, V3 = np.array([0.97000436, -0.24308753]), np.array([-0.93240737, -0.86473146])
PERIOD = 6.32591398


def figure_eight(scale=1.0):
    """The start scaled by `scale` in size: E / scale, period scale^(3/2) (Kepler's law
    holds for any orbit of a -1 homogeneous potential)."""
    v = V3 / math.sqrt(scale)
    return GRAVITY.state(scale * np.array([X1, -X1, [0.0, 0.0]]), [-v / 2, -v / 2, v])


@pytest.fixture(scope="module")
def eight():
    return periodic_orbit(GRAVITY, figure_eight(), 6.33)


def test_the_figure_eight_from_simos_digits(eight):
    """From the 8-digit start: its period to those digits (the start's rounding moves the
    energy, so the period, by ~1e-8), the return error at the tolerance, the four
    non-trivial multipliers on the unit circle to 1e-6 (it is linearly stable) and in
    reciprocal pairs."""
    assert eight.period == pytest.approx(PERIOD, rel=1e-8)
    assert eight.return_error < 1e-12 and eight.angular_momentum == pytest.approx(0, abs=1e-7)
    assert eight.multipliers.size == 4 and eight.stable and eight.kind == "elliptic"
    np.testing.assert_allclose(np.abs(eight.multipliers), 1.0, atol=1e-6)
    mu = eight.multipliers
    np.testing.assert_allclose(np.sort_complex(1 / mu), np.sort_complex(np.conj(mu)),
                               atol=1e-8)


def test_the_figure_eight_at_twice_the_energy_keeps_keplers_law(eight):
    """Shot again at E' = 2 E from the start shrunk by 2: the period is T / 2^(3/2) to 1e-10
    (the scaling law, not the shooting, fixes it)."""
    half = periodic_orbit(GRAVITY, figure_eight(0.5), 6.33 / 2 ** 1.5,
                          energy=2 * eight.energy)
    assert half.period == pytest.approx(eight.period / 2 ** 1.5, rel=1e-10)


def test_newton_converges_quadratically(eight):
    """From the start 1e-5 off, at the same energy: each return error at most ~ the square
    of the one before (a constant of 1e3: a pair of multipliers lies near 1, at angle 0.05)
    down to 1e-10 (the integration's 1e-13 amplified by 1 / |mu - 1|), then to the
    tolerance, and the same period to 1e-10; from a rougher guess, 1e-4 off with
    the period 0.06% off, it still converges, in more steps."""
    rng = np.random.default_rng(2)
    orbit = periodic_orbit(GRAVITY, figure_eight() + 1e-5 * rng.normal(size=GRAVITY.n),
                           PERIOD, energy=eight.energy)
    r = orbit.residuals
    assert r[0] > 1e-6 and r[-1] < 1e-12 and len(r) <= 5
    for before, after in zip(r[:-1], r[1:]):
        assert after < max(1e3 * before ** 2, 1e-10), r
    assert orbit.period == pytest.approx(eight.period, rel=1e-10)
    rough = periodic_orbit(GRAVITY, figure_eight() + 1e-4 * rng.normal(size=GRAVITY.n),
                           6.33, energy=eight.energy)
    assert rough.period == pytest.approx(eight.period, rel=1e-10)


def test_the_areal_homographic_orbit_is_unstable_at_the_rate_its_neighbours_leave():
    """Areal barrier U = 2/|A| + |A|^2, the equilateral family at delta = 0 (E = 8): the
    triangle breathes while it turns, a relative periodic orbit; its multipliers are a
    complex quartet off the unit circle, and a start 1e-10 off it loses its equal sides at
    the rate ln|mu| / T (the envelope of the difference between its sides)."""
    system = System.create(potential="areal_barrier")
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), delta=0.0, energy=8.0)
    orbit = periodic_orbit(system, y0, 1.5, rotating=True)
    assert orbit.kind == "complex unstable" and not orbit.stable
    mu = np.abs(orbit.multipliers)
    np.testing.assert_allclose(np.sort(mu) * np.sort(mu)[::-1], 1.0, rtol=1e-8)
    rate = orbit.rates[0]
    start = orbit.state + 1e-10 * np.random.default_rng(0).normal(size=system.n)
    times = np.linspace(0.0, 25.0, 2501)
    out = integrate(system, start, (0.0, 25.0), t_eval=times, rtol=1e-13, atol=1e-13)
    q = system.split(out.samples)[0]
    sides = np.stack([np.linalg.norm(q[:, a] - q[:, b], axis=1)
                      for a, b in ((0, 1), (1, 2), (2, 0))])
    spread = np.maximum.accumulate(np.ptp(sides, axis=0))
    window = (spread > 1e-7) & (spread < 1e-3)
    slope = np.polyfit(times[window], np.log(spread[window]), 1)[0]
    assert slope == pytest.approx(rate, rel=0.05)


def test_periodic_command(tmp_path, capsys):
    """`python -m survey periodic` shoots from a config's [initial] start ([periodic]
    period is required) and prints the orbit and its multipliers, or JSON."""
    cfg = _eight_config(tmp_path, 6.33)
    assert main(["periodic", str(cfg), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert found["period"] == pytest.approx(PERIOD, rel=1e-8) and found["stable"]
    assert len(found["multipliers"]) == 4 and found["newton_residuals"][-1] < 1e-12
    assert main(["periodic", str(cfg)]) == 0
    assert "elliptic, linearly stable" in capsys.readouterr().out
    cfg.write_text(cfg.read_text().replace("period = 6.33", "perod = 6.33"))
    assert main(["periodic", str(cfg)]) == 2
    assert "[periodic].perod: unknown key (did you mean 'period'?)" in capsys.readouterr().err


def test_a_given_energy_is_met_even_from_a_periodic_guess():
    """Shot from a converged orbit at another energy, the result has that energy (a guess
    that already returns must not end the iteration)."""
    system = System.create(potential="areal_barrier")
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), delta=0.0, energy=8.0)
    orbit = periodic_orbit(system, y0, 1.5, rotating=True)
    near = periodic_orbit(system, orbit.state, orbit.period, rotating=True, energy=7.9)
    assert float(system.energy(near.state)) == pytest.approx(7.9, rel=1e-12)
    assert near.return_error < 1e-12 and near.period != orbit.period
    assert near.angular_momentum == pytest.approx(orbit.angular_momentum, rel=1e-12)


def _eight_config(tmp_path, period):
    def rows(a):
        return "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]"
                               for row in a) + "]"
    cfg = tmp_path / "eight.toml"
    cfg.write_text(f"""
[system]
interactions = [{{kind = "pair", potential = "gravity", params = {{G = 1.0}}}}]
[initial]
family = "explicit"
positions = {rows([X1, -X1, [0.0, 0.0]])}
velocities = {rows([-V3 / 2, -V3 / 2, V3])}
[periodic]
period = {period!r}
""")
    return cfg


@pytest.mark.parametrize("period", [1e-14, 1e-9, 1e-5])
def test_a_period_guess_below_the_flows_time_scale_is_refused(tmp_path, capsys, period):
    """A guess whose period is far below the time the flow takes to turn (the eight's
    ~0.35) would return to its start to the tolerance before any Newton step: refused as a
    config error naming the key, before any shooting -- from a regular and from a chaotic
    start."""
    assert main(["periodic", str(_eight_config(tmp_path, period))]) == 2
    err = capsys.readouterr().err
    assert f"[periodic].period: a period of {period:.3g} is below 1/1000 of the flow's " \
           "time scale" in err
    cfg = tmp_path / "chaos.toml"
    cfg.write_text(f'[initial]\nfamily = "equilateral"\ndelta = 4.5\n[periodic]\n'
                   f'period = {period!r}\n')
    assert main(["periodic", str(cfg)]) == 2
    assert "[periodic].period: a period of" in capsys.readouterr().err


def test_a_start_that_does_not_move_is_no_periodic_orbit(monkeypatch, eight):
    """Past the guess's check, the converged orbit itself must move: a tiny period (which
    returns to its start to the tolerance at once) and the rotating triangle, a relative
    equilibrium that returns rotated after any time, are refused for what they are; the
    figure-eight leaves its start by about its size, and its velocity turns through more
    than a full circle (Fenchel: at least one for a closed curve)."""
    from survey.numerics import periodic
    monkeypatch.setattr(periodic, "SHORTEST", 1e300)
    for guess, period in ((figure_eight(), 1e-14), (figure_eight(), 1e-8)):
        with pytest.raises(ValueError, match="not a periodic orbit: it leaves its start by "
                                             "only"):
            periodic_orbit(GRAVITY, guess, period)
    paper = System.create()
    with pytest.raises(ValueError, match="a start at rest or in rigid rotation"):
        periodic_orbit(paper, initial_state(paper, "equilateral", delta=0.0), 1.0,
                       rotating=True)
    assert 1.5 < eight.motion.excursion < 2.5 and 1.5 < eight.motion.turning < 1.6
