"""What every figure shares: the regimes' and statuses' colours, the grid's axes (all of
them, and those a map is drawn over) and a variable's value per cell."""
from __future__ import annotations

import numpy as np

from ..analysis.refine import refined_axes
from ..catalog.regimes import Regime
from ..catalog.status import Status
from ..catalog.variables import V


REGIME_COLOURS = {Regime.TORUS: "#1f77b4", Regime.RESONANT: "#17becf",
                  Regime.PERIODIC: "#2ca02c", Regime.STICKY: "#ff7f0e",
                  Regime.CHAOTIC: "#d62728", Regime.COLLISION: "#000000",
                  Regime.INACCESSIBLE: "#d9d9d9", Regime.UNDETERMINED: "#9467bd",
                  Regime.EQUILIBRIUM: "#bcbd22", Regime.ESCAPED: "#e7cb94"}


STATUS_COLOURS = {Status.COLLISION: "#000000", Status.STEP_LIMIT: "#8c564b",
                  Status.NONFINITE: "#e377c2", Status.INACCESSIBLE: "#d9d9d9",
                  Status.TIME_LIMIT: "#7f7f7f", Status.ESCAPED: "#808000"}


def grid_axes(ds) -> list[str]:
    return list(ds[V.status].dims)


def map_axes(ds) -> list[str]:
    """The axes a map is drawn over: the grid's, or those a refined survey's cells spread
    over."""
    return refined_axes(ds) or grid_axes(ds)


def per_cell(ds, name) -> np.ndarray:
    """A variable's value at every cell, flat in the grid's order (a grid axis such as the
    target energy is a coordinate of one dimension)."""
    status = ds[V.status]
    return ds[name].broadcast_like(status).transpose(*status.dims).values.ravel()
