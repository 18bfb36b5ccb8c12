"""Survey configuration: TOML (data only, never evaluated) -> validated, frozen settings.

Every key is declared once in SCHEMA (pipeline.schema) with its type, default, unit,
allowed range and meaning; validation happens before any work and each problem is one
`ConfigError` naming the key and what to do. The documentation's configuration reference is generated from SCHEMA (survey.reference).
"""
from __future__ import annotations

import difflib
import functools
import hashlib
import json
import math
import os
import re
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..analysis.refine import Lattice, Rule
from ..catalog import defaults
from ..catalog.errors import ConfigError
from ..catalog.indicators import BY_NAME as INDICATOR
from ..catalog.indicators import REGISTRY, TANGENT
from ..catalog.variables import V, default_observables, shape_dof
from ..numerics.sections import CARTESIAN, REDUCED_SURFACES
from ..numerics.torus import resonance_count
from ..physics.families import FAMILIES, family_parameters
from ..physics.system import System
from ..physics.terms import (
    EXPRESSION_KINDS,
    KINDS,
    PAIR_NAMES,
    TRIPLET_NAMES,
    make_expression,
    make_potential,
    parameter_defaults,
)
from ..numerics.events import escape_defaults
from .build import build_system, escape_for, section_event_for, term_axis_names
from .resources import check_address, check_memory, ensure_writable
from . import records
from .records import Settings
from .schema import FLAGS, SCHEMA, Key, record_name

INT64_MAX = 2 ** 63 - 1
TERM_KEYS = ("kind", "potential", "expression", "params", "mass_weighted")   # an entry


def settings_of(tables: dict) -> Settings:
    """Validated tables as typed records (pipeline.records)."""
    return Settings(**{table: getattr(records, record_name(table))(**tables[table])
                       for table in SCHEMA}, **{f: tables[f] for f in FLAGS})


@dataclass(frozen=True)
class Axis:
    """A grid axis: an [initial] parameter, or (term >= 0) parameter `param` of term
    number `term` of the system."""

    name: str
    values: np.ndarray
    term: int = -1
    param: str = ""


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
        out = self.tables["survey"]["output"] or f"runs/{self.name}.nc"
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

    @functools.cached_property
    def settings(self) -> Settings:
        """Every table as a typed record (pipeline.records): what code outside this module
        reads -- config.settings.integration.rtol -- rather than string-keyed tables."""
        return settings_of(self.tables)

    @property
    def resolved_text(self) -> str:
        """The config as it was run, every default filled in, as TOML: each table given or
        implied (an optional [section], [check] or [refine] only if enabled; absent
        values -- none or computed elsewhere -- left out), [initial] with the family's
        fixed parameters. Archived beside the text as written (`config_resolved`), so a
        reader needs no defaults of its own."""
        def plain(v):
            if isinstance(v, dict):
                return {k: plain(x) for k, x in v.items() if x is not None}
            if isinstance(v, (list, tuple)):
                return [plain(x) for x in v]
            return v.tolist() if isinstance(v, (np.ndarray, np.generic)) else v
        tables = {name: plain(body) for name, body in self.tables.items()
                  if isinstance(body, dict) and self.tables.get(f"{name}_enabled", True)}
        tables["initial"] = {**tables["initial"], **plain(self.fixed)}
        return _to_toml(tables)

    @property
    def system_table(self) -> dict:
        """The [system] table as build_system takes it (the form a [[plane]] table and a
        family's systems share)."""
        return self.tables["system"]

    def with_output(self, path) -> "Config":
        """The same survey written to another archive (the config itself is never
        changed: other readers may hold it)."""
        return replace(self, tables={**self.tables,
                                     "survey": {**self.tables["survey"], "output": str(path)}})

    def system(self, index: int = 0) -> System:
        """The System of flat cell `index` (the same for every cell unless a parameter of
        an interaction term is a grid axis)."""
        return build_system(self.tables["system"], self.axis_values(index, terms=True))

    @functools.cached_property
    def escape(self) -> tuple[float, float] | None:
        """(radius, binding) of the escapes the first cell's System watches for, or None
        (build.escape_for; whether there are escapes is the same for every cell)."""
        return escape_for(self.settings.outcomes, self.system())

    def cell_parameters(self, index: int) -> dict:
        """Family parameters (and target energy) of flat cell `index` (C order)."""
        return {**self.fixed, **self.axis_values(index, terms=False)}

    @property
    def refined(self) -> bool:
        """Whether the grid is refined where its cells disagree ([refine])."""
        return self.tables["refine_enabled"]

    def lattice(self) -> Lattice:
        """The nodes a refined survey can hold: the grid's intervals halved max_level
        times."""
        return Lattice(tuple(a.values for a in self.axes), self.tables["refine"]["max_level"])

    def rule(self) -> Rule:
        r = self.tables["refine"]
        return Rule(by=r["by"], indicator=r["indicator"], jump=r["jump"] or np.inf,
                    ratio=r["ratio"] or np.inf, tolerance=r["tolerance"],
                    max_cells=r["max_cells"] or 1 << 62)

    def fine(self) -> "Config":
        """The survey over every node of the refinement lattice: a cell's flat index there
        is its lattice id, so everything that reads a cell by its index (its start, its
        System, its task) reads a refined survey's cells."""
        lattice = self.lattice()
        axes = tuple(replace(a, values=lattice.axis_values(k)) for k, a in enumerate(self.axes))
        return replace(self, axes=axes)

    def axis_values(self, index: int, terms: bool) -> dict:
        at = np.unravel_index(index, self.shape) if self.axes else ()
        return {a.name: float(a.values[i]) for a, i in zip(self.axes, at)
                if (a.term >= 0) == terms}

    def checks(self) -> dict[str, "Config"]:
        """The [check] table's variants, each the survey again with one thing changed
        (defaults.CHECK_VARIANTS), by name, into <output>_check_<variant>.nc (its own archive, with
        its own config text); {} without [check]: what the report measures its claims
        against."""
        if not self.tables["check_enabled"]:
            return {}
        check = self.tables["check"]
        out = {}
        for variant in check["variants"]:
            raw = tomllib.loads(self.text)
            raw.pop("check")
            ind, integ = raw.setdefault("indicators", {}), raw.setdefault("integration", {})
            mine = self.tables["integration"]
            if variant == "seed":
                ind.update(seed=check["seed"], perturbations=check["perturbations"],
                           nudge=check["nudge"])
            elif variant == "rounding":
                ind["nudge"] = check["nudge"]
            elif variant == "horizon":
                integ["t_final"] = 2.0 * mine["t_final"]
            else:
                integ.update(rtol=check["tolerance"] * mine["rtol"],
                             atol=check["tolerance"] * mine["atol"])
            survey = raw.setdefault("survey", {})
            survey["name"] = f"{self.name}_check_{variant}"
            if survey.get("output"):    # the text names the file its own output implies
                path = Path(survey["output"])
                survey["output"] = str(defaults.check_archive(path, variant))
            second = validate(raw, _to_toml(raw), f"{self.source} [check] {variant}",
                              check_output=False).with_output(
                defaults.check_archive(self.output, variant))
            ensure_writable(second.output)
            out[variant] = second
        return out

    def result_key(self) -> str:
        """Hash of everything that determines the cells' results -- the result tables, the
        grid (axis names and values, fixed family parameters, cell count) -- and the code
        that computes them: checkpoints are reused only under it. [dask] and [survey] do not
        change results and are left out."""
        h = hashlib.sha256()
        # every [tori] threshold counts: the workers decide with them which cells run again
        # to a longer horizon, and store their verdicts at T/2 and T
        relevant = {k: v for k, v in self.tables.items()
                    if k not in ("dask", "survey", "check", "check_enabled")}
        h.update(json.dumps(relevant, sort_keys=True, default=_jsonable).encode())
        for axis in self.axes:
            h.update(f"axis {axis.name} {axis.values.size}\n".encode())
            h.update(np.ascontiguousarray(axis.values, dtype="<f8").tobytes())
        fixed = {k: np.asarray(v, dtype=float).tolist() for k, v in self.fixed.items()}
        h.update(json.dumps(fixed, sort_keys=True).encode())
        h.update(f"cells {self.n_cells}\n".encode())
        h.update(code_fingerprint().encode())
        return h.hexdigest()[:20]


def _jsonable(x):
    return x.tolist() if isinstance(x, np.ndarray) else str(x)


def code_fingerprint(root: Path | None = None) -> str:
    """sha256 of every Python module of the package (or of `root`), subpackages included,
    with their paths (a module moved or added changes it too)."""
    root = Path(__file__).parents[1] if root is None else Path(root)
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def load_config(source, check_output: bool = True) -> Config:
    """A Config from a TOML file path or a dict of tables (Python values: numpy scalars,
    tuples and 1-D arrays are taken as numbers and lists; None as "not given").
    check_output: also refuse an output the survey could not write."""
    if isinstance(source, dict):
        tables = _plain(source, "")
        return validate(tables, _to_toml(tables), "<dict>", check_output)
    if not isinstance(source, (str, os.PathLike)):
        raise ConfigError("config", f"expected a TOML file path or a dict of tables, got "
                                    f"{type(source).__name__}")
    path = Path(source)
    if "\0" in str(path):
        raise ConfigError("config", "the file name contains a NUL character")
    try:
        data = path.read_bytes()
    except IsADirectoryError:
        raise ConfigError(str(source), "is a folder; give a TOML file") from None
    except FileNotFoundError:
        raise ConfigError(str(source), "no such config file") from None
    except OSError as exc:
        raise ConfigError(str(source), f"cannot read it ({exc.strerror or exc})") from None
    return parse_config(_decode(data, str(source)), str(source), check_output)


def _decode(data: bytes, where: str) -> str:
    """TOML files are UTF-8: anything else is named, not decoded by guesswork."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ConfigError(where, "is UTF-16 text; TOML files are UTF-8: save it as UTF-8")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(where, f"is not UTF-8 text (byte {exc.start} is not valid); a "
                                 "config is a UTF-8 TOML file") from None


def read_toml(text: str, where: str) -> dict:
    """TOML text as tables; ConfigError naming `where` if it is not TOML, or is nested
    deeper than the parser can follow (it recurses: 2000 levels of [[[...]]])."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(where, f"not valid TOML ({exc}); fix the syntax") from None
    except RecursionError:
        raise ConfigError(where, "nests arrays or tables deeper than a config needs (or "
                                 "the TOML reader can follow); flatten it") from None


def parse_config(text: str, where: str = "<text>", check_output: bool = True) -> Config:
    """A Config from TOML text."""
    return validate(read_toml(text, where), text, where, check_output)


def _plain(value, where):
    """A Python value given to the API as the TOML value it stands for."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise ConfigError(f"{where}{k!r}", "table keys must be strings")
            if v is not None:
                out[k] = _plain(v, f"{where}[{k}]." if not where else f"{where}{k}.")
        return out
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, str):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, (list, tuple, np.ndarray)):
        if isinstance(value, np.ndarray) and value.ndim > 2:
            raise ConfigError(where.rstrip("."), f"expected a list, got a {value.ndim}-D array")
        return [_plain(v, where) for v in value]
    raise ConfigError(where.rstrip(".") or "config",
                      f"{type(value).__name__} is not a config value (numbers, strings, "
                      "booleans, lists and tables are)")


def _to_toml(tables: dict) -> str:
    """Minimal TOML writer for config dicts (so an API-given config is archived as text)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, float):
            return repr(v) if math.isfinite(v) else ("nan" if v != v else
                                                    ("inf" if v > 0 else "-inf"))
        if isinstance(v, int):
            return str(v)
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
        if isinstance(v, int) and abs(v) > INT64_MAX:
            raise ConfigError(where, f"{v} does not fit a 64-bit integer; use a value below "
                                     f"{INT64_MAX:.3g}")
        if isinstance(v, str) and "\0" in v:
            raise ConfigError(where, "contains a NUL character")
        if isinstance(v, str) and not v.isascii():
            try:
                v.encode("utf-8")
            except UnicodeEncodeError:
                raise ConfigError(where, f"{v!r} is not text that can be written (a lone "
                                         "surrogate); use ordinary characters") from None
        if spec.choices is not None and v not in spec.choices:
            raise ConfigError(where, f"{v!r} is not one of {', '.join(map(repr, spec.choices))}"
                              + (_suggest(v, spec.choices) if isinstance(v, str) else ""))
        hint = f"; {spec.hint}" if spec.hint else ""
        if spec.low is not None and v < spec.low:
            raise ConfigError(where, f"must be >= {spec.low:.3g}, got {v!r}{hint}")
        if spec.above is not None and not v > spec.above:
            raise ConfigError(where, f"must be > {spec.above:.3g}, got {v!r}{hint}")
        if spec.high is not None and v > spec.high:
            raise ConfigError(where, f"must be <= {spec.high:.3g}, got {v!r}{hint}")
    return value


def _kind_name(kind):
    return {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false",
            "floats": "numbers", "ints": "integers", "strs": "strings"}[kind]


def _axis_size(value) -> int:
    """Number of values of a grid axis as written (1 for a number or a malformed axis, which
    is reported later): lets the memory check run before any axis is allocated."""
    if isinstance(value, dict):
        num = value.get("num")
        return num if isinstance(num, int) and not isinstance(num, bool) and num > 1 else 1
    return max(len(value), 1) if isinstance(value, list) else 1


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
        with np.errstate(over="ignore", invalid="ignore"):
            arr = np.linspace(float(value["start"]), float(value["stop"]), num)
        if not np.all(np.isfinite(arr)):
            raise ConfigError(where, "start and stop are so far apart that the grid "
                                     "overflows; narrow the range")
    elif isinstance(value, list):
        if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                and math.isfinite(v) for v in value):
            raise ConfigError(where, f"a grid axis list needs finite numbers, got {value!r}")
        arr = np.array(value, dtype=float)
    else:
        raise ConfigError(where, f"expected a number, a list or {{start, stop, num}}, got "
                                 f"{value!r}")
    if np.unique(arr).size != arr.size:
        raise ConfigError(where, "grid axis values must be distinct (in double precision); "
                                 "widen the range or use fewer points")
    return arr


def check_table(table: str, keys: dict[str, Key], given) -> dict:
    """One table's values checked against its Keys, defaults filled in; an unknown key is
    named with the nearest known one ([initial] also holds family parameters, checked
    later)."""
    if not isinstance(given, dict):
        raise ConfigError(f"[{table}]", "must be a table")
    if table == "initial":
        given = {k: v for k, v in given.items() if k in keys}
    extra = sorted(set(given) - set(keys))
    if extra:
        raise ConfigError(f"[{table}].{extra[0]}", "unknown key" + _suggest(extra[0], keys)
                          + f"; keys of [{table}] are {', '.join(keys)}")
    return {key: (given[key] if spec.kind == "axis" else _check(table, key, spec, given[key]))
            if key in given else spec.default for key, spec in keys.items()}


def validate(raw: dict, text: str, where: str = "<config>", check_output: bool = True) -> Config:
    """Check every table and key; fill defaults; build the grid. Raises ConfigError."""
    unknown = sorted(set(raw) - set(SCHEMA))
    special = [name for name in unknown if name in ("equilibria", "periodic")]
    if special:
        raise ConfigError(f"[{special[0]}]", f"is read by `python -m survey {special[0]}`, "
                                              "not by a survey; run that command on this file")
    if unknown:
        raise ConfigError(f"[{unknown[0]}]", "unknown table" + _suggest(unknown[0], SCHEMA)
                          + f"; tables are {', '.join(SCHEMA)}")
    tables: dict[str, dict] = {}
    initial_raw = raw.get("initial", {})
    for table, keys in SCHEMA.items():
        tables[table] = check_table(table, keys, raw.get(table, {}))
    tables["section_enabled"] = "section" in raw
    tables["check_enabled"] = "check" in raw
    tables["refine_enabled"] = "refine" in raw
    tables["reference_enabled"] = "reference" in raw
    _validate_names(tables)
    check_memory(settings_of(tables), math.prod(_axis_size(v) for v in initial_raw.values())
                 * tables["initial"]["starts_per_cell"])

    term_axes = _validate_terms(tables["system"], raw.get("system", {}))
    system = _validate_system(tables["system"], term_axes)
    axes, fixed = _validate_initial(dict(initial_raw), tables["initial"], system)
    clash = {a.name for a in axes} & {a.name for a in term_axes}
    if clash:
        raise ConfigError(f"[initial].{sorted(clash)[0]}", "has the name of a grid axis of "
                                                          "an interaction term")
    axes = term_axes + axes
    _validate_cross(tables, system)
    if tables["refine_enabled"]:
        _validate_refine(tables, axes)
    if tables["reference_enabled"]:
        _validate_reference(tables, axes)
    config = Config(tables=tables, axes=tuple(axes), fixed=fixed, text=text, source=where)
    if check_output:
        ensure_writable(config.output, inputs=[where] if Path(where).is_file() else [])
    return config


def _validate_names(tables: dict):
    name = tables["survey"]["name"]
    if not name.strip() or name in (".", "..") or any(c in name for c in "/\\") \
            or any(ord(c) < 32 for c in name):
        raise ConfigError("[survey].name", f"{name!r} is not a usable name: it names the "
                                           "archive file, so no path separators, control "
                                           "characters or '..'; e.g. name = \"delta-map\"")
    address = tables["dask"]["scheduler"]
    if address:
        check_address(address)


def _validate_terms(s: dict, given: dict) -> list[Axis]:
    """Check the interaction terms (the potential/params shorthand, or interactions) and
    return the grid axes among their parameters."""
    if s["interactions"] is not None:
        both = sorted({"potential", "params"} & set(given))
        if both:
            raise ConfigError(f"[system].{both[0]}", "give either potential/params (one "
                                                    "triplet term) or interactions, not both")
        if not isinstance(s["interactions"], list) or not s["interactions"]:
            raise ConfigError("[system].interactions", "expected a list of tables like "
                              "{kind = \"pair\", potential = \"lennard_jones\", params = "
                              "{epsilon = 1.0, sigma = 1.0}}")
    grids = []         # (term, parameter, values); named once every term is known good
    for i, entry in enumerate(s["interactions"] or [None]):
        if entry is None:
            where, kind, name, params = "[system.params]", "triplet", s["potential"], s["params"]
        else:
            where = f"[system].interactions[{i}]"
            if not isinstance(entry, dict):
                raise ConfigError(where, f"expected a table {{kind, potential, params}}, got "
                                         f"{entry!r}")
            extra = sorted(set(entry) - set(TERM_KEYS))
            if extra:
                raise ConfigError(f"{where}.{extra[0]}", "unknown key" + _suggest(
                    extra[0], TERM_KEYS) + "; a term has kind, potential (or expression), "
                    "params and (pair and external terms) mass_weighted")
            if "expression" in entry:
                grids += _validate_formula(entry, where, i, s["dim"])
                continue
            for key in ("kind", "potential"):
                if not isinstance(entry.get(key), str):
                    raise ConfigError(f"{where}.{key}", "is required (a string): "
                                      + ("\"pair\" or \"triplet\"" if key == "kind"
                                         else "the potential's name"))
            kind, name, params = entry["kind"], entry["potential"], entry.get("params", {})
            if kind not in KINDS:
                raise ConfigError(f"{where}.kind", f"{kind!r} is not one of "
                                  f"{', '.join(map(repr, KINDS))}" + _suggest(kind, KINDS)
                                  + (" (an external field is written as a formula: "
                                     "expression = \"...\")" if kind == "external" else ""))
            if not isinstance(params, dict):
                raise ConfigError(f"{where}.params", f"expected a table, got {params!r}")
            weighted = entry.get("mass_weighted", False)
            if not isinstance(weighted, bool):
                raise ConfigError(f"{where}.mass_weighted", f"expected true or false, got "
                                                            f"{weighted!r}")
            if weighted and kind != "pair":
                raise ConfigError(f"{where}.mass_weighted", "applies to pair terms only (a "
                                  "triplet potential is a function of its triangle alone); "
                                  "remove it")
            where += ".params"
        label = "[system].potential" if entry is None else f"[system].interactions[{i}].potential"
        if entry is None and name in PAIR_NAMES:
            raise ConfigError(label, f"{name!r} is a pair potential; potential takes one "
                                     f"triplet term. Write interactions = [{{kind = \"pair\", "
                                     f"potential = \"{name}\", params = {{...}}}}]")
        try:
            allowed = parameter_defaults(name, kind)
        except ValueError as exc:
            same_kind = PAIR_NAMES if kind == "pair" else TRIPLET_NAMES
            raise ConfigError(label, str(exc) + _suggest(name, same_kind)) from None
        for key in params:
            if key not in allowed:
                raise ConfigError(f"{where}.{key}", f"not a parameter of {name}"
                                  + _suggest(key, allowed) + f"; it takes {', '.join(allowed)}")
        if entry is not None:
            missing = [k for k in allowed if k not in params]
            if missing:
                raise ConfigError(f"{where}.{missing[0]}", f"is missing: a term in "
                                  f"interactions gives every parameter of {name} "
                                  f"({', '.join(allowed)})")
        values, axes = _parameter_values(params, where, i)
        grids += axes
        # every value of every axis must make a valid term (the checks are per parameter)
        first = {k: v[0] for k, v in values.items()}
        for key, options in [(None, [None])] + list(values.items()):
            for v in options:
                try:
                    make_potential(name, {**first, key: v} if key else first, kind)
                except ValueError as exc:
                    bad = re.search(r"parameter '(\w+)'", str(exc))
                    at = f" (at the grid value {v:g})" if key and len(options) > 1 else ""
                    raise ConfigError(f"{where}.{bad.group(1)}" if bad else where,
                                      str(exc) + at) from None
    names = term_axis_names(s)
    return [Axis(names[i][key], grid, term=i, param=key) for i, key, grid in grids]


def _parameter_values(params: dict, where: str, i: int) -> tuple[dict, list]:
    """Each parameter of term i as the list of values it takes (one, or a grid axis's),
    and its grid axes as (term, parameter, values)."""
    values, grids = {}, []
    for key, value in params.items():
        grid = _axis(f"{where}.{key}", value)
        values[key] = [float(value)] if grid is None else grid.tolist()
        if grid is not None:
            grids.append((i, key, grid))
    return values, grids


def _validate_formula(entry: dict, where: str, i: int, dim: int) -> list:
    """An interactions entry written as a formula: its kind, its expression (parsed by the
    whitelist grammar of physics.expressions, nothing evaluated), its named parameters
    (numbers or grid axes) and mass_weighted, each checked at every grid value. Returns
    its parameters' grid axes as (term, parameter, values)."""
    if "potential" in entry:
        raise ConfigError(f"{where}.potential", "give potential (a built-in term) or "
                                                "expression (a formula), not both")
    kind, expression = entry.get("kind"), entry["expression"]
    if kind not in EXPRESSION_KINDS:
        raise ConfigError(f"{where}.kind", f"{kind!r} is not one of "
                          f"{', '.join(map(repr, EXPRESSION_KINDS))} (the kinds a formula "
                          "may be)" + (_suggest(kind, EXPRESSION_KINDS)
                                       if isinstance(kind, str) else ""))
    params = entry.get("params", {})
    if not isinstance(params, dict):
        raise ConfigError(f"{where}.params", f"expected a table of named numbers, got "
                                             f"{params!r}")
    weighted = entry.get("mass_weighted", False)
    values, grids = _parameter_values(params, f"{where}.params", i)
    first = {k: v[0] for k, v in values.items()}
    try:
        make_expression(kind, expression, first, weighted, dim)
    except ValueError as exc:
        key = "mass_weighted" if "mass_weighted" in str(exc) else \
            next((f"params.{k}" for k in params if f"{k!r}" in str(exc)), "expression")
        raise ConfigError(f"{where}.{key}", str(exc)) from None
    return grids


def _validate_system(s: dict, term_axes: list[Axis]) -> System:
    if s["masses"] is not None and len(s["masses"]) != s["bodies"]:
        raise ConfigError("[system].masses", f"needs {s['bodies']} values (one per body), "
                                            f"got {len(s['masses'])}")
    try:
        return build_system(s, {a.name: float(a.values[0]) for a in term_axes})
    except ValueError as exc:       # a body count the terms do not support
        raise ConfigError("[system].bodies", str(exc)) from None


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
    if system.n_bodies != 3 and not FAMILIES[family].any_n:
        raise ConfigError("[initial].family", f"{family!r} starts three bodies; [system].bodies "
                                              f"is {system.n_bodies} (explicit, equilibrium "
                                              "and microcanonical start any number)")
    axes, fixed = [], {}
    for key, value in given.items():
        if key in ("family", "starts_per_cell"):
            continue
        where = f"[initial].{key}"
        default = defaults.get(key)
        if key != "energy" and not isinstance(default, (int, float)):
            # vector parameters: a list of numbers of the default's shape, never an axis
            shape = np.asarray(default).tolist()
            if default is None:      # positions, velocities: one row per body
                default = np.zeros((system.n_bodies, system.dim))
                shape = f"{system.n_bodies} rows (one per body) of {system.dim} numbers"
            arr = np.asarray(value, dtype=object)
            if np.shape(arr) != np.shape(default) or not all(
                    isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) for v in np.ravel(arr)):
                raise ConfigError(where, f"expected finite numbers shaped like {shape}, got "
                                         f"{value!r}")
            fixed[key] = np.asarray(value, dtype=float)
            continue
        values = _axis(where, value)
        if values is None:
            fixed[key] = float(value)
        else:
            axes.append(Axis(key, values))
    starts = body["starts_per_cell"]
    if starts > 1:
        if "seed" not in defaults:
            raise ConfigError("[initial].starts_per_cell", f"family {family!r} has no seed: "
                              "its starts are not random (families with a seed: " + ", ".join(
                                  f for f in FAMILIES if "seed" in FAMILIES[f].defaults) + ")")
        if any(a.name == "seed" for a in axes):
            raise ConfigError("[initial].starts_per_cell", "seed is already a grid axis; "
                                                           "give one or the other")
        first = fixed.pop("seed", defaults["seed"])
        if first != int(first):
            raise ConfigError("[initial].seed", f"a seed is a whole number, got {first:g}")
        axes.append(Axis("seed", np.arange(first, first + starts, dtype=float)))
    return axes, fixed


def _validate_reference(tables: dict, axes: list[Axis]):
    """Published regular shares are compared with a sample's: the survey draws seeded
    starts at each value of one axis, and every published value sits on that axis."""
    ref = tables["reference"]
    if ref["crossings"]:
        if not tables["section_enabled"]:
            raise ConfigError("[reference].crossings", "counts crossings of the surface of "
                                                       "section: give a [section] table")
        if tables["section"]["max_crossings"] < ref["crossings"]:
            raise ConfigError("[reference].crossings", f"{ref['crossings']} crossings are "
                              f"more than [section] max_crossings = "
                              f"{tables['section']['max_crossings']} keeps")
        if V.ftle not in tables["indicators"]["which"]:      # the indicator that fills it
            raise ConfigError("[reference].crossings", "reads the deviation's growth from "
                                                       "the ftle history: add 'ftle' to "
                                                       "[indicators] which")
        if not ref["growth"] > 1:
            raise ConfigError("[reference].growth", "give the largest growth of the "
                                                    "separation counted regular (> 1)")
    others = [a for a in axes if a.name != "seed"]
    if len(others) == len(axes) or len(others) != 1:
        raise ConfigError("[reference]", "compares published regular shares with a sample "
                          "of seeded starts along one axis: give [initial] starts_per_cell "
                          "> 1 and one other grid axis" + (f" (the grid has {len(others)})"
                                                           if others else ""))
    if others[0].name != ref["axis"]:
        raise ConfigError("[reference].axis", f"{ref['axis']!r} is not the survey's axis "
                                              f"({others[0].name})")
    if not ref["source"].strip():
        raise ConfigError("[reference].source", "say who published the values and how they "
                                                "measured them")
    at, share = ref["at"] or [], ref["regular_share"] or []
    if not at or len(at) != len(share):
        raise ConfigError("[reference].regular_share", f"needs one value per entry of at "
                                                       f"({len(at)}), got {len(share)}")
    for v in share:
        if not 0.0 <= v <= 1.0:
            raise ConfigError("[reference].regular_share", f"{v:g} is not a share in [0, 1]")
    grid = others[0].values
    for v in at:
        if not np.any(np.abs(grid - v) <= 1e-9 * max(1.0, abs(v))):
            raise ConfigError("[reference].at", f"{v:g} is not a value of the axis "
                              f"{ref['axis']} ({', '.join(f'{g:g}' for g in grid[:8])}"
                              + (", ..." if grid.size > 8 else "") + ")")


# the variables a refinement may follow: each indicator's headline
REFINE_INDICATORS = tuple(i.headline for i in REGISTRY)


def _validate_refine(tables: dict, axes: list[Axis]):
    r = tables["refine"]
    if not 1 <= len(axes) <= 2:
        raise ConfigError("[refine]", f"refines a grid over one or two axes; this one has "
                                      f"{len(axes)}" + (" (give the others single values)"
                                                        if axes else " (make a parameter an "
                                                        "axis)"))
    for a in axes:
        if a.name == "seed":
            raise ConfigError("[refine]", "splits parameter cells by their regimes; a grid "
                                          "of seeded starts (seed, starts_per_cell) is a sample, "
                                          "not a place to bisect: drop one or the other")
        where = f"[system] {a.name}" if a.term >= 0 else f"[initial].{a.name}"
        if a.values.size < 2:
            raise ConfigError(where, "a refined axis needs at least two values")
        if np.any(np.diff(a.values) <= 0):
            raise ConfigError(where, "a refined axis must be increasing: refinement splits "
                                     "the intervals between neighbours; sort the values")
    if not (tables["indicators"]["which"] or tables["tori"]["analyse"]):
        raise ConfigError("[refine]", "splits cells whose regimes differ, and with [indicators] "
                                      "which = [] and [tori] analyse = false nothing decides a "
                                      "regime; compute indicators")
    if r["indicator"]:
        if r["indicator"] not in REFINE_INDICATORS:
            raise ConfigError("[refine].indicator", f"{r['indicator']!r} is not one of "
                              f"{', '.join(REFINE_INDICATORS)}"
                              + _suggest(r["indicator"], REFINE_INDICATORS))
        owner = next(i for i in REGISTRY if r["indicator"] in i.variables)
        tangent = owner.source == TANGENT
        if not (owner.name in tables["indicators"]["which"] if tangent
                else tables["tori"]["analyse"]):
            raise ConfigError("[refine].indicator", f"{r['indicator']} is not computed by "
                              "this survey: " + (f"add {owner.name!r} to [indicators] which"
                                                 if tangent else "set [tori] analyse = true"))
        if not (r["jump"] > 0 or r["ratio"] > 0):
            raise ConfigError("[refine].jump", f"(or ratio) is needed with indicator = "
                                               f"{r['indicator']!r}: the change that splits")
        if 0 < r["ratio"] <= 1:
            raise ConfigError("[refine].ratio", f"is a factor above 1 (1.1: a change of 10%), "
                                                f"got {r['ratio']!r}")
    elif r["jump"] > 0 or r["ratio"] > 0:
        which = "jump" if r["jump"] > 0 else "ratio"
        raise ConfigError(f"[refine].{which}", "needs an indicator to measure it on: set "
                                               "[refine] indicator")
    if r["tolerance"] > 0 and len(axes) != 1:
        raise ConfigError("[refine].tolerance", "applies to one axis (a bisection); a map "
                                                "over two stops at max_level")
    base = math.prod(a.values.size for a in axes)
    if r["max_cells"] and r["max_cells"] < base:
        raise ConfigError("[refine].max_cells", f"is below the {base} cells of the grid it "
                                                "refines; raise it (or 0: no limit)")


RESONANCE_VECTORS = 10 ** 6    # integer vectors the resonance search may compare with


def _validate_thresholds(tori: dict, dof: int):
    """Each line of evidence's regular threshold on its regular side of the chaotic one
    (inverted, they would relabel cells), the widths positive, and the resonance order
    within what the search can enumerate for the system's shape frequencies."""
    for vote in (i.vote for i in REGISTRY if i.vote):
        name = vote.thresholds
        regular, chaotic = tori[f"{name}_regular"], tori[f"{name}_chaotic"]
        if not vote.sign * (regular - chaotic) >= 0:
            side = "at or above" if vote.sign > 0 else "at or below"
            raise ConfigError(f"[tori].{name}_regular", f"{regular!r} must be {side} "
                              f"{name}_chaotic = {chaotic!r}: larger {name} is more "
                              f"{'regular' if vote.sign > 0 else 'chaotic'}, and the values "
                              "between the two vote neither way")
    for key in ("resonance_width", "harmonic_width"):
        if not tori[key] >= 0:
            raise ConfigError(f"[tori].{key}", f"must be >= 0, got {tori[key]!r}")
    order = tori["resonance_order"]
    if order < 0:
        raise ConfigError("[tori].resonance_order", f"must be >= 0 (0: no search), got "
                                                    f"{order}")
    if resonance_count(dof, order) > RESONANCE_VECTORS:
        most = max(k for k in range(1, order) if resonance_count(dof, k) <= RESONANCE_VECTORS)
        raise ConfigError("[tori].resonance_order", f"{order} would compare every orbit with "
                          f"{resonance_count(dof, order):.3g} integer vectors (|m|_1 <= order "
                          f"over {dof} shape frequencies); at most {RESONANCE_VECTORS:.0e}: "
                          f"use at most {most}")


def _validate_outcomes(out: dict, system: System):
    field = not system.translation_invariant
    if out["exits"] is not None:
        if not field:
            raise ConfigError("[outcomes].exits", "are the exits of an external field's "
                              "potential; free bodies escape in every direction (drop exits)")
        if not out["exits"]:
            raise ConfigError("[outcomes].exits", "give at least one direction, or drop exits")
        if out["escape_radius"] <= 0:
            raise ConfigError("[outcomes].exits", "need escape_radius: the distance from the "
                              "origin at which the body has left through an exit")
    if field and out["escape_binding"] is not None:
        raise ConfigError("[outcomes].escape_binding", "bounds what other bodies pull an "
                          "escaping one back with; in an external field the radius alone "
                          "decides (drop escape_binding)")
    if out["escape"] and out["escape_radius"] > 0 and out["escape_binding"] is None \
            and not field and escape_defaults(system, out["escape_radius"]) is None:
        raise ConfigError("[outcomes].escape_binding", "cannot be derived for this system "
                          "(only for pair terms and the triple dipole): give the kinetic "
                          "energy of relative motion above which a body at escape_radius "
                          "escapes")


def _validate_cross(tables: dict, system: System):
    ind, sec, integ = tables["indicators"], tables["section"], tables["integration"]
    needy = [name for name in ind["which"] if INDICATOR[name].deviations > ind["deviations"]]
    if needy:
        need = max(INDICATOR[name].deviations for name in needy)
        raise ConfigError("[indicators].deviations", f"{' and '.join(needy)} need {need} "
                          f"deviation vectors; set deviations = {need} or drop them from which")
    if ind["deviations"] > system.n:
        raise ConfigError("[indicators].deviations", f"{ind['deviations']} deviation vectors "
                          f"in a {system.n}-dimensional phase space cannot be independent; "
                          f"use at most {system.n}")
    cores = os.cpu_count() or 1
    if not tables["dask"]["scheduler"] and tables["dask"]["workers"] > 4 * cores:
        raise ConfigError("[dask].workers", f"{tables['dask']['workers']} local worker "
                          f"processes on a machine with {cores} cores would only queue and "
                          f"use memory; use at most {4 * cores}, or [dask].scheduler for a "
                          "cluster")
    if ind["renorm_interval"] > integ["t_final"]:
        raise ConfigError("[indicators].renorm_interval", "is longer than t_final")
    if tables["tori"]["extend"] == 1:
        raise ConfigError("[tori].extend", "1 would decide a verdict in doubt again at the same "
                                           "horizon; use 0 (never) or a factor of 2 or more")
    if tables["check_enabled"]:
        check = tables["check"]
        if not ind["which"]:
            raise ConfigError("[check]", "compares the indicators of two ensembles, and "
                                         "[indicators] which = [] computes none; drop [check] "
                                         "or choose indicators")
        if check["seed"] < 0:
            check["seed"] = ind["seed"] + 1
        if check["perturbations"] < 0:
            check["perturbations"] = max(8, 2 * ind["perturbations"])
        if not check["variants"] or len(set(check["variants"])) < len(check["variants"]):
            raise ConfigError("[check].variants", "names each variant once and at least "
                                                  f"one of {', '.join(defaults.CHECK_VARIANTS)}; "
                                                  "or drop [check]")
        if "seed" in check["variants"] and (check["seed"], check["perturbations"],
                                            check["nudge"]) == \
                (ind["seed"], ind["perturbations"], ind["nudge"]):
            raise ConfigError("[check]", "the same seed, perturbations and nudge as "
                                         "[indicators] would repeat the survey bit for bit; "
                                         "change one")
        if "rounding" in check["variants"] and check["nudge"] == ind["nudge"]:
            raise ConfigError("[check].nudge", "equals [indicators].nudge, so the rounding "
                                               "variant would repeat the survey bit for bit; "
                                               "give it another value (1e-13 is usual)")
    field = not system.translation_invariant
    tor = tables["tori"]
    if tor["observables"] is None:
        tor["observables"] = default_observables(system.n_bodies, system.dim, field)
    if tor["analyse"] and not tor["observables"]:
        raise ConfigError("[tori].observables", "needs at least one observable (or set "
                                                "analyse = false)")
    for name in tor["observables"]:
        if name in CARTESIAN and not field:
            raise ConfigError("[tori].observables", f"{name!r} is the centre of mass's "
                              "coordinate, which moves uniformly without an external field: "
                              "use perimeter or inertia")
        if name in CARTESIAN and CARTESIAN.index(name) >= system.dim:
            raise ConfigError("[tori].observables", f"{name!r} needs dim = 3")
        if name not in CARTESIAN and system.n_bodies == 1:
            raise ConfigError("[tori].observables", f"{name!r} is a shape's, and one body "
                              "has none: use x, y" + (", z" if system.dim == 3 else ""))
    _validate_thresholds(tor, shape_dof(system.n_bodies, system.dim, field))
    _validate_outcomes(tables["outcomes"], system)
    if tables["section_enabled"]:
        coord = sec["coordinate"]
        if coord in REDUCED_SURFACES and (system.n_bodies != 3 or system.dim != 2):
            raise ConfigError("[section].coordinate", f"{coord!r} is a reduced coordinate of "
                                                      "three bodies in the plane")
        if coord in CARTESIAN and not field:
            raise ConfigError("[section].coordinate", f"{coord!r} is the centre of mass's "
                              "coordinate, which without an external field moves uniformly "
                              "and crosses a plane once at most")
        if coord == "linear" and (sec["coefficients"] is None
                                  or len(sec["coefficients"]) != system.n):
            raise ConfigError("[section].coefficients", f"a 'linear' surface needs {system.n} "
                                                        "coefficients (one per state component)")
        trip = sec["triplet"]
        uses = coord not in ("linear", *REDUCED_SURFACES, *CARTESIAN) or list(trip) != [0, 1, 2]
        if uses and (len(trip) != 3 or len(set(trip)) != 3 or max(trip) >= system.n_bodies):
            raise ConfigError("[section].triplet", f"needs three different bodies of "
                                                   f"0..{system.n_bodies - 1}, got {trip}")
        if sec["value"] is None:
            sec["value"] = math.pi / 2 if coord == "phi" else 0.0
        try:
            section_event_for(records.SectionTable(**sec), system)
        except ValueError as exc:
            raise ConfigError("[section]", str(exc)) from None
