"""The chaos indicators and lines of evidence, each declared once in REGISTRY: the archive
variables it fills, the deviation vectors it needs, how maps draw it and how it votes on a
cell's regime. The config's `[indicators] which`, the archive's indicator variables, the plot
labels' owners, colour maps and reference lines, and the classifier's evidence all follow
from it, and a test battery (tests/catalog/test_registries.py) runs on every entry, so an
indicator that lacks a piece fails a test. Also the options of their computation."""
from __future__ import annotations

from dataclasses import dataclass

# where an indicator is computed: integrated with deviation vectors ([indicators] which),
# or from the orbit's samples by the torus analysis ([tori] analyse)
TANGENT, TORUS = "tangent", "torus"


@dataclass(frozen=True)
class MapStyle:
    """How a map over two grid axes draws an indicator."""

    cmap: str
    clip: tuple[float, float] | None = None     # colour range (else the data's)
    log: bool = False


@dataclass(frozen=True)
class Vote:
    """How a line of evidence votes: the variable read, +1 if larger values are more regular
    (-1: more chaotic), and the catalog.regimes.Thresholds fields `<thresholds>_regular` and
    `<thresholds>_chaotic`; `per_torus_rate`: measured in units of ln(T)/T, a torus's FTLE;
    `half`: the variable holding its value at half the cell's horizon (a history, read at
    that time, or a scalar), "" if there is none -- the verdict at T/2; `log`: its
    thresholds span decades."""

    variable: str
    sign: int
    thresholds: str
    per_torus_rate: bool = False
    half: str = ""
    log: bool = False          # its thresholds span decades: moved in log10 (SALI)


@dataclass(frozen=True)
class Indicator:
    name: str
    source: str                     # TANGENT or TORUS
    variables: tuple[str, ...]      # the archive variables it fills
    reference: str
    deviations: int = 1             # deviation vectors it needs (TANGENT)
    map: MapStyle | None = None     # drawn in maps over two axes and in one-axis scans
    vote: Vote | None = None        # a line of evidence of the regime

    @property
    def headline(self) -> str:
        """The variable maps, scans and reports show: the first it fills."""
        return self.variables[0]

    def computed_in(self, config) -> bool:
        """Whether a survey config computes it."""
        if self.source == TANGENT:
            return self.name in config.settings.indicators.which
        return bool(config.settings.tori.analyse)


REGISTRY = (
    Indicator("ftle", TANGENT, ("ftle", "ftle_ensemble", "ensemble_orbits", "ftle_wba",
                                "ftle_history"),
              "Benettin, Galgani, Giorgilli & Strelcyn, Meccanica 15 (1980) 9",
              map=MapStyle("magma", log=True),
              vote=Vote("ftle", -1, "ftle", True, half="ftle_history")),
    Indicator("megno", TANGENT, ("megno", "megno_ensemble", "megno_slope", "megno_history"),
              "Cincotta & Simo, Astron. Astrophys. Suppl. 147 (2000) 205",
              map=MapStyle("viridis", (0.0, 8.0)),
              vote=Vote("megno", -1, "megno", half="megno_history")),
    Indicator("fli", TANGENT, ("fli", "fli_history"),
              "Froeschle, Lega & Gonczi, Celest. Mech. Dyn. Astron. 67 (1997) 41",
              map=MapStyle("cividis")),
    Indicator("sali", TANGENT, ("sali", "sali_history"), "Skokos, J. Phys. A 34 (2001) 10029",
              deviations=2, vote=Vote("sali", +1, "sali", half="sali_history", log=True)),
    Indicator("gali2", TANGENT, ("gali2",),
              "Skokos, Bountis & Antonopoulos, Physica D 231 (2007) 30", deviations=2),
    Indicator("wba", TORUS, ("birkhoff_digits", "birkhoff_digits_half",
                             "birkhoff_digits_observable", "birkhoff_digits_observable_half"),
              "Das, Saiki, Sander & Yorke, Nonlinearity 30 (2017) 4111",
              map=MapStyle("viridis_r", (0.0, 12.0)),
              vote=Vote("birkhoff_digits", +1, "digits", half="birkhoff_digits_half")),
    Indicator("diffusion", TORUS, ("frequency_diffusion", "frequency", "frequency_change",
                                   "resonance", "resonance_order", "resonance_distance",
                                   "moving_shapes"),
              "Laskar, Physica D 67 (1993) 257",
              vote=Vote("frequency_diffusion", -1, "diffusion")),
)
BY_NAME = {i.name: i for i in REGISTRY}
# the indicators `[indicators] which` chooses from, in their default order
INDICATORS = tuple(i.name for i in REGISTRY if i.source == TANGENT)
# the archive variable -> the indicator that fills it
OWNER = {v: i for i in REGISTRY for v in i.variables}


@dataclass(frozen=True)
class IndicatorOptions:
    """How the indicators are computed; its defaults are the `[indicators]` defaults of a
    survey config."""

    deviations: int = 2            # seeded deviation vectors per orbit (>= 2 for SALI)
    seed: int = 0
    renorm_interval: float = 1.0   # time between renormalisations of the tangent vectors
    history_points: int = 64       # coarse time grid of the convergence histories
    project_flow: bool = False     # project deviations off the flow and grad H at t = 0
    perturbations: int = 16        # extra orbits started perturbation_size away
    perturbation_size: float = 1e-9
    nudge: float = 0.0             # the nominal start moved this far (relative, seeded): the
    #                                same survey with other last bits ([check] runs)

    def __post_init__(self):
        if self.deviations < 1:
            raise ValueError("indicators need at least one deviation vector")
        if self.history_points < 2:
            raise ValueError("history_points must be >= 2")
        if self.perturbations < 0 or not self.perturbation_size > 0:
            raise ValueError("perturbations must be >= 0 and perturbation_size > 0")
        if not self.nudge >= 0:
            raise ValueError("nudge must be >= 0")
