"""Single orbits: one family member integrated with a tangent vector and sampled densely, what
it conserved, and orbit workflow files (their figures: survey.presentation.orbit_plots).

An orbit workflow is a TOML file of [[orbit]] tables, each naming a family member and the
figures to draw:

    [[orbit]]
    name = "sides"              # figures are written as NAME_paths.png, ...
    family = "sides"
    params = {}                 # family parameters; one of them may be a list: a set of orbits
    potential = "perimetric_power"
    potential_params = {}
    t_final = 500.0
    zoom_until = 20.0           # paths and side lengths shown for t <= this (P, A: all)
"""
from __future__ import annotations

import math
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..catalog import defaults
from ..catalog.errors import ConfigError
from ..numerics.dop853 import RTOL_MIN
from ..numerics.indicators import deviation_vectors
from ..numerics.integrate import Outcome, integrate
from ..physics.families import family_parameters, initial_state
from ..physics.system import System
from ..physics.terms import PERIMETER, POWER
from .progress import COMPILING, notice


@dataclass(frozen=True)
class OrbitSpec:
    name: str
    family: str
    params: dict = field(default_factory=dict)
    potential: str = defaults.POTENTIAL
    potential_params: dict = field(default_factory=dict)
    t_final: float = defaults.ORBIT_T_FINAL
    tol: float = defaults.RTOL
    zoom_until: float = 0.0      # paths and sides for t <= this (0: the whole run)
    samples: int = 20001

    def system(self) -> System:
        return System.create(potential=self.potential, **self.potential_params)


def check(spec: OrbitSpec, where: str = "orbit", cli: bool = False) -> OrbitSpec:
    """A ConfigError naming the key (the command-line option if cli) for anything that
    would fail later."""
    def key_name(key):
        return f"--{key.replace('_', '-')}" if cli else f"{where}.{key}"
    for key in ("t_final", "tol", "zoom_until"):
        value = getattr(spec, key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value):
            raise ConfigError(key_name(key), f"must be a finite number{' > 0' * (key == 't_final')}"
                                             f", got {value!r}")
    if spec.t_final <= 0:
        raise ConfigError(key_name("t_final"), f"must be a finite number > 0, got "
                                               f"{spec.t_final!r}")
    if not RTOL_MIN <= spec.tol < 1:
        raise ConfigError(key_name("tol"), f"must be in [{RTOL_MIN:.2g}, 1) (double "
                                           f"precision cannot honour less), got {spec.tol!r}")
    for key, value in spec.params.items():
        values = value if isinstance(value, list) else [value]
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                   for v in np.ravel(np.asarray(values, dtype=object))):
            raise ConfigError(f"{where}.params.{key}", f"must be finite numbers, got {value!r}")
    try:
        for params in expand(spec):
            initial_state(spec.system(), spec.family, **params)
    except ValueError as exc:
        raise ConfigError(where, str(exc)) from None
    return spec


def expand(spec: OrbitSpec) -> list[dict]:
    """The parameter sets of a spec: one, or one per value of its (single) list parameter
    (a list of numbers; vector parameters are lists of numbers too, told apart by the
    family's default)."""
    defaults = family_parameters(spec.family)
    lists = [k for k, v in spec.params.items()
             if isinstance(v, list) and isinstance(defaults.get(k), (int, float))]
    if not lists:
        return [dict(spec.params)]
    if len(lists) > 1:
        raise ConfigError(f"params.{lists[1]}", "only one parameter may be a list")
    key = lists[0]
    return [{**spec.params, key: v} for v in spec.params[key]]


def p_max(system: System, E: float, J: float) -> float | None:
    """The largest perimeter an orbit of energy E and angular momentum J can reach under
    U = c P^2/2 with unit masses: E >= J^2/(2I) + c P^2/2 and I <= P^2/6 give
    P^2 <= (E + sqrt(E^2 - 6 c J^2)) / c. (The paper's I >= P^2/9 bounds the wrong way.)
    None for other systems."""
    pot = system.potential
    if pot.measure != PERIMETER or pot.profile != POWER or pot.params[1] != 2.0 or \
            not np.all(system.masses == 1.0) or system.n_bodies != 3:
        return None
    c = pot.params[0]
    disc = E * E - 6 * c * J * J
    return math.sqrt((E + math.sqrt(disc)) / c) if disc >= 0 else None


def integrate_orbit(spec: OrbitSpec, params: dict | None = None):
    """(system, y0, outcome, wall seconds) of one orbit with one tangent vector, sampled
    at `samples` times."""
    system = spec.system()
    y0 = initial_state(system, spec.family, **(spec.params if params is None else params))
    w0 = deviation_vectors(system, y0, 1, seed=0)[0]
    t_eval = np.linspace(0.0, spec.t_final, spec.samples)
    with notice(COMPILING, sys.stderr.isatty()):                      # load the kernels
        integrate(system, y0, 1e-3, tangents=w0, t_eval=t_eval[:1])
    start = time.perf_counter()
    out = integrate(system, y0, spec.t_final, tangents=w0, t_eval=t_eval, rtol=spec.tol,
                    atol=spec.tol)
    return system, y0, out, time.perf_counter() - start


def describe(spec: OrbitSpec, run: "OrbitRun") -> list[str]:
    """What to print about one orbit: E, J, conservation, steps, its Lyapunov exponent."""
    system, y0, out, wall = run.system, run.y0, run.outcome, run.wall
    done = ~np.isnan(out.samples[:, 0])
    s = out.samples[done]
    E0, J0 = system.energy(y0), system.angular_momentum(y0)
    lines = [f"{spec.family} {run.params or ''} with {system.potential.describe()}",
             f"E = {E0:.10g}, J = {J0:.10g}; integrated to t = {out.t:g}: {out.status.name}, "
             f"{out.n_steps} steps, {out.n_rhs} RHS evaluations, {wall:.2f} s",
             f"max |E/E0 - 1| = {np.abs(system.energy(s) / E0 - 1).max():.2e}, "
             f"max |J - J0| = {np.abs(system.angular_momentum(s) - J0).max():.2e}, "
             f"max |p_total| = {np.abs(system.momentum(s)).max():.2e}",
             f"finite-time Lyapunov exponent ln(|w(t)|/|w0|)/t = "
             f"{out.log_growth[0] / out.t:.5f}"]
    bound = run.p_max
    if bound is not None:
        lines.append(f"P_max = sqrt(E + sqrt(E^2 - 6 J^2)) = {bound:.6g} (Hill-type disk "
                     f"radius {bound / 3:.6g})")
    return lines


class OrbitRun(NamedTuple):
    """One integrated orbit of a spec: its parameters, system, start, outcome (sampled at
    `samples` times), wall time, and the perimeter bound P_max where one is known."""

    params: dict
    system: System
    y0: np.ndarray
    outcome: Outcome
    wall: float
    p_max: float | None

    @property
    def label(self) -> str:
        return ", ".join(f"{k} = {v:g}" for k, v in self.params.items()
                         if isinstance(v, (int, float)))


def run_orbits(spec: OrbitSpec) -> list[OrbitRun]:
    """Every orbit of a spec: one, or one per value of its list parameter."""
    runs = []
    for params in expand(spec):
        system, y0, out, wall = integrate_orbit(spec, params)
        bound = p_max(system, system.energy(y0), float(system.angular_momentum(y0)))
        runs.append(OrbitRun(params, system, y0, out, wall, bound))
    return runs


KEYS = {f for f in OrbitSpec.__dataclass_fields__}


def load_workflow(path) -> list[OrbitSpec]:
    """The [[orbit]] tables of an orbit workflow file, checked."""
    text = Path(path).read_text()
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), f"not valid TOML ({exc}); fix the syntax") from None
    tables = raw.get("orbit")
    if not isinstance(tables, list) or not tables:
        raise ConfigError(str(path), "an orbit workflow needs [[orbit]] tables")
    specs = []
    for k, table in enumerate(tables):
        where = f"[[orbit]] {k + 1}"
        extra = sorted(set(table) - KEYS)
        if extra:
            raise ConfigError(f"{where}.{extra[0]}", f"unknown key; keys are {', '.join(sorted(KEYS))}")
        if "name" not in table or "family" not in table:
            raise ConfigError(where, "needs a name and a family")
        specs.append(check(OrbitSpec(**table), where))
    return specs


def is_orbit_workflow(path) -> bool:
    try:
        return "orbit" in tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return False
