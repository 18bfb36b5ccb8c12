"""The chaos indicators a survey can compute (`[indicators] which`) and how they are
computed: the options shared by the Python API and the config."""
from __future__ import annotations

from dataclasses import dataclass


INDICATORS = ("ftle", "megno", "fli", "sali", "gali2")


@dataclass(frozen=True)
class IndicatorOptions:
    """How the indicators are computed; its defaults are the `[indicators]` defaults of a
    survey config."""

    deviations: int = 2            # seeded deviation vectors per orbit (>= 2 for SALI)
    seed: int = 0
    renorm_interval: float = 1.0   # time between renormalisations of the tangent vectors
    history_points: int = 64       # coarse time grid of the convergence histories
    project_flow: bool = False     # project deviations off the flow and grad H at t = 0
    perturbations: int = 2         # extra orbits started perturbation_size away
    perturbation_size: float = 1e-9

    def __post_init__(self):
        if self.deviations < 1:
            raise ValueError("indicators need at least one deviation vector")
        if self.history_points < 2:
            raise ValueError("history_points must be >= 2")
        if self.perturbations < 0 or not self.perturbation_size > 0:
            raise ValueError("perturbations must be >= 0 and perturbation_size > 0")
