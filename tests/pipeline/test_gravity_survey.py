"""A survey of Newtonian gravity as a user writes it: Lagrange's equilateral triangle, whose
linear stability is Routh's criterion 27 (m1 m2 + m2 m3 + m3 m1) < M^2. The Routh-stable
masses (1, 0.001, 0.0001) give an equilibrium cell (a relative equilibrium: the shape stays
put), equal masses (unstable) a chaotic one."""
import math

import numpy as np
import pytest

from survey import Regime, run

GRAVITY = '{kind = "pair", potential = "gravity", params = {G = 1.0}}'
# the same force written as a mass-weighted power law: coupling r^-1 / -1 = -1 / r
WEIGHTED_POWER = ('{kind = "pair", potential = "power", mass_weighted = true, '
                  'params = {coupling = 1.0, exponent = -1.0}}')


def lagrange_config(masses, term, out):
    """Lagrange's triangle of side 1 (G = 1) turning at Omega^2 = M for 50 turns."""
    m = np.asarray(masses, dtype=float)
    angles = [math.pi / 2 + 2 * math.pi * k / 3 for k in range(3)]
    corners = np.array([[math.cos(a), math.sin(a)] for a in angles]) / math.sqrt(3)
    q = corners - m @ corners / m.sum()
    omega = math.sqrt(m.sum())
    v = omega * np.stack([-q[:, 1], q[:, 0]], axis=1)
    return f"""
[survey]
name = "lagrange"
output = "{out}"
[system]
masses = {m.tolist()}
interactions = [{term}]
[initial]
family = "explicit"
positions = {q.tolist()}
velocities = {v.tolist()}
[integration]
t_final = {50 * 2 * math.pi / omega!r}
"""


@pytest.mark.parametrize("masses,term,regime", [
    ((1.0, 0.001, 0.0001), GRAVITY, Regime.EQUILIBRIUM),
    ((1.0, 0.001, 0.0001), WEIGHTED_POWER, Regime.EQUILIBRIUM),
    ((1.0, 1.0, 1.0), GRAVITY, Regime.CHAOTIC)])
def test_the_lagrange_triangle_is_regular_exactly_where_routh_says(tmp_path, masses, term,
                                                                   regime):
    cfg = tmp_path / "lagrange.toml"
    cfg.write_text(lagrange_config(masses, term, tmp_path / "x.nc"))
    ds = run(cfg, workers=1, progress=False)
    assert Regime(int(ds.regime.values.ravel()[0])) == regime
    if regime == Regime.EQUILIBRIUM:   # the unstable one breaks up into close encounters
        assert float(ds.energy_error.max()) < 1e-10
