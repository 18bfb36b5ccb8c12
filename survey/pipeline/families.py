"""Families of special solutions from a config, as one pipeline: load and check the
config (its [equilibria] or [periodic] table), solve (`solve`: the relative equilibria or
the periodic orbit near the [initial] start, or with a parameter their family by
continuation), the family's Dataset (variables declared in catalog.families, built and
written by pipeline.archive), and `verify`'s computation again. The invariant manifolds
of a section map ([[plane]] manifolds) are a family archive too. What is printed of them
is presentation.families'; the commands (`python -m survey equilibria|periodic`) join the
two in cli.

The config is a survey's: [system] as in a survey, the start as one [initial] family
member (`family = "explicit"` with `positions` and `velocities` for any start; equilibria
use its positions only), plus an [equilibria] or a [periodic] table."""
from __future__ import annotations

import sys

import tomllib
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..catalog.errors import ConfigError, SurveyError
from ..catalog.families import EQUILIBRIA, FAMILY_ATTRIBUTES, MANIFOLDS, PERIODIC
from ..numerics.isosceles import PlaneManifolds, eigen2, plane_periodic
from ..numerics.periodic import (
    Family,
    GuessError,
    PeriodicOrbit,
    lyapunov_start,
    periodic_family,
    periodic_orbit,
)
from ..physics.equilibria import relative_equilibria, relative_equilibrium
from ..physics.system import System
from .archive import family_dataset
from .build import build_system
from .cells import build_starts, compiled_beside, warm_solvers
from .config import _decode, check_table, read_toml, validate
from .orbits import PlaneSpec, check_plane
from .progress import count_bar, family_bar
from .resources import ensure_writable
from .schema import Key

FAMILY = {      # a family's end, for [equilibria] and [periodic] with a parameter
    "to": Key("float", None, "the parameter's last value"),
    "steps": Key("int", 20, "arclength steps from the start to `to` where the family runs "
                            "along the parameter (more where it bends)", low=1, high=100000),
}


SQUARED = dict(low=-1e100, high=1e100, hint="its square must stay finite in double "
                                            "precision")


EQUILIBRIA_KEYS = {
    "angular_momentum": Key("float", None, "angular momentum J of the rotation (in the "
                                           "plane); default: the [initial] start's",
                            **SQUARED),
    "rotation_rate": Key("float", None, "rotation rate Omega instead of J (an isochronous "
                                        "potential, P^2/2, fixes Omega for every size)",
                         **SQUARED),
    "starts": Key("int", 0, "seeded random configurations tried besides the start (the "
                            "start's size, normal about its centre)", low=0, high=10000),
    "seed": Key("int", 0, "seed of those configurations", low=0),
    "parameter": Key("str", "", "continue the start's equilibrium in this parameter: "
                                "angular_momentum, mass_K (body K, from 0) or a potential "
                                "parameter by its grid-axis name (<potential>_<parameter>); "
                                "'' for none"),
    **FAMILY,
}


PERIODIC_KEYS = {
    "period": Key("float", None, "the period's guess (required unless mode)", "time", above=0),
    "rotating": Key("bool", False, "a relative periodic orbit: it returns rotated (the plane)"),
    "energy": Key("float", None, "the energy to find it at (default: the start's)", "energy"),
    "tol": Key("float", 1e-13, "rtol = atol of the shooting's integrations", low=2.2e-15,
               high=1e-6),
    "mode": Key("int", 0, "start the Lyapunov family of this normal mode (1: the lowest "
                          "frequency) of the relative equilibrium found from the [initial] "
                          "start's positions at its J; period and rotating follow; 0: none",
                low=0, high=1000),
    "amplitude": Key("float", 1e-3, "the mode's displacement, relative to the equilibrium's "
                                    "size", above=0, high=0.5),
    "parameter": Key("str", "", "continue the orbit in 'energy' (J held), in "
                                "'angular_momentum' (a rotating orbit, E held) or a parameter "
                                "of the system at fixed energy: mass_K (body K, from 0) or a "
                                "potential parameter by its grid-axis name; '' for none"),
    **FAMILY,
}



def _load(path, name: str, keys: dict):
    """(config without the [name] table, start state, the [name] table with defaults
    filled in) from a config file; ConfigError naming the key for anything wrong."""
    path = Path(path)
    try:
        text = _decode(path.read_bytes(), str(path))
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read it ({exc.strerror or exc})") from None
    raw = read_toml(text, str(path))
    table = check_table(name, keys, raw.pop(name, {}))
    config = validate(raw, text, str(path), check_output=False)
    if config.n_cells != 1:
        raise ConfigError("[initial]", f"has a grid of {config.n_cells} starts; give the one "
                                       "start to search from (no grid axes)")
    start = build_starts(config)[0]
    if np.isnan(start[0]):
        raise ConfigError("[initial]", "the start is inaccessible at this energy")
    return config, start, table



def load_equilibria(path):
    """(config, system, start positions (N, d), the [equilibria] table)."""
    config, start, table = _load(path, EQUILIBRIA, EQUILIBRIA_KEYS)
    system = config.system()
    if table["angular_momentum"] is not None and table["rotation_rate"] is not None:
        raise ConfigError("[equilibria]", "give angular_momentum or rotation_rate, not both")
    spin = table["angular_momentum"] if table["angular_momentum"] is not None \
        else table["rotation_rate"]
    if system.dim == 3 and spin:
        raise ConfigError("[equilibria]", "rotating relative equilibria are found in the "
                                          "plane ([system] dim = 2); in 3-D only at rest "
                                          "(angular_momentum = 0)")
    if table["angular_momentum"] is None and table["rotation_rate"] is None:
        table["angular_momentum"] = 0.0 if system.dim == 3 else \
            float(system.angular_momentum(start))
    return config, system, system.split(start)[0], table



def family_systems(config_system: dict, parameter: str, table: str = "equilibria"):
    """(p0, p -> System): the parameter's value in [system] and the System at another."""
    from .build import term_axis_names
    if parameter.startswith("mass_"):
        masses = list(config_system["masses"] or [1.0] * config_system["bodies"])
        k = parameter[5:]
        if not k.isdigit() or int(k) >= len(masses):
            raise ConfigError(f"[{table}].parameter", f"{parameter!r}: give mass_K with K a "
                                                      f"body from 0 to {len(masses) - 1}")
        k = int(k)

        def with_mass(p):
            table = {**config_system, "masses": masses[:k] + [p] + masses[k + 1:]}
            return build_system(table)
        return float(masses[k]), with_mass
    names = {name: (i, key) for i, axes in enumerate(term_axis_names(config_system))
             for key, name in axes.items()}
    if parameter not in names:
        raise ConfigError(f"[{table}].parameter", f"{parameter!r} is neither "
                          + ("energy, angular_momentum, " if table == "periodic" else
                             "angular_momentum, ") + "mass_K nor a "
                          "parameter of the system's terms (" + ", ".join(sorted(names)) + ")")
    p0 = build_system(config_system).terms[names[parameter][0]]
    value = dict(zip(p0.param_names, p0.params))[names[parameter][1]]
    return float(value), lambda p: build_system(config_system, {parameter: p})



def _reachable(systems, to: float, table: str):
    """The family's end value as a system: ConfigError naming `to` where the parameter
    cannot take it (a mass <= 0, a term's parameter outside its bounds)."""
    try:
        systems(to)
    except ValueError as exc:
        raise ConfigError(f"[{table}].to", f"{to:g}: {exc}") from None



def solve_equilibria(path):
    """(system, table, found): the relative equilibria from the start and the seeded
    configurations, or with [equilibria] parameter the start's family, (members,
    bifurcations, complete, ended): a continuation.EquilibriumFamily."""
    config, system, start, table = load_equilibria(path)
    if table["parameter"]:
        return system, table, _equilibrium_family(path, config, system, start, table)
    with compiled_beside(warm_solvers, system, start, False), \
            count_bar("solving for relative equilibria from each starting configuration",
                      sys.stderr.isatty()) as update:
        found = relative_equilibria(
            system, start, table["angular_momentum"], table["rotation_rate"],
            table["starts"], table["seed"], on_guess=None if update is None else
            lambda done, total, distinct: update(done, total, f"{distinct} distinct"))
    return system, table, found



def _equilibrium_family(path, config, system, start, table):
    """The family of the start's relative equilibrium along [equilibria] parameter, from its
    value in [system] to `to` (pseudo-arclength, about `steps` members where it runs along
    the parameter): a continuation.EquilibriumFamily."""
    from ..numerics.continuation import equilibrium_family
    if table["to"] is None:
        raise ConfigError("[equilibria].to", "is required with a parameter: its last value")
    spin = table["parameter"] == "angular_momentum"
    if spin and table["rotation_rate"] is not None:
        raise ConfigError("[equilibria].parameter", "'angular_momentum' runs J from "
                                                    "angular_momentum: give it, not "
                                                    "rotation_rate")
    p0, systems = (table["angular_momentum"], lambda p: system) if spin else \
        family_systems(config.system_table, table["parameter"])
    _reachable(systems, table["to"], "equilibria")
    if table["to"] == p0:
        raise ConfigError("[equilibria].to", f"equals the parameter's start value {p0:g}; "
                                             "give the family's other end")
    try:
        with family_bar(f"following the equilibria along {table['parameter']}",
                        sys.stderr.isatty()) as on_member:
            return equilibrium_family(
                systems, start, p0, table["to"], table["steps"], table["angular_momentum"],
                table["rotation_rate"], spin_parameter=spin, on_member=on_member)
    except ValueError as exc:
        raise SurveyError(f"{path}: the family does not start: {exc}") from None



def load_periodic(path):
    """(config, system, start state, the [periodic] table with period and rotating filled
    in). With `mode` the start is the Lyapunov family's first member: the relative
    equilibrium from the [initial] start's positions at its J, displaced along the mode."""
    config, start, table = _load(path, PERIODIC, PERIODIC_KEYS)
    system = config.system()
    if table["mode"]:
        spin = float(system.angular_momentum(start)) if system.dim == 2 else 0.0
        try:
            eq = relative_equilibrium(system, system.split(start)[0], angular_momentum=spin)
        except ValueError as exc:
            raise SurveyError(f"{path}: [periodic] mode = {table['mode']}: {exc}") from None
        if table["mode"] > eq.frequencies.size:
            raise ConfigError("[periodic].mode", f"{table['mode']}: the start's relative "
                              f"equilibrium has {eq.frequencies.size} normal modes on the "
                              f"imaginary axis; give 1 to {eq.frequencies.size}")
        start, table["period"] = lyapunov_start(system, eq, table["mode"], table["amplitude"])
        table["rotating"] = eq.rotation_rate != 0.0
        table["krein"] = int(eq.krein[eq.eigenvalues.imag > 0][
            np.argmin(np.abs(eq.eigenvalues[eq.eigenvalues.imag > 0].imag
                             - 2 * np.pi / table["period"]))])
    if table["period"] is None:
        raise ConfigError("[periodic].period", "is required: a guess of the period (or a "
                                               "normal mode to start from: mode)")
    if table["rotating"] and system.dim != 2:
        raise ConfigError("[periodic].rotating", "relative periodic orbits are found in the "
                                                 "plane ([system] dim = 2)")
    if table["parameter"] and table["to"] is None:
        raise ConfigError("[periodic].to", "is required with a parameter: its last value")
    if table["parameter"] == "energy" and table["energy"] is not None:
        raise ConfigError("[periodic].energy", "the family runs in energy from the start's: "
                                               "leave energy out, or continue in another "
                                               "parameter")
    return config, system, start, table



def solve_periodic(path) -> tuple[System, dict, PeriodicOrbit | Family]:
    """(system, table, the orbit through the start, or with [periodic] parameter its
    Family)."""
    config, system, start, table = load_periodic(path)
    try:
        with compiled_beside(warm_solvers, system, start):
            orbit = periodic_orbit(system, start, table["period"], table["rotating"],
                                   table["energy"], table["tol"])
    except GuessError as exc:
        raise ConfigError("[periodic].period" if not table["mode"] else "[periodic].mode",
                          str(exc)) from None
    except ValueError as exc:
        raise SurveyError(f"{path}: {exc}; try another [periodic] period or start") from None
    if not table["parameter"]:
        return system, table, orbit
    return system, table, _periodic_family(path, config, system, table, orbit)



def _periodic_family(path, config, system, table, orbit) -> Family:
    """The family of the start's periodic orbit along [periodic] parameter to `to`."""
    name = table["parameter"]
    if name == "energy":
        p0, systems = orbit.energy, lambda p: system
        if table["mode"] and (table["to"] - p0) * table["krein"] < 0:
            raise ConfigError("[periodic].to", f"mode {table['mode']}'s family leaves the "
                              "equilibrium toward " + ("higher" if table["krein"] > 0 else
                                                        "lower") + f" energy (its Krein sign "
                              f"is {table['krein']:+d}): give to " +
                              (">" if table["krein"] > 0 else "<") + f" {p0:.10g}")
    elif name == "angular_momentum":
        if not table["rotating"]:
            raise ConfigError("[periodic].parameter", "'angular_momentum' continues a rotating "
                                                      "orbit (rotating = true or a mode of a "
                                                      "rotating equilibrium); a periodic "
                                                      "orbit's J is its own")
        p0, systems = orbit.angular_momentum, lambda p: system
    else:
        p0, systems = family_systems(config.system_table, name, "periodic")
        _reachable(systems, table["to"], "periodic")
    if table["to"] == p0:
        raise ConfigError("[periodic].to", f"equals the parameter's start value {p0:g}; "
                                           "give the family's other end")
    try:
        with family_bar(f"following the orbit along {name}", sys.stderr.isatty()) as on_member:
            family = periodic_family(systems, orbit, p0, table["to"], table["steps"],
                                     table["rotating"], name if name in (
                                         "energy", "angular_momentum") else None,
                                     table["tol"], on_member=on_member)
    except ValueError as exc:
        raise SurveyError(f"{path}: the family does not start: {exc}") from None
    return family



class Solved(NamedTuple):
    """What `solve` found: the kind (catalog.families EQUILIBRIA or PERIODIC), the
    config's system, its table with defaults filled in, what was found -- an
    equilibria Search, an EquilibriumFamily, a PeriodicOrbit or a periodic Family -- and
    the config file and text."""

    kind: str
    system: System
    table: dict
    found: Any
    path: Path
    text: str

    @property
    def is_family(self) -> bool:
        return bool(self.table["parameter"])


def solve(path, kind: str | None = None, output=None) -> Solved:
    """The special solutions of a config ([equilibria] or [periodic], or `kind`), after
    checking that --output (a family's archive) can be written, before any work."""
    kind = kind or special_table(path)
    if kind not in (EQUILIBRIA, PERIODIC):
        raise ConfigError(str(path), "has neither an [equilibria] nor a [periodic] table")
    _refuse_output(path, kind, output)
    system, table, found = (solve_equilibria if kind == EQUILIBRIA else
                            solve_periodic)(path)
    return Solved(kind, system, table, found, Path(path), Path(path).read_text())


def dataset(solved: Solved):
    """A solved family's Dataset (`equilibrium_dataset` or `periodic_dataset`)."""
    make = equilibrium_dataset if solved.kind == EQUILIBRIA else periodic_dataset
    return make(solved.table, solved.found, solved.text)


def equilibrium_dataset(table: dict, family, config_text: str):
    """A family of relative equilibria as a labelled Dataset (catalog.families): per
    member the parameter, E, J, Omega, the positions, the reduced eigenvalues and the
    stability; per bifurcation where, how accurately and what."""
    members, found = family.members, family.bifurcations
    n = max(e.eigenvalues.size for _, e in members)
    lam = np.full((len(members), n), np.nan + 0j)
    for i, (_, e) in enumerate(members):
        lam[i, :e.eigenvalues.size] = e.eigenvalues
    return family_dataset(EQUILIBRIA, {
        "energy": [e.energy for _, e in members],
        "angular_momentum": [e.angular_momentum for _, e in members],
        "rotation_rate": [e.rotation_rate for _, e in members],
        "positions": np.array([e.positions for _, e in members]),
        "eigenvalue_real": lam.real, "eigenvalue_imag": lam.imag,
        "stable": [e.stable for _, e in members],
        "bifurcation_parameter": [b.parameter for b in found],
        "bifurcation_accuracy": [b.accuracy for b in found],
        "bifurcation_kind": [b.kind for b in found]},
        table["parameter"], coords={table["parameter"]: ("member", [p for p, _ in members])},
        attrs={"title": f"relative equilibria along {table['parameter']}",
               "complete": int(family.complete), "ended": family.ended,
               "config": config_text})



def periodic_dataset(table: dict, family: Family, config_text: str):
    """A periodic family as a labelled Dataset (catalog.families): per member the
    parameter, period, rotation, E, J, the initial state, the multipliers and stability
    indices, the kind; per bifurcation where, its period, how accurately and what."""
    members = family.members
    width = max(o.multipliers.size for o in members)
    mu = np.full((len(members), width), np.nan + 0j)
    b = np.full((len(members), width // 2), np.nan + 0j)
    for i, o in enumerate(members):
        mu[i, :o.multipliers.size] = o.multipliers
        b[i, :o.indices.size] = o.indices
    found = family.bifurcations
    name = table["parameter"]
    # the parameter labels the members (in energy: the pinned value, not the measured one)
    return family_dataset(PERIODIC, {
        "period": [o.period for o in members], "rotation": [o.rotation for o in members],
        "energy": [o.energy for o in members],
        "angular_momentum": [o.angular_momentum for o in members],
        "return_error": [o.return_error for o in members],
        "excursion": [o.motion.excursion for o in members],
        "turning": [o.motion.turning for o in members],
        "initial_state": np.array([o.state for o in members]),
        "multiplier_real": mu.real, "multiplier_imag": mu.imag,
        "index_real": b.real, "index_imag": b.imag,
        "stable": [o.stable for o in members], "kind": [o.kind for o in members],
        "bifurcation_parameter": [f.parameter for f in found],
        "bifurcation_period": [f.period for f in found],
        "bifurcation_accuracy": [f.accuracy for f in found],
        "bifurcation_kind": [f.kind for f in found]},
        name, coords={name: ("member", family.parameters, {"long_name": name})},
        attrs={"title": f"periodic orbits along {name}", "complete": int(family.complete),
               "ended": family.ended, "config": config_text})



def manifold_dataset(spec: PlaneSpec, found: list, config_text: str):
    """The manifolds of a plane run as a labelled Dataset (catalog.families): per guess
    the orbit Newton found (its point, period, kind, unstable multiplier); per branch
    which orbit, stable or unstable, which side; per point (b, p_b), arclength, level and
    seed; per homoclinic point where, how accurately, which branches cross there and at
    what angle."""
    grown = [f for f in found if isinstance(f, PlaneManifolds)]
    orbits = [f.orbit if isinstance(f, PlaneManifolds) else f for f in found]
    branches = [(k, b) for k, f in enumerate(found) if isinstance(f, PlaneManifolds)
                for b in f.branches]
    homoclinic = [(k, h) for k, f in enumerate(grown) for h in f.homoclinic]
    offset = np.cumsum([0] + [len(f.branches) for f in grown])
    points = np.concatenate([b.points for _, b in branches]) if branches else np.empty((0, 2))
    hyperbolic = [o.converged and o.kind != "elliptic" for o in orbits]

    def along(field):
        return np.concatenate([getattr(b, field) for _, b in branches] or [[]])
    return family_dataset(MANIFOLDS, {
        "orbit_b": [o.b[0] for o in orbits], "orbit_p_b": [o.p_b[0] for o in orbits],
        "orbit_crossings": [o.crossings for o in orbits],
        "orbit_period": [o.period for o in orbits],
        "orbit_converged": [o.converged for o in orbits],
        "orbit_kind": [o.kind for o in orbits],
        "orbit_multiplier": [eigen2(o.jacobian)[0][0] if h else np.nan
                             for o, h in zip(orbits, hyperbolic)],
        "branch_orbit": [k for k, _ in branches], "branch_kind": [b.kind for _, b in branches],
        "branch_side": [b.side for _, b in branches],
        "branch_resolved": [b.resolved for _, b in branches],
        "point_branch": np.repeat(np.arange(len(branches)),
                                  [b.points.shape[0] for _, b in branches]),
        "b": points[:, 0], "p_b": points[:, 1], "arclength": along("arclength"),
        "level": along("level"), "seed": along("seed"),
        "homoclinic_b": [h.point[0] for _, h in homoclinic],
        "homoclinic_p_b": [h.point[1] for _, h in homoclinic],
        "homoclinic_accuracy": [h.accuracy for _, h in homoclinic],
        "homoclinic_unstable": [offset[k] + h.unstable for k, h in homoclinic],
        "homoclinic_stable": [offset[k] + h.stable for k, h in homoclinic],
        "homoclinic_angle": [h.angle for _, h in homoclinic],
        "homoclinic_arclength": [h.arclength_unstable for _, h in homoclinic]},
        attrs={"title": f"stable and unstable manifolds on the section h = {spec.height:g} "
                        f"of the isosceles plane, E = {spec.energy:g}",
               "name": spec.name, "config": config_text})



def _refuse_output(path, name: str, output) -> None:
    """--output writes a family: refused before any work where [name] has no parameter,
    and where it could not be written or is the config itself."""
    if not output:
        return
    try:
        wants = bool(tomllib.loads(Path(path).read_text()).get(name, {}).get("parameter"))
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError, AttributeError,
            RecursionError):
        return          # the loader names what is wrong with the file
    if not wants:
        raise ConfigError("--output", f"writes a family: give [{name}] parameter and to")
    ensure_writable(Path(output), "--output", [path])



def special_table(path) -> str | None:
    """'equilibria' or 'periodic' if the config file has that table (a special-solution
    workflow), else None."""
    try:
        raw = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError):
        return None
    return next((name for name in (EQUILIBRIA, PERIODIC) if name in raw), None)



def is_family(path) -> bool:
    """Whether an archive is a family (of `equilibria` or `periodic --output`)."""
    from .archive import open_archive
    with open_archive(path) as ds:
        return "family" in ds.attrs



def verify_family(path, cells: int = 8) -> tuple[bool, list[str]]:
    """A family archive against its stored config: the family computed again and compared
    member by member -- the parameter and every per-member number (period, rotation, E, J,
    states, multipliers; or E, J, Omega, positions, eigenvalues) -- bit for bit, on any
    machine: the integrator and the linear algebra (machine.linalg) are portable. An
    archive of manifolds (pipeline.orbits.verify_manifolds): its orbits, `cells` of its
    points and its first homoclinic point."""
    import hashlib
    import tempfile

    from .archive import machine, open_archive
    with open_archive(path) as ds:
        stored = ds.load()
    missing = [k for k in ("config", "config_sha256") if k not in stored.attrs]
    if missing:
        return False, [f"{path}: a family archive without its {missing[0]} attribute cannot "
                       "be computed again"]
    text, kind = stored.attrs["config"], stored.attrs["family"]
    if hashlib.sha256(text.encode()).hexdigest() != stored.attrs["config_sha256"]:
        return False, [f"{path}: config_sha256 does not match the stored config text (edited "
                       "after the run)"]
    made = f"(made on {stored.attrs.get('machine', 'an unrecorded machine')}, checked on " \
           f"{machine()})"
    if kind == MANIFOLDS:
        lines, what = verify_manifolds(stored, cells), "manifolds computed again differ"
        agree = (f"{stored.sizes['orbit']} orbits, {min(cells, stored.sizes['point'])} of "
                 f"{stored.sizes['point']} points and "
                 f"{min(1, stored.sizes.get('homoclinic', 0))} homoclinic point")
    else:
        with tempfile.TemporaryDirectory() as folder:
            config = Path(folder) / "family.toml"
            config.write_text(text)
            if kind == PERIODIC:
                _, table, family = solve_periodic(config)
                fresh = periodic_dataset(table, family, text)
            else:
                _, table, family = solve_equilibria(config)
                fresh = equilibrium_dataset(table, family, text)
        lines, what = _family_differences(stored, fresh), "family computed again differs"
        agree = (f"{stored.sizes['member']} members and "
                 f"{stored.sizes.get('bifurcation', 0)} bifurcations")
    if lines:
        return False, [f"{path}: the {what} {made}:"] + [f"  {line}" for line in lines]
    return True, [f"{path}: {agree} computed again agree bit for bit {made}"]



def _family_differences(stored, fresh) -> list[str]:
    """How a stored family differs from the one computed again: every variable and
    coordinate (numbers bit for bit, NaN equal to NaN; labels as text), missing or extra
    ones, and the attributes the computation sets (complete, why it ended, title)."""
    lines = []
    if fresh.sizes.get("member") != stored.sizes.get("member"):
        lines.append(f"computed again the family has {fresh.sizes.get('member')} members, "
                     f"the archive {stored.sizes.get('member')}")
    for name in sorted(set(fresh.variables) | set(stored.variables)):
        if name not in stored.variables:
            lines.append(f"{name}: missing from the archive")
            continue
        if name not in fresh.variables:
            lines.append(f"{name}: in the archive, not computed again")
            continue
        a, b = stored[name].values, fresh[name].values
        if a.shape != b.shape:
            lines.append(f"{name}: shape {a.shape} stored, {b.shape} computed again")
        elif a.dtype.kind in "fc" and b.dtype.kind in "fc":
            if not np.array_equal(a, b, equal_nan=True):
                scale = np.nanmax(np.abs(a), initial=0.0) or 1.0
                worst = float(np.nanmax(np.abs(a - b), initial=0.0)) / scale
                lines.append(f"{name}: differs by {worst:.1e} of its scale")
        elif a.dtype.kind in "iub" and b.dtype.kind in "iub":
            if not np.array_equal(a, b):
                lines.append(f"{name}: {a.tolist()} stored, {b.tolist()} computed again")
        elif [str(v) for v in a.ravel()] != [str(v) for v in b.ravel()]:
            lines.append(f"{name}: {[str(v) for v in a.ravel()]} stored, "
                         f"{[str(v) for v in b.ravel()]} computed again")
    for key in FAMILY_ATTRIBUTES:
        if str(stored.attrs.get(key)) != str(fresh.attrs.get(key)):
            lines.append(f"attribute {key}: {str(stored.attrs.get(key))!r} stored, "
                         f"{str(fresh.attrs.get(key))!r} computed again")
    return lines



def verify_manifolds(stored, cells: int = 8) -> list[str]:
    """How a manifold archive differs from its config computed again: every orbit (Newton
    again, bit for bit), a sample of `cells` points of its branches (first, last, the rest
    at random; each P^n of its seed again) and the first homoclinic point (located again
    on the stored branches). Empty if they agree."""
    from ..numerics.isosceles import manifold_seeds
    from ..numerics.manifolds import Branch, first_homoclinic
    table = read_toml(stored.attrs["config"], "the stored config").get("plane", {})
    spec = check_plane(table, "[plane]")
    system = spec.build()
    lines = []
    found = [plane_periodic(system, spec.energy, spec.height, (b, p_b), k, spec.t_final,
                            rtol=spec.tol) for b, p_b, k in spec.manifolds]
    if len(found) != stored.sizes.get("orbit", 0):
        return [f"the config asks for {len(found)} orbits, the archive has "
                f"{stored.sizes.get('orbit', 0)}"]
    fresh = manifold_dataset(spec, found, stored.attrs["config"])
    for name in [v for v in fresh.variables if v.startswith("orbit_")]:
        a, b = stored[name].values, fresh[name].values
        if [str(x) for x in a] != [str(x) for x in b]:
            lines.append(f"{name}: {a.tolist()} stored, {b.tolist()} computed again")
    if lines:
        return lines
    made = {k: manifold_seeds(system, spec.energy, spec.height, orbit, spec.t_final,
                              spec.tol) for k, orbit in enumerate(found)
            if orbit.converged and orbit.kind != "elliptic"}
    branch_orbit = stored["branch_orbit"].values
    first = {int(j): int(np.sum(branch_orbit[:j] == branch_orbit[j]))
             for j in range(branch_orbit.size)}        # a branch's place in its orbit's four
    n = stored.sizes["point"]
    rest = np.random.default_rng(0).permutation(np.arange(1, max(n - 1, 1)))
    for i in np.unique(np.concatenate([[0, n - 1], rest[:max(cells - 2, 0)]]))[:n]:
        j = int(stored["point_branch"].values[i])
        seeds = made[int(branch_orbit[j])][first[j]]
        point = seeds.point(float(stored["seed"].values[i]), int(stored["level"].values[i]))
        kept = np.array([stored["b"].values[i], stored["p_b"].values[i]])
        if point is None or point.tobytes() != kept.tobytes():
            lines.append(f"point {i} (branch {j}, level {int(stored['level'].values[i])}): "
                         f"{kept.tolist()} stored, "
                         f"{None if point is None else point.tolist()} computed again")
    if stored.sizes.get("homoclinic", 0):
        u, s = (int(stored[f"homoclinic_{x}"].values[0]) for x in ("unstable", "stable"))
        k = int(branch_orbit[u])
        branches = []
        for j in np.flatnonzero(branch_orbit == k):
            on = stored["point_branch"].values == j
            branches.append(Branch(str(stored["branch_kind"].values[j]),
                                   int(stored["branch_side"].values[j]),
                                   np.column_stack((stored["b"].values[on],
                                                    stored["p_b"].values[on])),
                                   stored["arclength"].values[on], stored["level"].values[on],
                                   stored["seed"].values[on],
                                   bool(stored["branch_resolved"].values[j])))
        h = first_homoclinic(branches, first[u], first[s], made[k])
        kept = np.array([stored["homoclinic_b"].values[0], stored["homoclinic_p_b"].values[0]])
        if h is None or h.point.tobytes() != kept.tobytes():
            lines.append(f"the first homoclinic point: {kept.tolist()} stored, "
                         f"{None if h is None else h.point.tolist()} located again")
    return lines

