"""The archive's variables, each declared once: name, units, long name, fill, which cells
carry it, how a cell's result fills it, whether it is reproducible. Everything else follows
from VARIABLES: the arrays a task returns, how a cell fills them, the archive's variables and
attributes, the schema `verify` expects and the documentation's variable reference.

Dimensions: the grid axes (in the order the config writes them), then a variable's own:
`crossing` (section points, NaN-padded, with n_crossings), `history_time` (convergence
histories), `component` (phase-space state), `spatial` (3-D vectors), `observable` and
`fundamental` (torus analysis), `ensemble_statistic` (ENSEMBLE_STATISTICS of an indicator
over the cell's orbit and its perturbed starts), `horizon` (the verdicts at t_final / 2,
t_final and each extension's end).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Callable, NamedTuple

import numpy as np

from .indicators import OWNER
from .regimes import Regime
from .status import Status

# which cells a variable has values for; elsewhere it holds its fill value
ALL, STARTED, FINISHED = "all cells", "cells with a start", "cells with status ok or event"
# an indicator over an ensemble of orbits: its mean, sample standard deviation and quantiles
ENSEMBLE_STATISTICS = ("mean", "sd", "q05", "q50", "q95")
ENSEMBLE_QUANTILES = (0.05, 0.5, 0.95)
# below this many orbits an ensemble's spread is indicative only
ENSEMBLE_MIN = 8


class CellResult(NamedTuple):
    """What one cell computed: the source every archive variable is filled from."""

    status: Status
    wall_time: float
    n_steps: int = 0
    n_rhs: int = 0
    start: np.ndarray | None = None        # None where no start exists (inaccessible)
    t_end: float = np.nan
    energy: Any = np.nan
    angular_momentum: Any = np.nan
    scale_free_energy: float = np.nan     # E |J|^(-2k/(k+2)) of a potential of degree k
    start_potential: float = np.nan       # U at t = 0: E minus it is the start's kinetic energy
    energy_error: float = np.nan
    angular_momentum_error: float = np.nan
    indicators: Any = None                 # numerics.indicators.ChaosIndicators
    tori: Any = None                       # numerics.torus.TorusEvidence
    n_crossings: int = 0
    crossing_time: np.ndarray | None = None    # kept crossings
    crossing_state: np.ndarray | None = None
    reduced: Any = None                    # physics.jacobi.Reduced of the kept crossings
    centre: Any = None                     # (centre of mass, total momentum) of the kept
    #                                        crossings, (k, d) each, in an external field
    horizon: float = np.nan                # the run's t_final: T, or k^r T once extended
    verdicts: Any = None                   # regimes at T/2, T, k T, ... (-1 past the last)
    near: Any = None                       # the nominal orbit's closest approaches
    #                                        (numerics.driver.near_width)
    escape: Any = None                     # (time, body, exit) where a body escaped


@dataclass(frozen=True)
class Var:
    name: str
    long_name: str
    value: Callable[[CellResult], Any]     # how a cell's result fills it
    cells: str = STARTED                   # ALL, STARTED or FINISHED
    dtype: str = "f8"
    extra: tuple[str, ...] = ()            # own dimensions after the grid's
    units: str = "1"
    reproducible: bool = True              # part of the bit-for-bit contract
    when: Callable = lambda config: True   # whether a config's archive holds it
    flags: Any = None                      # an IntEnum: a CF flag variable
    derived: bool = False                  # computed from the other variables (classify)
    symbol: str = ""                       # its label on figures (matplotlib mathtext)

    @property
    def fill(self):
        return np.nan if self.dtype.startswith("f") else -1

    def attrs(self) -> dict:
        attrs = {"long_name": self.long_name}
        if self.flags is not None:
            attrs["flag_values"] = np.array([s.value for s in self.flags], dtype=np.int8)
            attrs["flag_meanings"] = " ".join(s.name.lower() for s in self.flags)
        else:
            attrs["units"] = self.units
        if self.derived:
            attrs["comment"] = "derived by survey.analysis.classify from the other variables"
        elif self.cells != ALL:
            attrs["comment"] = f"{'NaN' if self.dtype.startswith('f') else '-1'} except in " \
                               f"{self.cells}"
        if not self.reproducible:
            attrs["reproducible"] = "no: differs between runs"
        return attrs


def _section(c):
    return c.settings.section_enabled


def _decided(c):
    """Whether a config's cells carry evidence to decide their regime by."""
    return bool(c.settings.indicators.which) or bool(c.settings.tori.analyse)


def _planar3(c):
    s = c.settings.system
    return s.bodies == 3 and s.dim == 2


def _measured(name, long_name, value=None, dtype="f8", extra=(), symbol=""):
    """A variable an indicator fills (catalog.indicators.OWNER names it): in finished cells
    of the configs that compute that indicator; by default the indicator result's field of
    the same name."""
    value = value or (lambda r: getattr(r.indicators, name))
    return Var(name, long_name, value, FINISHED, dtype, extra, when=OWNER[name].computed_in,
               symbol=symbol)


def _ensemble(name, of):
    return _measured(f"{name}_ensemble", f"{of} over the ensemble of the cell's orbit and its "
                                         "perturbed starts: mean, sample standard deviation, "
                                         "5%, 50% and 95% quantiles",
                     extra=("ensemble_statistic",))


def _history(name, of):
    return _measured(f"{name}_history", f"{of} convergence history", extra=("history_time",))


def _reduced_crossing(q):
    return Var(f"crossing_{q}", f"reduced coordinate {q} at each kept section crossing",
               lambda r: getattr(r.reduced, q), extra=("crossing",),
               when=lambda c: _section(c) and _planar3(c))


def _field_crossing(q: str, momentum: bool):
    """The centre of mass's coordinate q (or the total momentum's) at each kept crossing of
    a system in an external field: for one body, its section coordinates (y, p_y on
    Henon-Heiles' x = 0)."""
    axis = "xyz".index(q)
    return Var(f"crossing_{'p_' if momentum else ''}{q}",
               f"{'total momentum p_' if momentum else 'centre of mass '}{q} at each kept "
               "section crossing", lambda r: r.centre[int(momentum)][:, axis],
               extra=("crossing",), symbol=f"p_{q}" if momentum else q,
               when=lambda c: (_section(c) and in_field(c.settings.system)
                               and axis < c.settings.system.dim))


def _pairs(c):
    return c.settings.system.bodies >= 2


def _triangle(c):
    """Three bodies: the paper's measures of their triangle (of more bodies, some triangle
    is nearly always thin -- three atoms in a row of a cluster -- and says nothing)."""
    return c.settings.system.bodies == 3


def _escapes(c):
    """Whether a config's cells watch for escapes (pipeline.build.escape_for)."""
    return c.escape is not None


def _near(name, long_name, at, symbol="", extra=(), when=_triangle):
    """A closest-approach variable: entries `at` (a slice or index) of the cell's record
    (numerics.driver.near_width), kept at step ends up to t_end."""
    return Var(name, long_name, lambda r: r.near[at], extra=extra, when=when,
               symbol=symbol)


VARIABLES = [
    Var("status", "integration outcome of the cell", lambda r: r.status, ALL, "i1",
        flags=Status),
    Var("regime", "regular or chaotic: the verdict of all the evidence", None, ALL, "i1",
        flags=Regime, derived=True, symbol="regime"),
    Var("regime_confidence", "share of the lines of evidence present that support the "
                             "regime", None, ALL, derived=True),
    Var("regime_stable", "1 where the regime is that of the horizon before (the same class: "
                         "regular, irregular or other), else 0", None, ALL, "i1",
        derived=True),
    Var("regime_horizon", "the horizon of the cell's evidence and regime: t_final, or "
                          "k^r t_final where a verdict in doubt was decided again",
        lambda r: r.horizon, STARTED, symbol="horizon"),
    Var("regime_history", "the regime decided at each horizon (at t_final / 2 and t_final "
                          "from the first run, then at the end of each extension; -1 past "
                          "the last)", lambda r: r.verdicts, STARTED, "i1", ("horizon",),
        when=_decided),
    Var("t_end", "time reached by the integration", lambda r: r.t_end),
    Var("energy", "energy H at t = 0", lambda r: r.energy, symbol="$E$"),
    Var("angular_momentum", "total angular momentum at t = 0 (z component in 2-D)",
        lambda r: r.angular_momentum, symbol="$J$"),
    Var("scale_free_energy", "E |J|^(-2k/(k+2)) for a potential homogeneous of degree k: "
                             "the one combination of E and J the shapes' dynamics depends "
                             "on (q -> s q, p -> s^(k/2) p, t -> s^(1-k/2) t)",
        lambda r: r.scale_free_energy, when=lambda c: c.system().homogeneity not in (None, -2.0),
        symbol=r"$E\,|J|^{-2k/(k+2)}$"),
    Var("start_potential", "potential energy U of the start: E minus it is the start's "
                           "kinetic energy, and for starts at an equilibrium (the "
                           "equilibrium family, displacement 0) the height of E above that "
                           "equilibrium, E - E_min: the energy axis of a map over a "
                           "parameter that moves the minimum",
        lambda r: r.start_potential, symbol="$U_0$"),
    Var("energy_error", "max |E(t)/E(0) - 1| over the history times and the end",
        lambda r: r.energy_error, symbol=r"$|\Delta E/E|$"),
    Var("angular_momentum_error", "max |J(t) - J(0)| / max(|J(0)|, 1) over the same times",
        lambda r: r.angular_momentum_error),
    _measured("ftle", "finite-time maximal Lyapunov exponent of the cell's orbit at t_end "
                      "(mean over its deviation vectors)", symbol=r"FTLE $\mu_T$ (1/time)"),
    _ensemble("ftle", "the FTLE"),
    _measured("ensemble_orbits", "orbits in the ensemble statistics (the cell's orbit and "
                                 "its perturbed starts that finished)", dtype="i8"),
    _measured("megno", "mean exponential growth factor of nearby orbits <Y> of the cell's "
                       "orbit at t_end", symbol=r"MEGNO $\langle Y\rangle$"),
    _ensemble("megno", "<Y>"),
    _measured("megno_slope", "least-squares slope d<Y>/dt over the second half of the run "
                             "(about ftle/2 in chaos)"),
    _measured("fli", "fast Lyapunov indicator: max ln(|w|/|w0|) of the first deviation "
                     "vector", symbol="FLI"),
    _measured("sali", "smaller alignment index of two deviation vectors at t_end",
              symbol="SALI"),
    _measured("gali2", "generalized alignment index |w1^ ^ w2^| at t_end",
              symbol=r"GALI$_2$"),
    _measured("ftle_wba", "weighted Birkhoff average of the growth rate d ln|w|/dt of the "
                          "first deviation vector (Sander & Meiss 2025)",
              symbol="WBA growth rate (1/time)"),
    _measured("birkhoff_digits", "weighted Birkhoff digits of convergence at t_end, mean over "
                                 "the observables", lambda r: r.tori.digits,
              symbol="Birkhoff digits"),
    _measured("birkhoff_digits_half", "weighted Birkhoff digits of convergence at t_end / 2, "
                                      "mean over the observables", lambda r: r.tori.digits_half,
              symbol="Birkhoff digits at T/2"),
    _measured("birkhoff_digits_observable", "weighted Birkhoff digits of convergence at t_end "
                                            "of each observable", lambda r: r.tori.digits_each,
              extra=("observable",)),
    _measured("birkhoff_digits_observable_half", "weighted Birkhoff digits of convergence at "
                                                 "t_end / 2 of each observable",
              lambda r: r.tori.digits_each_half, extra=("observable",)),
    _measured("frequency", "fundamental frequency in cycles per unit time, a magnitude (mean "
                           "of the two halves of the orbit)",
              lambda r: r.tori.frequencies.frequency,
              extra=("fundamental",), symbol=r"$\nu$ (cycles/time)"),
    Var("frequency_labelled", "the fundamental frequencies of the regular cells, the shape "
                              "frequencies ordered to continue their grid neighbours' (one "
                              "column follows one frequency through the grid)", None, ALL,
        extra=("fundamental",), derived=True, when=lambda c: c.settings.tori.analyse),
    _measured("frequency_change", "change of each fundamental frequency from the first half "
                                  "of the orbit to the second",
              lambda r: r.tori.frequencies.change, extra=("fundamental",)),
    _measured("frequency_diffusion", "log10 max |nu(second half) - nu(first half)| / max "
                                     "|nu|", lambda r: r.tori.frequencies.diffusion,
              symbol=r"$\log_{10}|\Delta\nu|/|\nu|$"),
    _measured("resonance", "integer vector m of the nearest resonance m . nu = 0 among the "
                           "shape frequencies (0 for the rotation)",
              lambda r: r.tori.frequencies.resonance, "i8", ("fundamental",)),
    _measured("resonance_order", "order |m|_1 of the nearest resonance (-1: none searched)",
              lambda r: r.tori.frequencies.resonance_order, "i8"),
    _measured("resonance_distance", "|m . nu| / (|m| max |nu|) of the nearest resonance",
              lambda r: r.tori.frequencies.resonance_distance),
    _measured("moving_shapes", "shape signals that move (0: the shape stays put -- an "
                               "equilibrium, or a relative equilibrium)",
              lambda r: r.tori.frequencies.moving, "i8"),
    Var("n_steps", "accepted integration steps of the nominal orbit", lambda r: r.n_steps,
        ALL, "i8"),
    Var("n_rhs", "right-hand-side evaluations of the nominal orbit", lambda r: r.n_rhs,
        ALL, "i8"),
    Var("wall_time", "wall-clock time spent on the cell", lambda r: r.wall_time, ALL,
        units="s", reproducible=False),
    Var("initial_state", "phase-space state at t = 0", lambda r: r.start,
        extra=("component",)),
    Var("n_crossings", "crossings of the surface of section (all, also those not kept)",
        lambda r: r.n_crossings, dtype="i8", when=_section),
    Var("crossing_time", "time of each kept section crossing", lambda r: r.crossing_time,
        extra=("crossing",), when=_section),
    *[_reduced_crossing(q) for q in ("sigma", "p_sigma", "eta", "p_eta", "phi", "p_phi")],
    *[_field_crossing(q, momentum) for q in "xyz" for momentum in (False, True)],
    Var("crossing_state", "phase-space state at each kept section crossing",
        lambda r: r.crossing_state, extra=("crossing", "component"),
        when=lambda c: _section(c) and c.settings.section.store_state),
    _near("closest_approach", "least distance of each pair of bodies up to t_end (at step "
                              "ends)", slice(0, -5, 2), "closest approach", ("pair",), _pairs),
    _near("closest_approach_time", "time of each pair's closest approach",
          slice(1, -5, 2), extra=("pair",), when=_pairs),
    _near("least_perimeter", "least perimeter of a triangle of the bodies up to t_end (at "
                             "step ends)", -5, "least perimeter $P_{min}$"),
    _near("least_perimeter_time", "time of the least perimeter", -4),
    _near("least_area", "least |area| of a triangle of the bodies up to t_end (at step "
                        "ends)", -3, r"least area $|A|_{min}$"),
    _near("least_area_time", "time of the least |area|", -2),
    Var("thin_share", "share of the run up to t_end during which a triangle was thin "
                      "(|A|/P^2 below [outcomes] thin times the equilateral's; step ends)",
        lambda r: r.near[-1] / r.t_end if r.t_end > 0 else 0.0, when=_triangle,
        symbol="thin share"),
    Var("escape_time", "time at which a body escaped (NaN: none did)",
        lambda r: np.nan if r.escape is None else r.escape[0], when=_escapes,
        symbol="escape time"),
    Var("escaped_body", "the body that escaped (-1: none)",
        lambda r: -1 if r.escape is None else r.escape[1], dtype="i1",
        when=lambda c: _pairs(c) and _escapes(c)),
    Var("escape_exit", "index of the [outcomes] exit the body escaped through (-1: none)",
        lambda r: -1 if r.escape is None else r.escape[2], dtype="i1",
        when=lambda c: bool(c.settings.outcomes.exits) and _escapes(c)),
    _history("ftle", "FTLE"),
    _history("megno", "<Y>"),
    _history("fli", "FLI"),
    _history("sali", "SALI"),
]
BY_NAME = {v.name: v for v in VARIABLES}
# attribute access to the declared names, so that code outside the catalog never retypes
# one: V.ftle == "ftle" (tests/test_layers.py fails on a name written as a string)
V = SimpleNamespace(**{v.name: v.name for v in VARIABLES})
# figure labels of the grid axes that are not archive variables (family and term
# parameters, coordinates)
# axes along which "where chaos sets in" means nothing: coordinates of a start on the
# section (neighbouring cells are different orbits of one shell, not a family parameter
# growing) and seeds (cells in no order at all)
START_COORDINATES = {"sigma", "p_sigma", "eta", "p_eta", "phi", "theta", "seed", "direction"}


PARAMETER_SYMBOLS = {
    "delta": r"$\delta$", "sigma": r"$\sigma$", "p_sigma": r"$p_\sigma$", "eta": r"$\eta$",
    "p_eta": r"$p_\eta$", "phi": r"$\phi$", "p_phi": r"$p_\phi$", "theta": r"$\theta$",
    "side": "side", "history_time": "t",
    "axilrod_teller_strength": r"triple-dipole strength $Z$",
    "lennard_jones_epsilon": r"$\epsilon$", "lennard_jones_sigma": r"$\sigma_{LJ}$",
}


def label(name: str) -> str:
    """The figure label of an archive variable or grid axis (its name if none is declared)."""
    symbol = BY_NAME[name].symbol if name in BY_NAME else ""
    return symbol or PARAMETER_SYMBOLS.get(name, name)


def history_times(t_final: float, points: int) -> np.ndarray:
    """The time grid of the convergence histories: `points` evenly spaced up to t_final."""
    return np.linspace(t_final / points, t_final, points)


def horizon_factors(extend: int, rounds: int) -> list[float]:
    """The horizons a cell's verdict may be decided at, in units of t_final: 1/2 and 1 from
    the first run, then k, k^2, ... for each extension round (none if extend = 0)."""
    return [0.5, 1.0] + ([float(extend) ** r for r in range(1, rounds + 1)] if extend else [])


def history_grid(t_final: float, points: int, extend: int, rounds: int) -> np.ndarray:
    """The archive's history times: `points` per t_final, up to the longest horizon, so
    that a run to any horizon fills a prefix of it."""
    longest = int(horizon_factors(extend, rounds)[-1])
    return history_times(t_final * longest, points * longest)


OBSERVABLES = {
    "perimeter": "sum of all pair distances (the perimeter for three bodies)",
    "inertia": "moment of inertia about the centre of mass",
    "x": "the centre of mass's x (one body's, in an external field)",
    "y": "the centre of mass's y",
    "z": "the centre of mass's z (3-D)",
}


def default_observables(n_bodies: int, dim: int, field: bool) -> list[str]:
    """The Birkhoff observables a survey takes unless told: the shape's (perimeter,
    inertia) of a free system; in an external field the centre of mass's coordinates, and
    the shape's too where there is one."""
    shape = ["perimeter", "inertia"] if n_bodies > 1 else []
    return shape + ["x", "y", "z"][:dim] if field else shape


def in_field(system_table) -> bool:
    """Whether a [system] table (records.SystemTable) has an external term."""
    return any(t.get("kind") == "external" for t in system_table.interactions or [])


def shape_dof(n_bodies: int, dim: int, field: bool = False) -> int:
    """Degrees of freedom of the shape: N d minus translations and rotations (3 for three
    bodies in the plane or in space); in an external field, which fixes neither, all N d
    (2 for Henon-Heiles)."""
    return n_bodies * dim if field else n_bodies * dim - dim - dim * (dim - 1) // 2


def fundamental_names(n_bodies: int, dim: int, field: bool = False) -> list[str]:
    """The frequencies stored per cell: a basis of shape frequencies (in a field, of the
    motion's N d degrees of freedom), and for three free bodies in the plane the rotation
    frequency of theta."""
    return [f"shape_{k + 1}" for k in range(shape_dof(n_bodies, dim, field))] + \
        (["rotation"] if (n_bodies, dim) == (3, 2) and not field else [])
