"""Special solutions of a config's system near the config's [initial] start: its relative
equilibria with their linear stability (`python -m survey equilibria CONFIG.toml`), and the
periodic orbit through the start with its Floquet multipliers (`python -m survey periodic
CONFIG.toml`).

The config is a survey's: [system] as in a survey, the start as one [initial] family
member (`family = "explicit"` with `positions` and `velocities` for any start; equilibria
use its positions only), plus an [equilibria] or a [periodic] table."""
from __future__ import annotations

import contextlib
import json
import tomllib
from pathlib import Path

import numpy as np

from ..analysis.findings import family_stability
from ..analysis.refine import as_grid, cell_label, cell_values
from ..catalog.errors import ConfigError, SurveyError
from ..numerics.integrate import integrate
from ..numerics.periodic import (
    EXCURSION,
    Family,
    GuessError,
    PeriodicOrbit,
    lyapunov_start,
    periodic_family,
    periodic_orbit,
)
from ..machine import linalg
from ..physics.equilibria import (
    RelativeEquilibrium,
    forces,
    relative_equilibria,
    relative_equilibrium,
)
from ..physics.system import System
from .build import build_system
from .cells import build_starts
from .config import _decode, check_table, read_toml, validate
from .schema import Key
from .resources import ensure_writable

FAMILY = {      # a family's end, for [equilibria] and [periodic] with a parameter
    "to": Key("float", None, "the parameter's last value"),
    "steps": Key("int", 20, "arclength steps from the start to `to` where the family runs "
                            "along the parameter (more where it bends)", low=1, high=100000),
}

SQUARED = dict(low=-1e100, high=1e100, hint="its square must stay finite in double "
                                            "precision")
EQUILIBRIA = {
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


PERIODIC = {
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
    config, start, table = _load(path, "equilibria", EQUILIBRIA)
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


def _family_systems(config_system: dict, parameter: str, table: str = "equilibria"):
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
    return system, table, relative_equilibria(system, start, table["angular_momentum"],
                                              table["rotation_rate"], table["starts"],
                                              table["seed"])


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
        _family_systems(config.system_table, table["parameter"])
    _reachable(systems, table["to"], "equilibria")
    if table["to"] == p0:
        raise ConfigError("[equilibria].to", f"equals the parameter's start value {p0:g}; "
                                             "give the family's other end")
    try:
        return equilibrium_family(
            systems, start, p0, table["to"], table["steps"], table["angular_momentum"],
            table["rotation_rate"], spin_parameter=spin)
    except ValueError as exc:
        raise SurveyError(f"{path}: the family does not start: {exc}") from None


def family_text(table: dict, family) -> str:
    """A family of relative equilibria (continuation.EquilibriumFamily) as text."""
    name = table["parameter"]
    members, found = family.members, family.bifurcations
    lines = [f"Family along {name} ({len(members)} members, " + (
        "reaching" if family.complete else "not reaching") + f" {name} = {table['to']:g}"
             + ("" if family.complete else f": {family.ended}") + "):", "",
             f"| {name} | E | J | Omega | stable | largest growth rate |",
             "| --- | --- | --- | --- | --- | --- |"]
    for p, e in members:
        lines.append(f"| {p:.6g} | {e.energy:.8g} | {e.angular_momentum:.8g} | "
                     f"{e.rotation_rate:.8g} | {'yes' if e.stable else 'no'} | "
                     f"{max(e.rates, default=0.0):.4g} |")
    lines += [""] + ([f"At {name} = {located(b)}: a fold." if b.kind == "fold" else
                      f"Stability changes at {name} = {located(b)}: {b.kind} on the "
                      "unstable side." for b in found] or ["The stability does not change."])
    return "\n".join(lines)


def equilibrium_dataset(table: dict, family, config_text: str):
    """A family of relative equilibria as a labelled xarray Dataset: per member the
    parameter, E, J, Omega, the positions, the reduced eigenvalues and the stability."""
    import xarray as xr
    members, found = family.members, family.bifurcations
    n = max(e.eigenvalues.size for _, e in members)
    lam = np.full((len(members), n), np.nan + 0j)
    for i, (_, e) in enumerate(members):
        lam[i, :e.eigenvalues.size] = e.eigenvalues
    return xr.Dataset(
        {"energy": ("member", [e.energy for _, e in members], {"long_name": "energy"}),
         "angular_momentum": ("member", [e.angular_momentum for _, e in members],
                              {"long_name": "angular momentum"}),
         "rotation_rate": ("member", [e.rotation_rate for _, e in members],
                           {"long_name": "rotation rate Omega"}),
         "positions": (("member", "body", "axis"), np.array([e.positions for _, e in members]),
                       {"long_name": "positions at t = 0, centre of mass at the origin"}),
         "eigenvalue_real": (("member", "eigenvalue"), lam.real,
                             {"long_name": "reduced linearisation's eigenvalues, real part"}),
         "eigenvalue_imag": (("member", "eigenvalue"), lam.imag,
                             {"long_name": "reduced linearisation's eigenvalues, imaginary "
                                           "part"}),
         "stable": ("member", np.array([e.stable for _, e in members], dtype=np.int8),
                    {"long_name": "1 where every reduced eigenvalue is on the imaginary axis"}),
         "bifurcation_parameter": ("bifurcation", [b.parameter for b in found],
                                   {"long_name": f"{table['parameter']} where the stability "
                                                 "changes"}),
         "bifurcation_accuracy": ("bifurcation", [b.accuracy for b in found],
                                  {"long_name": "how far the parameter may be off: the "
                                                "bisection's bracket"}),
         "bifurcation_kind": ("bifurcation", np.array([b.kind for b in found], dtype=object))},
        coords={table["parameter"]: ("member", [p for p, _ in members])},
        attrs={"title": f"relative equilibria along {table['parameter']}",
               "family": "equilibria", "complete": int(family.complete),
               "ended": family.ended, "config": config_text})


def write_archive(ds, path, command: str) -> Path:
    """A family's Dataset in NetCDF with its provenance (command, commit, machine,
    versions) and its config's sha256, written atomically."""
    import hashlib

    from .archive import git_commit, machine, versions
    out = Path(path)
    ds = ds.assign_attrs(config_sha256=hashlib.sha256(ds.attrs["config"].encode()).hexdigest(),
                         history=command, git_commit=git_commit(), machine=machine(),
                         **{f"version_{k}": v for k, v in versions().items()})
    tmp = out.with_name(f".{out.name}.partial")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        ds.to_netcdf(tmp, engine="netcdf4")
        tmp.replace(out)
    except (OSError, RuntimeError) as exc:     # netCDF4 reports some as RuntimeError
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise SurveyError(f"cannot write {out} ({getattr(exc, 'strerror', None) or exc}); "
                          "free some space or choose another --output") from None
    return out


def located(b) -> str:
    """A bifurcation's parameter with the digits its accuracy supports (at most 10), and the
    accuracy itself: 0.999879112 +- 2e-09."""
    acc = b.accuracy
    if not (np.isfinite(acc) and acc > 0):
        return f"{b.parameter:.10g}"
    digits = int(np.floor(np.log10(max(abs(b.parameter), 1e-300)))
                 - np.floor(np.log10(acc))) + 1
    return f"{b.parameter:.{min(max(digits, 1), 10)}g} +- {acc:.1g}"


def equilibria_json(found: list[RelativeEquilibrium], search=None) -> dict:
    """The equilibria as JSON; with their `search` (physics.equilibria.Search) how it
    covered the configurations: tries, shape-sphere points, seeded starts, how many times
    each was reached and an estimate of how many none reached."""
    cover = {} if search is None else {"search": {
        "tries": search.tries, "shape_sphere_points": search.shapes,
        "seeded": search.seeded, "missed_estimate": search.missed}}
    hits = [None] * len(found) if search is None else search.hits
    return {**cover, "equilibria": [{
        "positions": e.positions.tolist(), "rotation_rate": e.rotation_rate,
        "energy": e.energy, "angular_momentum": e.angular_momentum,
        "eigenvalues": [[float(z.real), float(z.imag)] for z in e.eigenvalues],
        "frequencies": e.frequencies.tolist(),
        "krein": [int(k) for k, z in zip(e.krein, e.eigenvalues) if k],
        "stable": e.stable, "residual": e.residual, "morse_index": e.morse,
        **({} if h is None else {"reached": h})} for e, h in zip(found, hits)]}


def equilibria_text(system: System, table: dict, search) -> str:
    """The search's equilibria, each with how many tries reached it and its Morse index,
    and how complete the list is."""
    found = search.equilibria
    given = f"J = {table['angular_momentum']:g}" if table["angular_momentum"] is not None \
        else f"Omega = {table['rotation_rate']:g}"
    tried = (f"the start, {search.shapes} points of the shape sphere (each by Newton and "
             f"by descent) and {search.seeded} seeded configurations" if search.shapes else
             f"the start and {search.seeded} seeded configurations")
    lines = [f"Relative equilibria of {system.n_bodies} bodies ({system.describe()}) at "
             f"{given}, from {tried}: {len(found)} distinct (up to rotations, reflections "
             f"and permutations), reached {', '.join(map(str, search.hits))} times of "
             f"{search.tries} tries. " + (
                 "Every one was reached at least twice: no sign of one missed."
                 if search.missed == 0 else
                 f"Some were reached only once: about {search.missed:.1f} more may have been "
                 "missed (Chao's estimate); more starts would find them.")]
    for k, e in enumerate(found):
        i, j = np.triu_indices(system.n_bodies, 1)
        dist = np.linalg.norm(e.positions[i] - e.positions[j], axis=1)
        modes = ", ".join(f"{f:.10g} ({'+' if s > 0 else '-'})" for f, s in zip(
            e.frequencies, e.krein[e.krein != 0])) or "none"
        lines += ["", f"{k + 1}. E = {e.energy:.10g}, J = {e.angular_momentum:.10g}, "
                      f"Omega = {e.rotation_rate:.10g}: "
                      + ("linearly stable" if e.stable else "unstable")
                      + f"; Morse index {e.morse} of the amended potential"
                      + (" (a minimum)" if e.morse == 0 else ""),
                  "   mutual distances " + ", ".join(f"r{a}{b} = {r:.10g}" for a, b, r in
                                                     zip(i, j, dist)),
                  f"   normal modes in the rotating frame (cycles per unit time, Krein "
                  f"sign): {modes}"]
        if e.unstable.size:
            lines.append("   growth rates: " + ", ".join(
                f"{z.real:.10g}" + (f" +- {abs(z.imag):.6g} i" if abs(z.imag) > 1e-12 else "")
                for z in e.unstable))
    return "\n".join(lines)


def print_equilibria(path, as_json_text: bool = False, output=None,
                     command: str = "python -m survey equilibria") -> int:
    """The command: the equilibria found, or with [equilibria] parameter the family of the
    start's one and where its stability changes (and --output, its archive)."""
    _refuse_output(path, "equilibria", output)
    system, table, found = solve_equilibria(path)
    if table["parameter"]:
        family = found
        if output:
            ds = equilibrium_dataset(table, family, Path(path).read_text())
            print(f"wrote {write_archive(ds, output, command)}")
        print(json.dumps({"family": equilibria_json([e for _, e in family.members])[
                              "equilibria"],
                          table["parameter"]: [float(p) for p, _ in family.members],
                          "complete": family.complete, "ended": family.ended,
                          "bifurcations": [b._asdict() for b in family.bifurcations]},
                         indent=1)
              if as_json_text else family_text(table, family))
        return 0
    print(json.dumps(equilibria_json(found.equilibria, found), indent=1) if as_json_text
          else equilibria_text(system, table, found))
    return 0


def load_periodic(path):
    """(config, system, start state, the [periodic] table with period and rotating filled
    in). With `mode` the start is the Lyapunov family's first member: the relative
    equilibrium from the [initial] start's positions at its J, displaced along the mode."""
    config, start, table = _load(path, "periodic", PERIODIC)
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
        p0, systems = _family_systems(config.system_table, name, "periodic")
        _reachable(systems, table["to"], "periodic")
    if table["to"] == p0:
        raise ConfigError("[periodic].to", f"equals the parameter's start value {p0:g}; "
                                           "give the family's other end")
    try:
        family = periodic_family(systems, orbit, p0, table["to"], table["steps"],
                                 table["rotating"], name if name in (
                                     "energy", "angular_momentum") else None, table["tol"])
    except ValueError as exc:
        raise SurveyError(f"{path}: the family does not start: {exc}") from None
    return family


def periodic_json(orbit: PeriodicOrbit) -> dict:
    return {"period": orbit.period, "rotation": orbit.rotation, "energy": orbit.energy,
            "angular_momentum": orbit.angular_momentum,
            "initial_state": orbit.state.tolist(), "return_error": orbit.return_error,
            "newton_residuals": orbit.residuals.tolist(),
            "multipliers": [[float(z.real), float(z.imag)] for z in orbit.multipliers],
            "stable": orbit.stable, "kind": orbit.kind, "rates": orbit.rates.tolist(),
            "excursion": orbit.motion.excursion, "turning": orbit.motion.turning,
            "residues": [[float(z.real), float(z.imag)] for z in orbit.residues]}


def _residues(orbit: PeriodicOrbit) -> str:
    return ", ".join(f"{z.real:.9f}" if abs(z.imag) <= 1e-9 else f"{z.real:.6f} {z.imag:+.6f}i"
                     for z in orbit.residues)


def periodic_text(system: System, orbit: PeriodicOrbit) -> str:
    turn = f", returning rotated by {orbit.rotation:.10g} rad" if orbit.rotation else ""
    spin = orbit.angular_momentum if abs(orbit.angular_momentum) > 1e-12 else 0.0
    lines = [f"Periodic orbit of {system.n_bodies} bodies ({system.describe()}): period "
             f"{orbit.period:.11g}{turn}; E = {orbit.energy:.10g}, J = {spin:.10g}.",
             "Newton shooting, return error |y(T) - y(0)| / |y(0)| before each step and "
             "after the last: " + ", ".join(f"{r:.1e}" if r >= 1e-12 else "< 1e-12"
                                            for r in orbit.residuals) + ".",
             "Non-trivial Floquet multipliers (|mu|, angle/pi): " + ", ".join(
                 f"{m:.9f} {a / np.pi:+.6f}" for m, a in zip(linalg.modulus(orbit.multipliers),
                                                          linalg.argument(orbit.multipliers)))
             + f": {orbit.kind}" + (", linearly stable." if orbit.stable else
                                    ", unstable; nearby orbits leave at " + ", ".join(
                                        f"{r:.6g}" for r in sorted({float(f"{r:.6g}") for r in
                                                                    orbit.rates}, reverse=True))
                                    + " per unit time."),
             f"Greene's residues R = (2 - mu - 1/mu) / 4, one per pair (0 < R < 1 elliptic): "
             f"{_residues(orbit)}.",
             f"Checked to be an orbit that moves: it leaves its start by up to "
             f"{orbit.motion.excursion:.3g} of its size (at least {EXCURSION:.0e} times its "
             f"return error) and its velocity turns through {orbit.motion.turning:.4g} times "
             "a full circle over the period (a closed orbit's turns through one at least)."]
    return "\n".join(lines)


def periodic_family_text(system: System, table: dict, family: Family, rows: int = 40) -> str:
    name = table["parameter"]
    first = family.members[0]
    start = (f"the Lyapunov family of normal mode {table['mode']} of the relative "
             f"equilibrium" if table["mode"] else "the family of the start's orbit")
    n = len(family.members)
    shown = np.unique(np.round(np.linspace(0, n - 1, min(rows, n))).astype(int))
    lines = [f"Periodic orbits of {system.n_bodies} bodies ({system.describe()}): {start}, "
             f"followed in {name} by pseudo-arclength continuation"
             + (f" at J = {first.angular_momentum:.10g}" if name == "energy" and
                table["rotating"] else "")
             + f": {n} members, " + ("reaching" if family.complete else "not reaching")
             + f" {name} = {table['to']:g}" + ("" if family.complete else
                                              f" ({family.ended})")
             + ("" if len(shown) == n else f" (every {n / len(shown):.1f}th shown)") + ".", "",
             f"| {name} | period | rotation | "
             + ("" if name == "energy" else "E | ") + "kind | stability indices (mu + 1/mu)/2 |",
             "| --- " * (5 if name == "energy" else 6) + "|"]
    for i in shown:
        o, p = family.members[i], family.parameters[i]
        lines.append(f"| {p:.10g} | {o.period:.10g} | {o.rotation:.8g} | "
                     + ("" if name == "energy" else f"{o.energy:.10g} | ") + f"{o.kind} | "
                     + ", ".join(
                         f"{b.real:.6f}" if abs(b.imag) <= 1e-9 else
                         f"{b.real:.4f}{b.imag:+.4f}i" for b in o.indices) + " |")
    lines += [""] + ([f"At {name} = {located(b)}: {b.kind}." for b in
                      family.bifurcations] or ["No fold, and no multiplier leaves or joins the "
                                               "unit circle between members."])
    indices = np.array([o.indices for o in family.members])
    stretches = family_stability(family.parameters, indices.real, indices.imag,
                                 [o.stable for o in family.members], name)
    if stretches:
        lines += ["", f"Stable stretches ({stretches[0].test}):"] + \
            [f"- {f.text()}." for f in stretches]
    return "\n".join(lines)


def family_dataset(table: dict, family: Family, config_text: str):
    """A periodic family as a labelled xarray Dataset: per member the parameter, period,
    rotation, E, J, the initial state, the multipliers and stability indices, the kind."""
    import xarray as xr
    members = family.members
    width = max(o.multipliers.size for o in members)
    mu = np.full((len(members), width), np.nan + 0j)
    b = np.full((len(members), width // 2), np.nan + 0j)
    for i, o in enumerate(members):
        mu[i, :o.multipliers.size] = o.multipliers
        b[i, :o.indices.size] = o.indices
    ds = xr.Dataset(
        {"period": ("member", [o.period for o in members], {"long_name": "period"}),
         "rotation": ("member", [o.rotation for o in members],
                      {"long_name": "angle the orbit returns rotated by", "units": "rad"}),
         "energy": ("member", [o.energy for o in members], {"long_name": "energy"}),
         "angular_momentum": ("member", [o.angular_momentum for o in members],
                              {"long_name": "angular momentum"}),
         "return_error": ("member", [o.return_error for o in members],
                          {"long_name": "relative return error of the converged orbit"}),
         "excursion": ("member", [o.motion.excursion for o in members],
                       {"long_name": "how far the orbit leaves its start, relative to its "
                                     "size (in the frame turning with it)"}),
         "turning": ("member", [o.motion.turning for o in members],
                     {"long_name": "full circles its velocity turns through over a period "
                                   "(at least 1 for a closed orbit)"}),
         "initial_state": (("member", "component"), np.array([o.state for o in members]),
                           {"long_name": "state at t = 0 (positions, then momenta)"}),
         "multiplier_real": (("member", "multiplier"), mu.real,
                             {"long_name": "non-trivial Floquet multipliers, real part"}),
         "multiplier_imag": (("member", "multiplier"), mu.imag,
                             {"long_name": "non-trivial Floquet multipliers, imaginary part"}),
         "index_real": (("member", "pair"), b.real,
                        {"long_name": "stability index (mu + 1/mu)/2, real part"}),
         "index_imag": (("member", "pair"), b.imag,
                        {"long_name": "stability index (mu + 1/mu)/2, imaginary part"}),
         "stable": ("member", np.array([o.stable for o in members], dtype=np.int8),
                    {"long_name": "1 where every non-trivial multiplier is on the unit "
                                  "circle"}),
         "kind": ("member", np.array([o.kind for o in members], dtype=object)),
         "bifurcation_parameter": ("bifurcation", [f.parameter for f in family.bifurcations],
                                   {"long_name": f"{table['parameter']} at a fold or where "
                                                 "multipliers leave or join the unit circle"}),
         "bifurcation_period": ("bifurcation", [f.period for f in family.bifurcations],
                                {"long_name": "period there"}),
         "bifurcation_accuracy": ("bifurcation", [f.accuracy for f in family.bifurcations],
                                  {"long_name": "how far the parameter may be off: the "
                                                "bisection's bracket, or the stability "
                                                "indices' error over their slope"}),
         "bifurcation_kind": ("bifurcation", np.array([f.kind for f in family.bifurcations],
                                                      dtype=object))},
        attrs={"title": f"periodic orbits along {table['parameter']}",
               "family": "periodic", "complete": int(family.complete),
               "ended": family.ended,
               "config": config_text})
    # the parameter labels the members (in energy: the pinned value, not the measured one)
    name = table["parameter"]
    return ds.drop_vars(name, errors="ignore").assign_coords(
        {name: ("member", family.parameters, {"long_name": name})})


def print_periodic(path, as_json_text: bool = False, output=None,
                   command: str = "python -m survey periodic") -> int:
    """The command: the orbit found, or with [periodic] parameter its family (and
    --output, the family's archive)."""
    _refuse_output(path, "periodic", output)
    system, table, found = solve_periodic(path)
    if table["parameter"]:
        family = found
        if output:
            ds = family_dataset(table, family, Path(path).read_text())
            print(f"wrote {write_archive(ds, output, command)}")
        print(json.dumps({"family": [periodic_json(o) for o in family.members],
                          table["parameter"]: family.parameters.tolist(),
                          "complete": family.complete, "ended": family.ended,
                          "bifurcations": [f._asdict() for f in family.bifurcations]},
                         indent=1) if as_json_text else
              periodic_family_text(system, table, family))
        return 0
    print(json.dumps(periodic_json(found), indent=1) if as_json_text else
          periodic_text(system, found))
    return 0


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
    return next((name for name in ("equilibria", "periodic") if name in raw), None)


def write_report(path, folder, draw=None) -> Path:
    """NAME.md in `folder` for a special-solution workflow: what it is (its config) and
    what was found, in the words the command prints; for a periodic family also NAME.png,
    its bifurcation diagram drawn by `draw(dataset, title)`."""
    path = Path(path)
    figure = None
    if special_table(path) == "equilibria":
        system, table, found = solve_equilibria(path)
        text = family_text(table, found) if table["parameter"] else \
            equilibria_text(system, table, found)
    else:
        system, table, found = solve_periodic(path)
        text = periodic_family_text(system, table, found) if table["parameter"] else \
            periodic_text(system, found)
        if table["parameter"] and draw is not None:     # plots.family_diagram
            figure = Path(folder) / f"{path.stem}.png"
            draw(family_dataset(table, found, path.read_text()),
                 _family_title(path, system, table, found)).savefig(figure, dpi=130)
    command = f"python -m survey {special_table(path)} {path.as_posix()}"
    out = Path(folder) / f"{path.stem}.md"
    body = (f"# {path.stem}\n\n`{command}` (written by `python -m survey reproduce`):\n\n"
            f"```\n{text}\n```\n\n"
            + (f"![bifurcation diagram]({figure.name})\n\n" if figure else "")
            + f"The workflow:\n\n```toml\n{path.read_text().strip()}\n```\n")
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(body)
    tmp.replace(out)
    return out


def _family_title(path, system, table, family) -> str:
    """What a periodic family's diagram is of: the workflow, the start, the parameter
    (and the J it is held at), the bodies and their terms."""
    start = f"Lyapunov family of normal mode {table['mode']}" if table["mode"] else "family"
    terms = " + ".join(f"{t.name} (" + ", ".join(f"{k} {v:g}" for k, v in zip(
        t.param_names, t.params)) + ")" for t in system.terms)
    spin = f" at J = {family.members[0].angular_momentum:.6g}" if table["rotating"] and \
        table["parameter"] == "energy" else ""
    return (f"{Path(path).stem}: {start} in {table['parameter']}{spin}; "
            f"{system.n_bodies} bodies, {terms}")


def equilibrium_cells(ds, most: int = 8) -> list[dict]:
    """The relative equilibria at an archive's `equilibrium` cells (at most `most`), each
    solved again from the cell's start at its J, with its stability and normal modes: what
    the report sets beside the family's frequencies. Cells where the solver finds none are
    left out."""
    from ..catalog.regimes import Regime
    from ..catalog.variables import V
    from .config import parse_config
    if V.regime not in ds or V.initial_state not in ds:
        return []
    cells = np.argwhere(ds[V.regime].values == Regime.EQUILIBRIUM)[:most]
    if not cells.size:
        return []
    config = parse_config(ds.attrs["config"], check_output=False)
    out = []
    for idx in map(tuple, cells):
        system = _cell_system(config, ds, idx)
        start = ds[V.initial_state].values[idx]
        spin = float(ds[V.angular_momentum].values[idx]) if system.dim == 2 else 0.0
        try:
            eq = relative_equilibrium(system, system.split(start)[0], angular_momentum=spin)
        except (ValueError, np.linalg.LinAlgError):
            continue
        out.append({"kind": "equilibrium",
                    "cell": cell_label(ds, idx), "index": idx,
                    "rotation_rate": eq.rotation_rate, "stable": eq.stable,
                    "frequencies": eq.frequencies.tolist(),
                    "krein": [int(k) for k in eq.krein if k],
                    "rates": eq.rates})
    return out


def homographic_period(system: System, y, horizon: float) -> float | None:
    """The period of the size of a homographic start -- a central configuration moving
    as a similarity (v_i = a q_i + b e_z x q_i, forces -lambda m_i q_i) keeps its shape
    while it breathes and turns: a relative periodic orbit -- from the time between the
    first two minima of its moment of inertia within `horizon`; None if the start is
    not homographic (or not planar), is a rigid rotation (an equilibrium's business), or
    does not breathe within the horizon."""
    if system.dim != 2:
        return None
    q, p = system.split(np.asarray(y, dtype=float))
    m = system.masses[:, None]
    q = q - np.sum(m * q, axis=0) / m.sum()
    v = p / m - np.sum(p, axis=0) / m.sum()
    gq = np.stack([-q[:, 1], q[:, 0]], axis=1)
    size = np.sum(m * q * q)
    a, b = np.sum(m * v * q) / size, np.sum(m * v * gq) / size
    acc = forces(system, q).reshape(q.shape) / m
    lam = -np.sum(m * acc * q) / size
    norm = lambda x: np.sqrt(np.sum(m * x * x))
    rigid = abs(a) <= 1e-9 * abs(b) and abs(lam - b * b) <= 1e-9 * lam
    if not (norm(v) > 0 and norm(v - a * q - b * gq) <= 1e-10 * norm(v) and lam > 0
            and norm(acc + lam * q) <= 1e-9 * norm(acc)) or rigid:
        return None
    times = np.linspace(0.0, horizon, 4001)
    out = integrate(system, y, horizon, t_eval=times, rtol=1e-12, atol=1e-12)
    if not out.ok:
        return None
    qs = system.split(out.samples)[0]
    inertia = np.sum(system.masses[None, :, None] * (qs - np.sum(
        system.masses[None, :, None] * qs, axis=1, keepdims=True) / m.sum()) ** 2, axis=(1, 2))
    low = np.flatnonzero((inertia[1:-1] < inertia[:-2]) & (inertia[1:-1] <= inertia[2:])) + 1
    return float(times[low[1]] - times[low[0]]) if low.size >= 2 else None


def homographic_cells(ds, most: int = 8) -> list[dict]:
    """The cells of an archive whose start is homographic (see homographic_period), each
    shot as a relative periodic orbit at its energy (`python -m survey periodic`): period,
    rotation, kind, how fast nearby orbits leave, beside the cell's own FTLE -- what the
    report sets beside a map's column of such cells. Cells where shooting fails are left
    out."""
    from ..catalog.variables import V
    from .config import parse_config
    if V.initial_state not in ds or V.status not in ds:
        return []
    config = parse_config(ds.attrs["config"], check_output=False)
    horizon = float(config.settings.integration.t_final)
    axes = list(ds[V.status].dims)
    starts = ds[V.initial_state].values.reshape(-1, ds[V.initial_state].shape[-1])
    out = []
    for flat, y in enumerate(starts):
        if len(out) == most or not np.all(np.isfinite(y)):
            continue
        system = _cell_system(config, ds, np.unravel_index(flat, ds[V.status].shape))
        period = homographic_period(system, y, min(horizon, 100.0))
        if period is None:
            continue
        try:
            orbit = periodic_orbit(system, y, period, rotating=True)
        except ValueError:
            continue
        idx = np.unravel_index(flat, ds[V.status].shape) if axes else ()
        ftle = float(ds[V.ftle].values[idx]) if V.ftle in ds else float("nan")
        out.append({"kind": "periodic", "index": idx,
                    "cell": cell_label(ds, idx),
                    "period": orbit.period, "rotation": orbit.rotation,
                    "orbit_kind": orbit.kind, "stable": orbit.stable,
                    "rates": orbit.rates.tolist(), V.ftle: ftle})
    return out


def _cell_system(config, ds, idx) -> System:
    """The System of an archive's cell at index `idx` of its grid: the [system] table with
    the cell's values of any interaction-term axes (read from the archive's coordinates,
    so a refined survey's cells are read too)."""
    values = cell_values(ds, idx)
    return build_system(config.system_table, {a.name: values[a.name] for a in config.axes
                                                  if a.term >= 0})


def special_cells(ds) -> list[dict]:
    """The special solutions an archive's cells start on, for its report: relative
    equilibria at its equilibrium cells, relative periodic orbits at its homographic
    ones."""
    ds = as_grid(ds)
    return equilibrium_cells(ds) + homographic_cells(ds)


def report_attributes(ds) -> dict[str, str]:
    """What a survey's report needs that only a solver computes, as attributes of its
    archive (JSON text): the special solutions its cells start on (special_cells) and the
    section coordinates a section grid fixes (section_slice). Written with the archive
    (pipeline.archive.write), so every reader -- `python -m survey report`,
    `ds.survey.report()` -- sets the same beside the cells without solving again."""
    def plain(x):
        if isinstance(x, np.integer):
            return int(x)
        if isinstance(x, (np.floating, np.bool_)):
            return x.item()
        if isinstance(x, np.ndarray):
            return x.tolist()
        raise TypeError(f"{type(x).__name__} is not JSON")
    return {"special_cells": json.dumps(special_cells(ds), default=plain),
            "section_slice": json.dumps(section_slice(ds))}


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
    if kind == "manifolds":
        from .orbits import verify_manifolds
        lines, what = verify_manifolds(stored, cells), "manifolds computed again differ"
        agree = (f"{stored.sizes['orbit']} orbits, {min(cells, stored.sizes['point'])} of "
                 f"{stored.sizes['point']} points and "
                 f"{min(1, stored.sizes.get('homoclinic', 0))} homoclinic point")
    else:
        with tempfile.TemporaryDirectory() as folder:
            config = Path(folder) / "family.toml"
            config.write_text(text)
            if kind == "periodic":
                _, table, family = solve_periodic(config)
                fresh = family_dataset(table, family, text)
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
    for key in ("title", "family", "complete", "ended"):
        if str(stored.attrs.get(key)) != str(fresh.attrs.get(key)):
            lines.append(f"attribute {key}: {str(stored.attrs.get(key))!r} stored, "
                         f"{str(fresh.attrs.get(key))!r} computed again")
    return lines


def section_slice(ds) -> dict:
    """The section coordinates (sigma, p_sigma, eta, p_eta) an archive's config fixes while
    its grid varies the others: the slice of the section a `section` grid is."""
    from .config import parse_config
    fixed = parse_config(ds.attrs["config"], check_output=False).fixed
    return {q: float(fixed[q]) for q in ("sigma", "p_sigma", "eta", "p_eta")
            if q in fixed and f"crossing_{q}" in ds}
