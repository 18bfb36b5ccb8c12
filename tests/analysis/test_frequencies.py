"""Frequencies labelled across a grid: each regular cell's shape frequencies, listed in
whatever order NAFF found them, are put in the order that continues the neighbours', so
one family is one curve."""
import numpy as np
import xarray as xr

from survey.analysis.frequencies import labelled
from survey.catalog.regimes import Regime
from survey.catalog.variables import V


def family(grid_shape, curves, regime, rng):
    """A Dataset whose cells hold `curves` (..., 3 shape frequencies) shuffled per cell,
    then a rotation column."""
    shuffled = np.empty(grid_shape + (4,))
    for idx in np.ndindex(grid_shape):
        shuffled[idx + (slice(0, 3),)] = rng.permutation(curves[idx])
        shuffled[idx + (3,)] = 0.47
    dims = [f"a{k}" for k in range(len(grid_shape))]
    return xr.Dataset({V.frequency: (dims + ["fundamental"], shuffled),
                       V.regime: (dims, regime)},
                      coords={"fundamental_name": ("fundamental",
                                                   ["shape_1", "shape_2", "shape_3", "rotation"])})


def test_a_one_axis_family_becomes_three_curves_and_chaos_is_left_out():
    rng = np.random.default_rng(1)
    x = np.linspace(0.0, 1.0, 40)
    # three frequencies that cross each other's values nowhere near a grid step
    curves = np.stack([0.95 + 0.01 * x, 0.82 + 0.05 * x, 0.14 - 0.05 * x], axis=-1)
    regime = np.full(40, Regime.TORUS)
    regime[25:28] = Regime.CHAOTIC                       # a gap: the next patch continues
    ds = family((40,), curves, regime, rng)
    out = labelled(ds)
    assert np.isnan(out[25:28]).all()
    rest = np.r_[0:25, 28:40]
    np.testing.assert_array_equal(out[rest, :3], curves[rest])     # fastest first, followed
    np.testing.assert_array_equal(out[rest, 3], 0.47)


def test_a_map_over_two_axes_is_labelled_breadth_first():
    rng = np.random.default_rng(2)
    a, b = np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 9), indexing="ij")
    curves = np.stack([0.9 + 0.04 * a - 0.02 * b, 0.7 + 0.05 * b, 0.2 - 0.03 * a], axis=-1)
    ds = family((12, 9), curves, np.full((12, 9), Regime.TORUS), rng)
    np.testing.assert_array_equal(labelled(ds)[..., :3], curves)
