"""Single orbits: family members integrated with a tangent vector and sampled densely, what
they conserved, the ranges of their shape and their closest approaches, and orbit workflow
files (their figures: survey.presentation.orbit_plots).

An orbit workflow is a TOML file of [[orbit]] tables, each naming a family member and the
figures to draw:

    [[orbit]]
    name = "sides"              # figures are written as NAME_paths.png, ...
    family = "sides"
    params = {}                 # family parameters; one of them may be a list: a set of orbits
    potential = "perimetric_power"
    potential_params = {}
    # or, instead of potential/potential_params, any survey [system] table:
    # system = {masses = [1.0, 0.001, 0.0001], interactions = [...]}
    t_final = 500.0
    zoom_until = 20.0           # paths and side lengths shown for t <= this (P, A: all)

A survey config is an orbit set too: `python -m survey orbit grid.toml --cell K` integrates
cell K of its grid with its [system] and [initial] (see `from_survey_config`).

A workflow may also hold [[plane]] tables: sections of the isosceles plane
(numerics.isosceles), several orbits of one energy each drawn as the points where its
height crosses a level upwards:

    [[plane]]
    name = "isosceles_perimetric"    # written as NAME_plane.png
    potential = "perimetric_power"   # (or system = {...}, three unit masses in the plane)
    energy = 1.0
    height = 0.0                     # the section h = height
    starts = [[0.69, 0.0], [0.1, 0.75]]   # (b, p_b) on it, p_h > 0 from the energy
    crossings = 400                  # points per orbit, at most
    t_final = 2000.0
    periodic = [[0.0, 0.7], [0.18, 0.0, 2]]   # guesses (b, p_b[, k]) of periodic orbits
    #   with k points on the section (default 1), found by Newton's method on the
    #   section map and marked with their stability (numerics.isosceles.plane_periodic)
    manifolds = [[0.57, 0.0]]        # guesses of hyperbolic orbits whose stable and
    manifold_length = 3.0            #   unstable manifolds are grown (numerics.manifolds)
    manifold_gap = 0.02              #   to this arclength, points at most this far apart,
    #   drawn on the section and archived in NAME_plane.nc (python -m survey verify)
"""
from __future__ import annotations

import math
import sys
import time
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..analysis.findings import to_accuracy
from ..catalog import defaults
from ..catalog.errors import ConfigError
from ..catalog.variables import V
from ..machine import portable
from ..numerics.dop853 import RTOL_MIN
from ..numerics.driver import compile_round
from ..numerics.indicators import deviation_vectors
from ..numerics.integrate import Outcome, integrate
from ..numerics.isosceles import (
    PlaneManifolds,
    PlaneOrbit,
    PlaneSection,
    eigen2,
    plane_manifolds,
    plane_periodic,
    plane_section,
    plane_start,
    plane_state,
)
from ..physics.families import FAMILIES
from ..physics.geometry import area, sides
from ..physics.system import System
from ..physics.terms import PERIMETER, POWER
from .build import section_event_for
from .cells import build_starts, compiled_beside
from .config import Config, load_config, read_toml
from .progress import COMPILING, notice
from .resources import check_bytes
from .schema import Key

MAX_ORBITS = 8          # more cells than this in one orbit set: pick one with --cell


@dataclass(frozen=True)
class OrbitSpec:
    name: str
    family: str
    params: dict = field(default_factory=dict)
    potential: str = defaults.POTENTIAL
    potential_params: dict = field(default_factory=dict)
    system: dict | None = None   # a survey [system] table, instead of potential/_params
    t_final: float = defaults.ORBIT_T_FINAL
    tol: float = defaults.RTOL
    zoom_until: float = 0.0      # paths and sides for t <= this (0: the whole run)
    samples: int = 20001
    cells: tuple = ()            # the cells of the set to integrate (empty: all)

    def tables(self) -> dict:
        """The spec as the survey config tables that say the same (a list parameter is a
        grid axis: one orbit per value)."""
        system = self.system if self.system is not None else \
            {"potential": self.potential, "params": dict(self.potential_params)}
        return {"survey": {"name": "orbit"}, "system": system,
                "initial": {"family": self.family, **self.params},
                "integration": {"t_final": self.t_final, "rtol": self.tol, "atol": self.tol}}

    def config(self) -> Config:
        """The validated config of the spec (ConfigError naming the key otherwise)."""
        return load_config(self.tables(), check_output=False)


def check(spec: OrbitSpec, where: str = "orbit", cli: bool = False) -> OrbitSpec:
    """A ConfigError naming the key (the command-line option if cli) for anything that
    would fail later: the spec's own keys here, the system and the family's parameters by
    the survey config's checks (their keys renamed to the spec's)."""
    def key_name(key):
        return f"--{key.replace('_', '-')}" if cli else f"{where}.{key}"
    for key in ("t_final", "tol", "zoom_until"):
        value = getattr(spec, key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value):
            raise ConfigError(key_name(key), f"must be a finite number{' > 0' * (key == 't_final')}"
                                             f", got {value!r}")
    if spec.zoom_until < 0:
        raise ConfigError(key_name("zoom_until"), f"must be >= 0 (0: no zoom), got "
                                                  f"{spec.zoom_until!r}")
    if spec.system is not None and (spec.potential != defaults.POTENTIAL
                                    or spec.potential_params):
        raise ConfigError(key_name("system"), "give either system or potential/"
                                              "potential_params, not both")
    def spec_error(exc):
        return ConfigError(_spec_key(exc.key, key_name, cli, spec.system is not None),
                           str(exc).split(": ", 1)[1])

    try:
        config = spec.config()
    except ConfigError as exc:
        raise spec_error(exc) from None
    cells = spec.cells or tuple(range(config.n_cells))
    if len(cells) > MAX_ORBITS:
        raise ConfigError("--cell" if cli else key_name("params"),
                          f"{config.n_cells} orbits is too many for one orbit set (at most "
                          f"{MAX_ORBITS}); pick cells with --cell K (0..{config.n_cells - 1})")
    n = config.system().n
    check_bytes(len(cells) * spec.samples * 8 * (3 * n + 4),   # states, tangents, shapes
                "--cell" if cli else key_name("params"), f"{len(cells)} orbits of {n} "
                f"components sampled {spec.samples} times", "integrate fewer bodies")
    bad = [c for c in cells if not 0 <= c < config.n_cells]
    if bad:
        raise ConfigError("--cell", f"{bad[0]} is not a cell of the grid (0.."
                                    f"{config.n_cells - 1})")
    try:        # the chosen cells' only: a grid of millions of cells has one picked
        starts = build_starts(config, cells)
    except ConfigError as exc:
        raise spec_error(exc) from None
    if np.all(np.isnan(starts[:, 0])):
        raise ConfigError(key_name("params"), "no start exists there (inaccessible: the "
                                              "potential energy exceeds the energy)")
    return spec


def _spec_key(key: str, key_name, cli: bool, system_table: bool) -> str:
    """A survey config's key as the orbit spec (or the command line) spells it."""
    table, _, rest = key.partition("].")
    table += "]" if rest else ""
    if table == "[integration]":
        return key_name("tol" if rest in ("rtol", "atol") else rest)
    if cli:
        flags = {"[initial]": "--family" if rest == "family" else f"--param {rest}",
                 "[system.params]": f"--potential-param {rest}",
                 "[system]": "--masses" if rest in ("masses", "bodies") else "--potential"}
        return flags.get(table, key)
    if table == "[initial]":
        return key_name("family" if rest == "family" else f"params.{rest}")
    if table.startswith("[system"):
        return key_name(("system." if system_table else "potential_params.") + rest
                        if rest and (system_table or table == "[system.params]") else
                        "system" if system_table else "potential")
    return key


def from_survey_config(path, cells=(), t_final=None, zoom_until=0.0) -> OrbitSpec:
    """The orbits of a survey config's cells (all if `cells` is empty), with its [system],
    [initial] and tolerance; t_final its own unless given."""
    return from_config(load_config(path, check_output=False), cells, t_final, zoom_until)


def from_config(config: Config, cells=(), t_final=None, zoom_until=0.0) -> OrbitSpec:
    """`from_survey_config` of a loaded config (an archive's stored one: survey explore)."""
    raw = tomllib.loads(config.text)
    initial = dict(raw.get("initial", {}))
    integration = config.settings.integration
    spec = OrbitSpec(name=config.name, family=initial.pop("family"), params=initial,
                     system=raw.get("system", {}),
                     t_final=integration.t_final if t_final is None else t_final,
                     tol=integration.rtol, zoom_until=zoom_until, cells=tuple(cells))
    return check(spec, "orbit", cli=True)


def p_max(system: System, E: float, J: float) -> float | None:
    """The largest perimeter an orbit of energy E and angular momentum J can reach under
    U = c P^2/2 with unit masses: E >= J^2/(2I) + c P^2/2 and I <= P^2/6 give
    P^2 <= (E + sqrt(E^2 - 6 c J^2)) / c. (The paper's I >= P^2/9 bounds the wrong way.)
    None for other systems."""
    if not system.is_paper_kind:
        return None
    pot = system.potential
    if pot.measure != PERIMETER or pot.profile != POWER or pot.params[1] != 2.0 or \
            not np.all(system.masses == 1.0) or system.n_bodies != 3:
        return None
    c = pot.params[0]
    disc = E * E - 6 * c * J * J
    return math.sqrt((E + math.sqrt(disc)) / c) if disc >= 0 else None


class OrbitRun(NamedTuple):
    """One integrated orbit of a spec: its parameters, system, start, outcome (sampled at
    `samples` times), wall time, and the perimeter bound P_max where one is known."""

    params: dict
    system: System
    y0: np.ndarray
    outcome: Outcome
    wall: float
    p_max: float | None
    section: object = None       # the surface its crossings are of (section_of), or None

    @property
    def label(self) -> str:
        return ", ".join(f"{k} = {v:g}" for k, v in self.params.items()
                         if isinstance(v, (int, float)))


def section_of(config: Config):
    """The surface whose crossings an orbit records (records.SectionTable): the config's
    [section]; for three bodies in the plane without one, the paper's phi = pi/2 crossed
    with phi increasing; else None."""
    settings = config.settings
    if settings.section_enabled:
        return settings.section
    system = config.system()
    if system.n_bodies == 3 and system.dim == 2:
        return replace(settings.section, coordinate="phi", value=math.pi / 2, direction=1)
    return None


def section_text(section) -> str:
    way = {1: "increasing", -1: "decreasing", 0: "either way"}[section.direction]
    return f"{section.coordinate} = {section.value:.6g} ({way})"


def run_orbits(spec: OrbitSpec) -> list[OrbitRun]:
    """Every orbit of a spec (one per cell of its set), each with one tangent vector and its
    MEGNO, both sampled at `samples` times, and its crossings of `section_of` its config; a
    cell without a start is skipped."""
    config = spec.config()
    section = section_of(config)
    cells = spec.cells or range(config.n_cells)
    t_eval = np.linspace(0.0, spec.t_final, spec.samples)
    runs = []
    for cell, y0 in zip(cells, build_starts(config, cells)):
        if np.isnan(y0[0]):
            continue
        system = config.system(cell)
        w0 = deviation_vectors(system, y0, 1, seed=0)[0]
        events = () if section is None else (section_event_for(section, system),)
        kw = dict(tangents=w0, megno=True, sample_tangents=True, events=events)

        def first():
            integrate(system, y0, 1e-3, t_eval=t_eval[:1], **kw)

        with notice(COMPILING, sys.stderr.isatty(), compiling=True), \
                compiled_beside(_warm, first, system, y0):     # load the kernels
            first()
        start = time.perf_counter()
        out = integrate(system, y0, spec.t_final, t_eval=t_eval, rtol=spec.tol, atol=spec.tol,
                        **kw)
        wall = time.perf_counter() - start
        params = {**config.cell_parameters(cell), **config.axis_values(cell, terms=True)}
        params = {k: v for k, v in params.items()          # as given, and the grid's
                  if k in spec.params or k in {a.name for a in config.axes}}
        bound = p_max(system, system.energy(y0), float(np.sum(system.angular_momentum(y0))))
        runs.append(OrbitRun(params, system, y0, out, wall, bound, section))
    return runs


def _warm(first, system, y0):
    """`run_orbits`' helper on a first run (cells.compiled_beside): the stepping round of
    the orbit's first integration, then what the command compiled after it -- the
    restored samples' angles, their energies and moments of inertia (`describe`) -- on
    copies of the start."""
    compile_round(first, False, True)
    states = np.repeat(y0[None], 4, 0)
    system.energy(states)
    system.moment_of_inertia(states)
    x = np.linspace(0.1, 1.0, 4)
    portable.vatan2(x, x)
    portable.vsin(x)


def describe(spec: OrbitSpec, run: OrbitRun) -> list[str]:
    """What to print about one orbit: E, J, conservation, steps, its Lyapunov exponent,
    the ranges of P, |A| and I, and each pair's closest approach."""
    system, y0, out, wall = run.system, run.y0, run.outcome, run.wall
    done = ~np.isnan(out.samples[:, 0])
    s, t = out.samples[done, :system.n], out.t_eval[done]
    E0, J0 = system.energy(y0), system.angular_momentum(y0)
    J_text = (f"{J0:.10g}" if system.dim == 2 else
              "(" + ", ".join(f"{c:.6g}" for c in J0) + ")")
    dJ = np.abs(system.angular_momentum(s) - J0).max()
    lines = [f"{spec.family}{' (' + run.label + ')' if run.label else ''} with "
             f"{system.describe()}, masses {system.masses.tolist()}",
             f"E = {E0:.10g}, J = {J_text}; integrated to t = {out.t:g}: {out.status.name}, "
             f"{out.n_steps} steps, {out.n_rhs} RHS evaluations, {wall:.2f} s",
             f"max |E/E0 - 1| = {np.abs(system.energy(s) / E0 - 1).max():.2e}, "
             f"max |J - J0| = {dJ:.2e}, "
             f"max |p_total| = {np.abs(system.momentum(s)).max():.2e}",
             f"finite-time Lyapunov exponent ln(|w(t)|/|w0|)/t = "
             f"{out.log_growth[0] / out.t:.5f}"
             + (f", MEGNO {out.megno_sums[1] / out.t:.5g}" if out.t > 0 else "")]
    if run.section is not None:
        lines.append(f"{out.n_crossings} crossings of the section {section_text(run.section)}")
    lines += shape_ranges(system, t, s)
    bound = run.p_max
    if bound is not None:
        lines.append(f"P_max = sqrt(E + sqrt(E^2 - 6 J^2)) = {bound:.6g} (Hill-type disk "
                     f"radius {bound / 3:.6g})")
    return lines


def shape_ranges(system: System, t, states) -> list[str]:
    """The ranges of the perimeter P and area |A| (three bodies) and of the moment of
    inertia I over the samples, and each pair's closest approach with its time (the
    smallest sampled distance, refined by a parabola through its neighbours)."""
    q, _ = system.split(states)
    out = []
    if system.n_bodies == 3:
        u, v, w = q[:, 0], q[:, 1], q[:, 2]
        P = sides(u, v, w).sum(axis=1)
        A = np.abs(area(u, v, w)) if system.dim == 2 else np.linalg.norm(area(u, v, w), axis=1)
        out.append(f"P in [{P.min():.6g}, {P.max():.6g}], |A| in [{A.min():.6g}, "
                   f"{A.max():.6g}]")
    inertia = system.moment_of_inertia(states)
    out.append(f"I in [{inertia.min():.6g}, {inertia.max():.6g}] (about the centre of mass); "
               f"sampled every {t[1] - t[0]:.3g} time units" if t.size > 1 else "")
    approaches = []
    for i in range(system.n_bodies - 1):
        for j in range(i + 1, system.n_bodies):
            r = np.linalg.norm(q[:, j] - q[:, i], axis=-1)
            tk, rk = closest(t, r)
            approaches.append(f"{i}-{j}: {rk:.4g} at t = {tk:.6g}")
    out.append("closest approaches: " + "; ".join(approaches))
    return [line for line in out if line]


def closest(t, r) -> tuple[float, float]:
    """Time and value of the minimum of samples r(t), refined by the parabola through the
    smallest sample and its neighbours (equally spaced times)."""
    k = int(np.argmin(r))
    if 0 < k < r.size - 1:
        a, b, c = r[k - 1], r[k], r[k + 1]
        curvature = a - 2 * b + c
        if curvature > 0:
            shift = 0.5 * (a - c) / curvature
            dt = t[k + 1] - t[k]
            return float(t[k] + shift * dt), float(b - 0.25 * (a - c) * shift)
    return float(t[k]), float(r[k])


ORBIT_KEYS = {      # an [[orbit]] table's keys (OrbitSpec's fields; the docs' reference)
    "name": Key("str", None, "names the figure files NAME_paths.png, ... (required; a plain "
                             "file name)"),
    "family": Key("str", None, "initial-condition family (required)", choices=tuple(FAMILIES)),
    "params": Key("table", {}, "family parameters; one of them may be a list: a set of "
                               "orbits, drawn together"),
    "potential": Key("str", defaults.POTENTIAL, "triplet potential, as [system] potential"),
    "potential_params": Key("table", {}, "its parameters, as [system] params"),
    "system": Key("table", None, "any survey [system] table instead of potential/"
                                 "potential_params (masses, interactions, ...)"),
    "t_final": Key("float", defaults.ORBIT_T_FINAL, "end time", "time", above=0),
    "tol": Key("float", defaults.RTOL, "rtol = atol of the integration", low=RTOL_MIN),
    "zoom_until": Key("float", 0.0, "paths and side lengths drawn for t <= this (P, |A| "
                                    "and inequities: the whole run); 0: no zoom", "time",
                      low=0),
    "samples": Key("int", 20001, "dense-output samples of the orbit the figures draw", low=2),
    "cells": Key("ints", (), "the orbits of the set to integrate (default all; `orbit "
                               "--cell K` for a survey config)", low=0),
}


@dataclass(frozen=True)
class PlaneSpec:
    """A section of the isosceles plane: orbits of one energy from starts (b, p_b) on the
    section h = height, each drawn as its upward crossings of it."""

    name: str
    energy: float
    starts: tuple
    height: float = 0.0
    potential: str = defaults.POTENTIAL
    potential_params: dict = field(default_factory=dict)
    system: dict | None = None
    t_final: float = 2000.0
    crossings: int = 500
    tol: float = 1e-13
    periodic: tuple = ()        # guesses (b, p_b, k) of periodic orbits
    manifolds: tuple = ()       # guesses (b, p_b, k) of hyperbolic ones: their manifolds
    manifold_length: float = 3.0
    manifold_gap: float = 0.02

    def build(self) -> System:
        """The system (ConfigError naming the key if it is not one)."""
        table = self.system if self.system is not None else \
            {"potential": self.potential, "params": dict(self.potential_params)}
        return load_config({"system": table, "initial": {"family": "isosceles"}},
                           check_output=False).system()


PLANE_KEYS = {      # a [[plane]] table's keys (PlaneSpec's fields; the docs' reference)
    "name": Key("str", None, "names the figure NAME_plane.png and archive NAME_plane.nc "
                             "(required)"),
    V.energy: Key("float", None, "the energy of every orbit (required)"),
    "starts": Key("table", None, "[[b, p_b], ...]: starts on the section, p_h > 0 from the "
                                 "energy (required)"),
    "height": Key("float", 0.0, "the section h = height, crossed upwards", "length"),
    "potential": Key("str", defaults.POTENTIAL, "triplet potential, as [system] potential"),
    "potential_params": Key("table", {}, "its parameters, as [system] params"),
    "system": Key("table", None, "a survey [system] table instead (three unit masses in "
                                 "the plane)"),
    "t_final": Key("float", 2000.0, "longest time each orbit runs", "time", above=0),
    "crossings": Key("int", 500, "section points per orbit, at most", low=1),
    "tol": Key("float", 1e-13, "rtol = atol", low=RTOL_MIN, high=1e-3),
    "periodic": Key("table", (), "[[b, p_b], [b, p_b, k], ...]: guesses of periodic orbits "
                                 "with k points on the section (default 1), found by Newton's "
                                 "method on the section map and marked with their stability"),
    "manifolds": Key("table", (), "guesses like periodic of hyperbolic orbits whose stable "
                                  "and unstable manifolds are grown, drawn and archived"),
    "manifold_length": Key("float", 3.0, "arclength each manifold branch is grown to",
                           low=1e-3, high=1e3),
    "manifold_gap": Key("float", 0.02, "largest distance between neighbouring points of a "
                                       "branch", low=1e-4, high=1.0),
}


# bytes an orbit of the plane holds per section crossing while it runs (its state, time
# and index in the integrator's event buffer; b, p_b, t as Python floats), and a
# tolerance looser than an orbit's figures can show
CROSSING_BYTES = 8 * 15 + 3 * 32
TOL_MAX = 1e-3


def check_name(name, key: str):
    """A figure's name, which names its files in --plot DIR: a plain file name."""
    if not isinstance(name, str) or not name.strip() or name in (".", "..") or \
            any(c in name for c in "/\\") or any(ord(c) < 32 for c in name):
        raise ConfigError(key, f"{name!r} is not a usable name: it names the figure files "
                               "in the --plot folder, so no path separators, control "
                               "characters or '..'; e.g. name = \"sides\"")


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_plane(table: dict, where: str) -> PlaneSpec:
    """A [[plane]] table as a PlaneSpec, every key checked before any work."""
    extra = sorted(set(table) - set(PLANE_KEYS))
    if extra:
        raise ConfigError(f"{where}.{extra[0]}", f"unknown key; keys are "
                                                 f"{', '.join(sorted(PLANE_KEYS))}")
    for key in ("name", V.energy, "starts"):
        if key not in table:
            raise ConfigError(f"{where}.{key}", "is required")
    check_name(table["name"], f"{where}.name")
    if "system" in table and ({"potential", "potential_params"} & set(table)):
        raise ConfigError(f"{where}.system", "give either system or potential/"
                                             "potential_params, not both")
    for key, low, high in ((V.energy, None, None), ("height", None, None),
                           ("t_final", 0.0, None), ("tol", RTOL_MIN, TOL_MAX),
                           ("manifold_length", 1e-3, 1e3), ("manifold_gap", 1e-4, 1.0)):
        value = table.get(key, getattr(PlaneSpec, key, None))
        if not _finite(value) or (low is not None and not value >= low) or \
                (high is not None and not value <= high) or (key == "t_final" and value <= 0):
            raise ConfigError(f"{where}.{key}", f"must be a finite number"
                                                f"{f' >= {low:.3g}' if low else ''}"
                                                f"{f' and <= {high:g}' if high else ''}"
                                                f"{' > 0' if key == 't_final' else ''}, got "
                                                f"{value!r}")
    crossings = table.get("crossings", PlaneSpec.crossings)
    if isinstance(crossings, bool) or not isinstance(crossings, int) or crossings < 1:
        raise ConfigError(f"{where}.crossings", f"must be an integer >= 1, got {crossings!r}")
    starts = table["starts"]
    if not isinstance(starts, list) or not starts or not all(
            isinstance(x, list) and len(x) == 2 and all(map(_finite, x)) for x in starts):
        raise ConfigError(f"{where}.starts", "expected a list of [b, p_b] pairs of finite "
                                             "numbers, e.g. [[0.69, 0.0], [0.1, 0.75]]")
    for key in ("periodic", "manifolds"):
        guesses = table.get(key, [])
        if not isinstance(guesses, list) or not all(
                isinstance(x, list) and len(x) in (2, 3) and all(map(_finite, x[:2])) and (
                    len(x) == 2 or (
                        isinstance(x[2], int) and not isinstance(x[2], bool) and x[2] >= 1))
                for x in guesses):
            raise ConfigError(f"{where}.{key}", "expected a list of guesses [b, p_b] or "
                                                "[b, p_b, k] (k >= 1 points on the section), "
                                                "e.g. [[0.0, 0.7], [0.18, 0.0, 2]]")

    def guesses(key):
        return tuple((float(x[0]), float(x[1]), int(x[2]) if len(x) > 2 else 1)
                     for x in table.get(key, []))
    spec = PlaneSpec(**{**table, "starts": tuple((float(b), float(p)) for b, p in starts),
                        "periodic": guesses("periodic"), "manifolds": guesses("manifolds")})
    most = max([crossings] + [k for _, _, k in spec.periodic + spec.manifolds])
    check_bytes(most * CROSSING_BYTES + crossings * len(starts) * 24,
                f"{where}.crossings" if most == crossings else f"{where}.periodic",
                f"{most:,} crossings of the section", "ask for fewer")
    try:
        system = spec.build()
    except ConfigError as exc:
        raise ConfigError(f"{where}.{'system' if spec.system is not None else 'potential'}",
                          str(exc).split(": ", 1)[1]) from None
    if system.n_bodies != 3 or system.dim != 2 or not np.all(system.masses == 1.0):
        raise ConfigError(f"{where}.system", "the isosceles plane is of three unit masses in "
                                             "the plane")
    for key, points in (("starts", spec.starts), ("periodic", spec.periodic),
                        ("manifolds", spec.manifolds)):
        for k, (b, p_b, *_) in enumerate(points):
            if plane_start(system, spec.energy, spec.height, b, p_b) is None:
                raise ConfigError(f"{where}.{key}[{k}]", f"(b, p_b) = ({b:g}, {p_b:g}) is not "
                                  f"on the section h = {spec.height:g} of the energy shell "
                                  f"E = {spec.energy:g}: the potential there exceeds "
                                  f"E - p_b^2")
    return spec


class PlaneRun(NamedTuple):
    """The orbits of a PlaneSpec: their sections, the shell's edge on the section (b and
    the largest |p_b| there), the periodic orbits found from its guesses (one per guess,
    converged or not), the manifolds of those asked for (an orbit Newton did not find or
    found elliptic stands alone) and what the run cost."""

    system: System
    sections: list[PlaneSection]
    edge: tuple[np.ndarray, np.ndarray]
    wall: float
    periodic: list[PlaneOrbit]
    manifolds: list = []          # PlaneManifolds, or the PlaneOrbit that has none


def run_plane(spec: PlaneSpec) -> PlaneRun:
    system = spec.build()
    with notice(COMPILING, sys.stderr.isatty(), compiling=True):     # load the kernels
        plane_section(system, plane_start(system, spec.energy, spec.height,
                                          *spec.starts[0]), 1e-3, spec.height, 1)
    clock = time.perf_counter()
    sections = [plane_section(system, plane_start(system, spec.energy, spec.height, b, p_b),
                              spec.t_final, spec.height, spec.crossings, spec.tol, spec.tol)
                for b, p_b in spec.starts]
    periodic = [plane_periodic(system, spec.energy, spec.height, (b, p_b), k, spec.t_final,
                               rtol=spec.tol) for b, p_b, k in spec.periodic]
    manifolds = spec_manifolds(spec, system)
    wall = time.perf_counter() - clock
    reach = max(max(abs(b) for b, _ in spec.starts), 1e-3)
    while plane_start(system, spec.energy, spec.height, 2 * reach, 0.0) is not None:
        reach *= 2                                 # the shell's extent in b, bracketed
    b = np.linspace(-2 * reach, 2 * reach, 2001)
    room = spec.energy - system.potential_energy(
        np.array([plane_state(x, spec.height, 0.0, 0.0) for x in b]))
    edge = np.where(room > 0, np.sqrt(np.maximum(room, 0.0)), np.nan)
    return PlaneRun(system, sections, (b, edge), wall, periodic, manifolds)


def spec_manifolds(spec: PlaneSpec, system: System) -> list:
    """For each of the spec's `manifolds` guesses: the orbit Newton finds there and, if it
    is hyperbolic, its manifolds (numerics.isosceles.plane_manifolds)."""
    out = []
    for b, p_b, k in spec.manifolds:
        orbit = plane_periodic(system, spec.energy, spec.height, (b, p_b), k, spec.t_final,
                               rtol=spec.tol)
        out.append(plane_manifolds(system, spec.energy, spec.height, orbit,
                                   spec.manifold_length, spec.manifold_gap, spec.t_final,
                                   spec.tol)
                   if orbit.converged and orbit.kind != "elliptic" else orbit)
    return out


def describe_plane(spec: PlaneSpec, run: PlaneRun) -> list[str]:
    lines = [f"{spec.name}: the isosceles plane under {run.system.describe()}, E = "
             f"{spec.energy:g}, section h = {spec.height:g} crossed upwards; "
             f"{len(run.sections)} orbits in {run.wall:.1f} s"]
    for (b, p_b), sec in zip(spec.starts, run.sections):
        lines.append(f"  from (b, p_b) = ({b:g}, {p_b:g}): {sec.b.size} crossings to t = "
                     f"{sec.t_end:g} ({sec.status.name}), {sec.passages} passages through b = "
                     f"0, |E/E0 - 1| = {sec.energy_error:.1e}")
    seen = []
    for (b, p_b, k), orbit in zip(spec.periodic, run.periodic):
        lines.append(f"  periodic orbit from the guess ({b:g}, {p_b:g}), k = {k}: "
                     + describe_periodic(orbit, seen))
        seen.append(orbit)
    for (b, p_b, k), found in zip(spec.manifolds, run.manifolds):
        lines += describe_manifolds(found, f"  manifolds from the guess ({b:g}, {p_b:g}), "
                                           f"k = {k}: ")
    return lines


def describe_manifolds(found, head: str) -> list[str]:
    """Lines on a hyperbolic orbit's manifolds: each branch's extent and points, and the
    first homoclinic points with the digits their accuracy supports."""
    if not isinstance(found, PlaneManifolds):
        what = describe_periodic(found) if not found.converged else \
            f"the orbit there is {found.kind}: it has no stable and unstable manifolds"
        return [head + what]
    orbit = found.orbit
    lines = [head + f"of the {orbit.kind} orbit at ({orbit.b[0] + 0.0:.8f}, {round(orbit.p_b[0], 8) + 0.0:.8f}) "
                    f"(multiplier {eigen2(orbit.jacobian)[0][0]:.6g})"]
    for branch in found.branches:
        lines.append(f"    {branch.kind} {'+' if branch.side > 0 else '-'}: "
                     f"{branch.points.shape[0]} points to arclength "
                     f"{branch.arclength[-1]:.3g}, {branch.level.max()} iterates of its "
                     f"fundamental domain"
                     + ("" if branch.resolved else "; stopped short (point budget)"))
    for h in found.homoclinic:
        u, s = (found.branches[i] for i in (h.unstable, h.stable))
        lines.append(f"    first crossing of unstable {'+' if u.side > 0 else '-'} and stable "
                     f"{'+' if s.side > 0 else '-'} (homoclinic): ({to_accuracy(h.point[0], h.accuracy)}, "
                     f"{to_accuracy(h.point[1], h.accuracy)}) +- {h.accuracy:.0e}, angle "
                     f"{np.degrees(h.angle):.2f} degrees, arclength {h.arclength_unstable:.4f} "
                     f"along the unstable branch")
    if not found.homoclinic:
        lines.append("    no homoclinic crossing within this arclength")
    return lines


def describe_periodic(orbit: PlaneOrbit, seen=()) -> str:
    """One line on a periodic orbit of the plane: where it is, its period, its stability
    and how well Newton's method and the Jacobian did."""
    if not orbit.converged:
        return (f"not found (Newton's residual {orbit.residual:.1e} after "
                f"{orbit.residuals.size} steps, last at ({orbit.b[0]:.6g}, {orbit.p_b[0]:.6g}))")
    same = next((j for j, o in enumerate(seen) if o.same_as(orbit)), None)
    if same is not None:
        return f"the same orbit as guess {same + 1}"
    points = ", ".join(f"({round(b, 8) + 0.0:.8f}, {round(p, 8) + 0.0:.8f})"   # no -0
                       for b, p in zip(orbit.b, orbit.p_b))
    mu = orbit.multipliers
    if orbit.kind == "elliptic":
        nu = np.arccos(np.clip(orbit.trace / 2, -1, 1)) / (2 * np.pi)
        stability = f"elliptic, rotation number {nu:.6f} (trace {orbit.trace:.6f})"
    else:
        lam = float(np.max(np.abs(mu)))
        stability = (f"{orbit.kind}, multipliers {-lam if orbit.trace < 0 else lam:.6g} and "
                     f"its inverse, ln|mu| / T = {np.log(lam) / orbit.period:.4g}")
    return (f"{orbit.crossings} point{'s' if orbit.crossings > 1 else ''} {points}, period "
            f"T = {orbit.period:.10f}, {stability}; |P^k(x) - x| = {orbit.residual:.0e}, "
            f"det J - 1 = {np.linalg.det(orbit.jacobian) - 1:.0e}")



def load_workflow(path) -> list:
    """The [[orbit]] tables (OrbitSpec) and [[plane]] tables (PlaneSpec) of an orbit
    workflow file, checked."""
    raw = read_toml(Path(path).read_text(), str(path))
    tables, planes = raw.get("orbit", []), raw.get("plane", [])
    if not isinstance(tables, list) or not isinstance(planes, list) or not (tables or planes):
        raise ConfigError(str(path), "an orbit workflow needs [[orbit]] or [[plane]] tables")
    specs = [check_plane(table, f"[[plane]] {k + 1}") for k, table in enumerate(planes)]
    for k, table in enumerate(tables):
        where = f"[[orbit]] {k + 1}"
        extra = sorted(set(table) - set(ORBIT_KEYS))
        if extra:
            raise ConfigError(f"{where}.{extra[0]}", f"unknown key; keys are {', '.join(sorted(ORBIT_KEYS))}")
        if "name" not in table or "family" not in table:
            raise ConfigError(where, "needs a name and a family")
        check_name(table["name"], f"{where}.name")
        if "cells" in table:
            raise ConfigError(f"{where}.cells", "unknown key; a list parameter makes a set "
                                                "of orbits")
        specs.append(check(OrbitSpec(**table), where))
    return specs


def is_orbit_workflow(path) -> bool:
    try:
        raw = tomllib.loads(Path(path).read_text())
        return "orbit" in raw or "plane" in raw
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError):
        return False


def plane_text(spec: PlaneSpec) -> str:
    """A [[plane]] table as the TOML text its archive stores (a [plane] table of every
    key, defaults included), from which `verify` computes it again."""
    from dataclasses import asdict

    from .config import _to_toml

    def plain(v):
        return [plain(x) for x in v] if isinstance(v, (tuple, list)) else v
    table = {k: plain(v) for k, v in asdict(spec).items() if v is not None}
    return _to_toml({"plane": table})
