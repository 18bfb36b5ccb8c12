"""Special solutions of a config's system near the config's [initial] start: its relative
equilibria with their linear stability (`python -m survey equilibria CONFIG.toml`), and the
periodic orbit through the start with its Floquet multipliers (`python -m survey periodic
CONFIG.toml`).

The config is a survey's: [system] as in a survey, the start as one [initial] family
member (`family = "explicit"` with `positions` and `velocities` for any start; equilibria
use its positions only), plus an [equilibria] or a [periodic] table."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np

from ..catalog.errors import ConfigError, SurveyError
from ..numerics.periodic import PeriodicOrbit, periodic_orbit
from ..physics.equilibria import RelativeEquilibrium, relative_equilibria
from ..physics.system import System
from .cells import build_starts
from .config import Key, _check, _decode, _suggest, validate

EQUILIBRIA = {
    "angular_momentum": Key("float", None, "angular momentum J of the rotation (in the "
                                           "plane); default: the [initial] start's"),
    "rotation_rate": Key("float", None, "rotation rate Omega instead of J (an isochronous "
                                        "potential, P^2/2, fixes Omega for every size)"),
    "starts": Key("int", 0, "seeded random configurations tried besides the start (the "
                            "start's size, normal about its centre)", low=0, high=10000),
    "seed": Key("int", 0, "seed of those configurations", low=0),
}


PERIODIC = {
    "period": Key("float", None, "the period's guess (required)", "time", above=0),
    "rotating": Key("bool", False, "a relative periodic orbit: it returns rotated (the plane)"),
    "energy": Key("float", None, "the energy to find it at (default: the start's)", "energy"),
    "tol": Key("float", 1e-13, "rtol = atol of the shooting's integrations", low=2.2e-15,
               high=1e-6),
}


def _load(path, name: str, keys: dict):
    """(system, start state, the [name] table with defaults filled in) from a config
    file; ConfigError naming the key for anything wrong."""
    path = Path(path)
    try:
        text = _decode(path.read_bytes(), str(path))
    except OSError as exc:
        raise ConfigError(str(path), f"cannot read it ({exc.strerror or exc})") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(str(path), f"not valid TOML ({exc}); fix the syntax") from None
    given = raw.pop(name, {})
    if not isinstance(given, dict):
        raise ConfigError(f"[{name}]", "must be a table")
    extra = sorted(set(given) - set(keys))
    if extra:
        raise ConfigError(f"[{name}].{extra[0]}", "unknown key" + _suggest(extra[0], keys)
                          + f"; keys of [{name}] are {', '.join(keys)}")
    table = {k: _check(name, k, spec, given[k]) if k in given else spec.default
             for k, spec in keys.items()}
    config = validate(raw, text, str(path), check_output=False)
    if config.n_cells != 1:
        raise ConfigError("[initial]", f"has a grid of {config.n_cells} starts; give the one "
                                       "start to search from (no grid axes)")
    start = build_starts(config)[0]
    if np.isnan(start[0]):
        raise ConfigError("[initial]", "the start is inaccessible at this energy")
    return config.system(), start, table


def load_equilibria(path) -> tuple[System, np.ndarray, dict]:
    """(system, start positions (N, d), the [equilibria] table)."""
    system, start, table = _load(path, "equilibria", EQUILIBRIA)
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
    return system, system.split(start)[0], table


def find_equilibria(path) -> tuple[System, dict, list[RelativeEquilibrium]]:
    system, start, table = load_equilibria(path)
    found = relative_equilibria(system, start, table["angular_momentum"],
                                table["rotation_rate"], table["starts"], table["seed"])
    return system, table, found


def equilibria_json(found: list[RelativeEquilibrium]) -> dict:
    return {"equilibria": [{
        "positions": e.positions.tolist(), "rotation_rate": e.rotation_rate,
        "energy": e.energy, "angular_momentum": e.angular_momentum,
        "eigenvalues": [[float(z.real), float(z.imag)] for z in e.eigenvalues],
        "frequencies": e.frequencies.tolist(),
        "krein": [int(k) for k, z in zip(e.krein, e.eigenvalues) if k],
        "stable": e.stable, "residual": e.residual} for e in found]}


def equilibria_text(system: System, table: dict, found: list[RelativeEquilibrium]) -> str:
    given = f"J = {table['angular_momentum']:g}" if table["angular_momentum"] is not None \
        else f"Omega = {table['rotation_rate']:g}"
    lines = [f"Relative equilibria of {system.n_bodies} bodies ({system.describe()}) at "
             f"{given}, from the start and {table['starts']} seeded configurations: "
             f"{len(found)} distinct (up to rotations, reflections and permutations)."]
    for k, e in enumerate(found):
        i, j = np.triu_indices(system.n_bodies, 1)
        dist = np.linalg.norm(e.positions[i] - e.positions[j], axis=1)
        modes = ", ".join(f"{f:.10g} ({'+' if s > 0 else '-'})" for f, s in zip(
            e.frequencies, e.krein[e.krein != 0])) or "none"
        unstable = [z for z in e.eigenvalues if z.real > 0 and
                    abs(z.real) > 1e-7 * max(np.abs(e.eigenvalues).max(), 1.0)]
        lines += ["", f"{k + 1}. E = {e.energy:.10g}, J = {e.angular_momentum:.10g}, "
                      f"Omega = {e.rotation_rate:.10g}: "
                      + ("linearly stable" if e.stable else "unstable"),
                  "   mutual distances " + ", ".join(f"r{a}{b} = {r:.10g}" for a, b, r in
                                                     zip(i, j, dist)),
                  f"   normal modes in the rotating frame (cycles per unit time, Krein "
                  f"sign): {modes}"]
        if unstable:
            lines.append("   growth rates: " + ", ".join(
                f"{z.real:.10g}" + (f" +- {abs(z.imag):.6g} i" if abs(z.imag) > 1e-12 else "")
                for z in unstable))
    return "\n".join(lines)


def print_equilibria(path, as_json_text: bool = False) -> int:
    system, table, found = find_equilibria(path)
    print(json.dumps(equilibria_json(found), indent=1) if as_json_text else
          equilibria_text(system, table, found))
    return 0


def load_periodic(path) -> tuple[System, np.ndarray, dict]:
    """(system, start state, the [periodic] table)."""
    system, start, table = _load(path, "periodic", PERIODIC)
    if table["period"] is None:
        raise ConfigError("[periodic].period", "is required: a guess of the period")
    if table["rotating"] and system.dim != 2:
        raise ConfigError("[periodic].rotating", "relative periodic orbits are found in the "
                                                 "plane ([system] dim = 2)")
    return system, start, table


def find_periodic(path) -> tuple[System, dict, PeriodicOrbit]:
    system, start, table = load_periodic(path)
    try:
        orbit = periodic_orbit(system, start, table["period"], table["rotating"],
                               table["energy"], table["tol"])
    except ValueError as exc:
        raise SurveyError(f"{path}: {exc}; try another [periodic] period or start") from None
    return system, table, orbit


def periodic_json(orbit: PeriodicOrbit) -> dict:
    return {"period": orbit.period, "rotation": orbit.rotation, "energy": orbit.energy,
            "angular_momentum": orbit.angular_momentum,
            "initial_state": orbit.state.tolist(), "return_error": orbit.return_error,
            "newton_residuals": orbit.residuals.tolist(),
            "multipliers": [[float(z.real), float(z.imag)] for z in orbit.multipliers],
            "stable": orbit.stable, "kind": orbit.kind, "rates": orbit.rates.tolist()}


def periodic_text(system: System, orbit: PeriodicOrbit) -> str:
    turn = f", returning rotated by {orbit.rotation:.10g} rad" if orbit.rotation else ""
    spin = orbit.angular_momentum if abs(orbit.angular_momentum) > 1e-12 else 0.0
    lines = [f"Periodic orbit of {system.n_bodies} bodies ({system.describe()}): period "
             f"{orbit.period:.11g}{turn}; E = {orbit.energy:.10g}, J = {spin:.10g}.",
             "Newton shooting, return error |y(T) - y(0)| / |y(0)| before each step and "
             "after the last: " + ", ".join(f"{r:.1e}" if r >= 1e-12 else "< 1e-12"
                                            for r in orbit.residuals) + ".",
             "Non-trivial Floquet multipliers (|mu|, angle/pi): " + ", ".join(
                 f"{abs(z):.9f} {np.angle(z) / np.pi:+.6f}" for z in orbit.multipliers)
             + f": {orbit.kind}" + (", linearly stable." if orbit.stable else
                                    ", unstable; nearby orbits leave at rates " + ", ".join(
                                        f"{r:.6g}" for r in orbit.rates) + " per unit time.")]
    return "\n".join(lines)


def print_periodic(path, as_json_text: bool = False) -> int:
    system, _, orbit = find_periodic(path)
    print(json.dumps(periodic_json(orbit), indent=1) if as_json_text else
          periodic_text(system, orbit))
    return 0


def special_table(path) -> str | None:
    """'equilibria' or 'periodic' if the config file has that table (a special-solution
    workflow), else None."""
    try:
        raw = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError):
        return None
    return next((name for name in ("equilibria", "periodic") if name in raw), None)


def write_report(path, folder) -> Path:
    """NAME.md in `folder` for a special-solution workflow: what it is (its config) and
    what was found, in the words the command prints."""
    path = Path(path)
    if special_table(path) == "equilibria":
        system, table, found = find_equilibria(path)
        text = equilibria_text(system, table, found)
    else:
        system, _, orbit = find_periodic(path)
        text = periodic_text(system, orbit)
    command = f"python -m survey {special_table(path)} {path.as_posix()}"
    out = Path(folder) / f"{path.stem}.md"
    body = (f"# {path.stem}\n\n`{command}` (written by `python -m survey reproduce`):\n\n"
            f"```\n{text}\n```\n\nThe workflow:\n\n```toml\n{path.read_text().strip()}\n```\n")
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(body)
    tmp.replace(out)
    return out
