"""A potential homogeneous of degree k maps orbits to orbits under q -> s q, p -> s^(k/2) p,
t -> s^(1-k/2) t: two starts related so are one dynamics. The archive's
scale_free_energy, E |J|^(-2k/(k+2)), is the same for both; their regimes are the same and
their frequencies scale by s^(k/2 - 1) (the runs' times and sampling scaled alike)."""
import numpy as np
import pytest

from survey.catalog.variables import V
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.pipeline.sweep import run


@pytest.mark.parametrize("k, s", [(2.0, 2.0), (3.0, 4.0)])
def test_scaled_starts_are_one_dynamics(tmp_path, k, s):
    system = System.create(potential="perimetric_power", exponent=k)
    q, p = system.split(initial_state(system, "equilateral", delta=3.0))
    T = 1000.0
    runs = []
    for scale in (1.0, s):
        stretch = scale ** (1 - k / 2)             # the time scale
        runs.append(run({
            "survey": {"name": "scaled", "output": str(tmp_path / f"s{scale}.nc")},
            "system": {"potential": "perimetric_power", "params": {"exponent": k}},
            "initial": {"family": "explicit", "positions": (scale * q).tolist(),
                        "velocities": (scale ** (k / 2) * p).tolist()},
            "integration": {"t_final": T * stretch},
            "indicators": {"perturbations": 2, "renorm_interval": stretch},
            "tori": {"sample_interval": 0.05 * stretch}, "dask": {"workers": 1}},
            progress=False))
    a, b = runs
    assert float(a[V.scale_free_energy]) == pytest.approx(float(b[V.scale_free_energy]),
                                                          rel=1e-13)
    if k == 2.0:        # E / |J|
        assert float(a[V.scale_free_energy]) == pytest.approx(
            float(a[V.energy]) / abs(float(a[V.angular_momentum])), rel=1e-15)
    assert int(a[V.regime]) == int(b[V.regime]) == 0              # a torus, both
    np.testing.assert_allclose(b[V.frequency].values, s ** (k / 2 - 1) * a[V.frequency].values,
                               rtol=1e-7)


def test_no_scale_free_energy_where_a_scale_is_set():
    """The areal barrier and Lennard-Jones set a scale: no scale-free combination."""
    assert System.create(potential="areal_barrier").homogeneity is None
    assert System.create(potential="perimetric_power", exponent=0.0).homogeneity is None
    assert System.create(potential="areal_power", exponent=2.0).homogeneity == 4.0
