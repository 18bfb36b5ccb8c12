"""Survey configuration: TOML (data only, never evaluated) -> validated, frozen settings.

Every key is declared once in SCHEMA with its type, default, unit, allowed range and meaning;
validation happens before any work and each problem is one `ConfigError` naming the key and
what to do. The README's configuration table is checked against SCHEMA by the tests.
"""
from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .coordinates import REDUCED_SURFACES, SURFACES
from .families import FAMILIES, family_parameters
from .dynamics import System
from .indicators import IndicatorOptions
from .potentials import POTENTIAL_NAMES, PROFILES, make_potential

INDICATOR_NAMES = ("ftle", "megno", "fli", "sali", "gali2")


class ConfigError(ValueError):
    """A bad configuration: one line naming the key and the fix."""

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}")
        self.key = key


@dataclass(frozen=True)
class Key:
    kind: str            # "int", "float", "bool", "str", "floats", "ints", "strs", "table"
    default: Any
    doc: str
    unit: str = ""
    low: float | None = None        # inclusive lower bound
    above: float | None = None      # exclusive lower bound
    choices: tuple | None = None


SCHEMA: dict[str, dict[str, Key]] = {
    "survey": {
        "name": Key("str", "survey", "name of the survey: archive title and default file name"),
        "output": Key("str", "", "archive path (default results/<name>.nc); its folder is "
                                 "created; checkpoints go to <output>.checkpoints/"),
    },
    "system": {
        "bodies": Key("int", 3, "number of bodies N", low=3),
        "dim": Key("int", 2, "dimension of space", choices=(2, 3)),
        "masses": Key("floats", None, "masses, one per body (default all 1)", "mass", above=0),
        "potential": Key("str", "perimetric_power", "triplet potential <measure>_<profile>",
                         choices=POTENTIAL_NAMES),
        "params": Key("table", {}, "potential parameters, e.g. {coupling = 1, exponent = 2}"),
    },
    "initial": {
        "family": Key("str", None, "initial-condition family", choices=tuple(FAMILIES)),
        "energy": Key("axis", None, "target energy: rescales centre-of-mass-frame velocities "
                                    "so that K + U = energy (cells with U > energy are "
                                    "inaccessible); a number or a grid axis", "energy"),
    },
    "integration": {
        "t_final": Key("float", 2000.0, "integration time of every cell", "time", above=0),
        "rtol": Key("float", 1e-12, "relative tolerance of DOP853", above=0),
        "atol": Key("float", 1e-12, "absolute tolerance of DOP853", above=0),
        "max_steps": Key("int", 10_000_000, "step attempts per orbit before step_limit", low=1),
        "cell_time_limit": Key("float", 0.0, "wall-clock budget per cell, 0 for none "
                                             "(cells past it get status time_limit)", "s",
                               low=0),
        "control_tangents": Key("bool", False, "include tangent vectors in the error norm"),
    },
    "indicators": {
        "which": Key("strs", list(INDICATOR_NAMES), "indicators to compute; [] integrates "
                     "the orbit alone", choices=INDICATOR_NAMES),
        "deviations": Key("int", 2, "seeded deviation vectors per orbit (sali and gali2 need "
                                    "2)", low=1),
        "seed": Key("int", 0, "seed of the deviation vectors (with the cell index)", low=0),
        "renorm_interval": Key("float", 1.0, "time between renormalisations of the deviation "
                                             "vectors", "time", above=0),
        "history_points": Key("int", 64, "points of the convergence histories", low=2),
        "project_flow": Key("bool", False, "project deviation vectors off the flow and grad H"),
        "perturbations": Key("int", 2, "orbits started perturbation_size away, for the "
                                       "spread of ftle and megno", low=0),
        "perturbation_size": Key("float", 1e-9, "relative size of those perturbations",
                                 above=0),
    },
    "section": {
        "coordinate": Key("str", "phi", "surface coordinate = value", choices=SURFACES),
        "value": Key("float", None, "surface value (default pi/2 for phi, else 0)"),
        "direction": Key("int", 1, "+1 coordinate increasing, -1 decreasing, 0 both",
                         choices=(-1, 0, 1)),
        "max_crossings": Key("int", 200, "crossings kept per cell (all are counted)", low=1),
        "triplet": Key("ints", [0, 1, 2], "bodies of the triangle for side/area surfaces",
                       low=0),
        "coefficients": Key("floats", None, "state coefficients of a 'linear' surface"),
        "store_state": Key("bool", False, "also store the Cartesian state at each crossing"),
    },
    "dask": {
        "workers": Key("int", 2, "local worker processes (1 thread each)", low=1),
        "scheduler": Key("str", "", "address of an existing dask scheduler, e.g. "
                                    "tcp://host:8786 (then workers is ignored)"),
        "chunk_size": Key("int", 0, "cells per task; 0 picks about 64 tasks per worker "
                                    "(at most 256 cells each); chunks interleave the grid so "
                                    "that every task mixes cheap and costly cells", low=0),
        "retries": Key("int", 2, "retries of a task whose worker raised", low=0),
    },
}
# [initial] also takes the family's own parameters; any numeric one may be a grid axis.


@dataclass(frozen=True)
class Axis:
    name: str
    values: np.ndarray


@dataclass(frozen=True, eq=False)
class Config:
    """A validated survey configuration. `tables` holds every value with defaults filled
    in; `axes` the grid axes in the order written; `fixed` the other family parameters."""

    tables: dict
    axes: tuple[Axis, ...]
    fixed: dict
    text: str
    source: str

    # ---- derived views
    @property
    def name(self) -> str:
        return self.tables["survey"]["name"]

    @property
    def output(self) -> Path:
        out = self.tables["survey"]["output"] or f"results/{self.name}.nc"
        return Path(out)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.values.size for a in self.axes)

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.text.encode()).hexdigest()

    def system(self) -> System:
        s = self.tables["system"]
        masses = s["masses"] if s["masses"] is not None else [1.0] * s["bodies"]
        return System(np.array(masses, dtype=float), s["dim"],
                      make_potential(s["potential"], s["params"]))

    def indicator_options(self) -> IndicatorOptions:
        i = self.tables["indicators"]
        return IndicatorOptions(deviations=i["deviations"], seed=i["seed"],
                                renorm_interval=i["renorm_interval"],
                                history_points=i["history_points"],
                                project_flow=i["project_flow"],
                                perturbations=i["perturbations"],
                                perturbation_size=i["perturbation_size"])

    def cell_parameters(self, index: int) -> dict:
        """Family parameters (and target energy) of flat cell `index` (C order)."""
        params = dict(self.fixed)
        for axis, i in zip(self.axes, np.unravel_index(index, self.shape) if self.axes else ()):
            params[axis.name] = float(axis.values[i])
        return params

    def result_key(self) -> str:
        """Hash of everything that determines the cells' results (not dask or output
        settings), plus the code that computes them: checkpoints are reused only under it."""
        relevant = {k: v for k, v in self.tables.items() if k not in ("dask", "survey")}
        blob = json.dumps(relevant, sort_keys=True, default=_jsonable).encode()
        return hashlib.sha256(blob + code_fingerprint().encode()).hexdigest()[:20]


def _jsonable(x):
    return x.tolist() if isinstance(x, np.ndarray) else str(x)


def code_fingerprint() -> str:
    """sha256 of survey's own source files."""
    h = hashlib.sha256()
    for path in sorted(Path(__file__).parent.glob("*.py")):
        h.update(path.read_bytes())
    return h.hexdigest()


# ---------------------------------------------------------------- loading

def load_config(source) -> Config:
    """A Config from a TOML file path or a dict of tables."""
    if isinstance(source, dict):
        return validate(source, _to_toml(source), "<dict>")
    path = Path(source)
    if not path.is_file():
        raise ConfigError(str(source), "no such config file")
    return parse_config(path.read_text(), str(path))


def parse_config(text: str, where: str = "<text>", check_output: bool = True) -> Config:
    """A Config from TOML text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(where, f"not valid TOML ({exc}); fix the syntax") from None
    return validate(raw, text, where, check_output)


def _to_toml(tables: dict) -> str:
    """Minimal TOML writer for config dicts (so an API-given config is archived as text)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, float, np.integer, np.floating)):
            return repr(float(v)) if isinstance(v, (float, np.floating)) else str(int(v))
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, dict):
            return "{" + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + "}"
        return "[" + ", ".join(val(x) for x in v) + "]"
    lines = []
    for table, body in tables.items():
        if not isinstance(body, dict):
            raise ConfigError(table, "top-level entries must be tables like [system]")
        lines.append(f"[{table}]")
        lines += [f"{k} = {val(v)}" for k, v in body.items()]
        lines.append("")
    return "\n".join(lines)


def _suggest(word, options):
    close = difflib.get_close_matches(word, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _check(table: str, key: str, spec: Key, value):
    where = f"[{table}].{key}"
    kinds = {"int": int, "float": (int, float), "str": str, "bool": bool}
    if spec.kind in kinds:
        ok = isinstance(value, kinds[spec.kind]) and not (
            spec.kind in ("int", "float") and isinstance(value, bool))
        if not ok:
            raise ConfigError(where, f"expected {_kind_name(spec.kind)}, got {value!r}")
        items = [value]
    elif spec.kind in ("floats", "ints", "strs"):
        inner = {"floats": (int, float), "ints": int, "strs": str}[spec.kind]
        if not isinstance(value, list) or not all(
                isinstance(v, inner) and not isinstance(v, bool) for v in value):
            raise ConfigError(where, f"expected a list of {_kind_name(spec.kind)}, got {value!r}")
        items = value
    elif spec.kind == "table":
        if not isinstance(value, dict):
            raise ConfigError(where, f"expected a table like {{key = value}}, got {value!r}")
        return value
    else:
        return value
    for v in items:
        if isinstance(v, float) and not math.isfinite(v):
            raise ConfigError(where, f"must be finite, got {v!r}")
        if spec.choices is not None and v not in spec.choices:
            raise ConfigError(where, f"{v!r} is not one of {', '.join(map(repr, spec.choices))}"
                              + (_suggest(v, spec.choices) if isinstance(v, str) else ""))
        if spec.low is not None and v < spec.low:
            raise ConfigError(where, f"must be >= {spec.low:g}, got {v!r}")
        if spec.above is not None and not v > spec.above:
            raise ConfigError(where, f"must be > {spec.above:g}, got {v!r}")
    return value


def _kind_name(kind):
    return {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false",
            "floats": "numbers", "ints": "integers", "strs": "strings"}[kind]


def _axis(where: str, value) -> np.ndarray | None:
    """A grid axis from {start, stop, num} or a list of numbers; None for a plain number."""
    if isinstance(value, bool):
        raise ConfigError(where, f"expected a number or a grid axis, got {value!r}")
    if isinstance(value, (int, float)):
        if not math.isfinite(value):
            raise ConfigError(where, f"must be finite, got {value!r}")
        return None
    if isinstance(value, dict):
        keys = {"start", "stop", "num"}
        extra = sorted(set(value) - keys)
        if extra:
            raise ConfigError(f"{where}.{extra[0]}", "a grid axis takes only start, stop, num"
                              + _suggest(extra[0], keys))
        missing = sorted(keys - set(value))
        if missing:
            raise ConfigError(where, f"a grid axis needs {', '.join(sorted(keys))}; "
                                     f"{missing[0]} is missing")
        for k in ("start", "stop"):
            if isinstance(value[k], bool) or not isinstance(value[k], (int, float)) \
                    or not math.isfinite(value[k]):
                raise ConfigError(f"{where}.{k}", f"expected a finite number, got {value[k]!r}")
        num = value["num"]
        if isinstance(num, bool) or not isinstance(num, int) or num < 1:
            raise ConfigError(f"{where}.num", f"must be an integer >= 1, got {num!r}")
        return np.linspace(float(value["start"]), float(value["stop"]), num)
    if isinstance(value, list):
        if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                and math.isfinite(v) for v in value):
            raise ConfigError(where, f"a grid axis list needs finite numbers, got {value!r}")
        arr = np.array(value, dtype=float)
        if np.unique(arr).size != arr.size:
            raise ConfigError(where, "grid axis values must be distinct")
        return arr
    raise ConfigError(where, f"expected a number, a list or {{start, stop, num}}, got {value!r}")


def validate(raw: dict, text: str, where: str = "<config>", check_output: bool = True) -> Config:
    """Check every table and key; fill defaults; build the grid. Raises ConfigError."""
    unknown = sorted(set(raw) - set(SCHEMA))
    if unknown:
        raise ConfigError(f"[{unknown[0]}]", "unknown table" + _suggest(unknown[0], SCHEMA)
                          + f"; tables are {', '.join(SCHEMA)}")
    tables: dict[str, dict] = {}
    initial_raw = dict(raw.get("initial", {}))
    for table, keys in SCHEMA.items():
        given = raw.get(table, {})
        if not isinstance(given, dict):
            raise ConfigError(f"[{table}]", "must be a table")
        if table == "initial":
            given = {k: v for k, v in given.items() if k in keys}
        else:
            extra = sorted(set(given) - set(keys))
            if extra:
                raise ConfigError(f"[{table}].{extra[0]}", "unknown key"
                                  + _suggest(extra[0], keys)
                                  + f"; keys of [{table}] are {', '.join(keys)}")
        body = {}
        for key, spec in keys.items():
            if key in given:
                body[key] = _check(table, key, spec, given[key]) if spec.kind != "axis" \
                    else given[key]
            else:
                body[key] = spec.default
        tables[table] = body
    tables["section_enabled"] = "section" in raw

    system = _validate_system(tables["system"])
    axes, fixed = _validate_initial(initial_raw, tables["initial"], system)
    _validate_cross(tables, system)
    config = Config(tables=tables, axes=tuple(axes), fixed=fixed, text=text, source=where)
    if check_output:
        ensure_writable(config.output)
    return config


def _validate_system(s: dict) -> System:
    if s["masses"] is not None and len(s["masses"]) != s["bodies"]:
        raise ConfigError("[system].masses", f"needs {s['bodies']} values (one per body), "
                                            f"got {len(s['masses'])}")
    measure, _, profile = s["potential"].partition("_")
    allowed = PROFILES[profile][2]
    for key, value in s["params"].items():
        if key not in allowed:
            raise ConfigError(f"[system.params].{key}", f"not a parameter of {s['potential']}"
                              + _suggest(key, allowed) + f"; it takes {', '.join(allowed)}")
    try:
        masses = s["masses"] if s["masses"] is not None else [1.0] * s["bodies"]
        return System(np.array(masses, float), s["dim"], make_potential(s["potential"],
                                                                        s["params"]))
    except ValueError as exc:
        raise ConfigError("[system.params]", str(exc)) from None


def _validate_initial(given: dict, body: dict, system: System):
    family = body["family"]
    if family is None:
        raise ConfigError("[initial].family", "is required; choose one of " + ", ".join(FAMILIES))
    defaults = family_parameters(family)
    own = set(SCHEMA["initial"])
    extra = sorted(set(given) - own - set(defaults))
    if extra:
        raise ConfigError(f"[initial].{extra[0]}", f"not a parameter of family {family!r}"
                          + _suggest(extra[0], list(defaults) + list(own))
                          + f"; it takes {', '.join(defaults)}")
    if system.n_bodies != 3:
        raise ConfigError("[initial].family", f"{family!r} starts three bodies; [system].bodies "
                                              f"is {system.n_bodies}")
    axes, fixed = [], {}
    for key, value in given.items():
        if key == "family":
            continue
        where = f"[initial].{key}"
        default = defaults.get(key)
        if key != "energy" and not isinstance(default, (int, float)):
            # vector parameters: a list of numbers of the default's shape, never an axis
            arr = np.asarray(value, dtype=object)
            if np.shape(arr) != np.shape(default) or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool)
                    for v in np.ravel(arr)):
                raise ConfigError(where, f"expected numbers shaped like {list(map(list, default)) if np.ndim(default) == 2 else list(default)}, got {value!r}")
            fixed[key] = np.asarray(value, dtype=float)
            continue
        values = _axis(where, value)
        if values is None:
            fixed[key] = float(value)
        else:
            axes.append(Axis(key, values))
    return axes, fixed


def _validate_cross(tables: dict, system: System):
    ind, sec, integ = tables["indicators"], tables["section"], tables["integration"]
    if {"sali", "gali2"} & set(ind["which"]) and ind["deviations"] < 2:
        raise ConfigError("[indicators].deviations", "sali and gali2 need 2 deviation vectors; "
                                                     "set deviations = 2 or drop them from which")
    if ind["renorm_interval"] > integ["t_final"]:
        raise ConfigError("[indicators].renorm_interval", "is longer than t_final")
    if tables["section_enabled"]:
        coord = sec["coordinate"]
        if coord in REDUCED_SURFACES and (system.n_bodies != 3 or system.dim != 2):
            raise ConfigError("[section].coordinate", f"{coord!r} is a reduced coordinate of "
                                                      "three bodies in the plane")
        if coord == "linear" and (sec["coefficients"] is None
                                  or len(sec["coefficients"]) != system.n):
            raise ConfigError("[section].coefficients", f"a 'linear' surface needs {system.n} "
                                                        "coefficients (one per state component)")
        trip = sec["triplet"]
        if len(trip) != 3 or len(set(trip)) != 3 or max(trip) >= system.n_bodies:
            raise ConfigError("[section].triplet", f"needs three different bodies of "
                                                   f"0..{system.n_bodies - 1}, got {trip}")
        if sec["value"] is None:
            sec["value"] = math.pi / 2 if coord == "phi" else 0.0
        try:
            section_event_for(tables, system)
        except ValueError as exc:
            raise ConfigError("[section]", str(exc)) from None


def section_event_for(tables: dict, system: System):
    from .coordinates import section_event
    sec = tables["section"]
    return section_event(system, sec["coordinate"], sec["value"], sec["direction"],
                         tuple(sec["triplet"]), sec["coefficients"])


def ensure_writable(path: Path):
    folder = path.parent if str(path.parent) else Path(".")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".survey-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ConfigError("[survey].output", f"cannot write to {folder} ({exc.strerror}); "
                                             "choose a writable path") from None
    if path.exists() and path.is_dir():
        raise ConfigError("[survey].output", f"{path} is a folder; give a file name")
