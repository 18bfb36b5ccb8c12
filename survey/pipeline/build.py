"""What a worker builds from a config's tables: a cell's System (its interaction terms, with
the values of any term parameter that is a grid axis), its indicator options and its
surface of section."""
from __future__ import annotations

from dataclasses import fields

import numpy as np

from ..catalog.indicators import IndicatorOptions
from ..numerics.events import escape_defaults
from ..numerics.sections import section_event
from ..physics.system import System
from ..physics.terms import make_expression, make_potential, parameter_defaults


def system_terms(s: dict) -> list[tuple[str, str, dict]]:
    """(kind, potential, params as written) of each term of a [system] table; a term
    written as a formula is named <kind>_formula."""
    if s["interactions"] is None:
        return [("triplet", s["potential"], s["params"])]
    return [(t["kind"], t.get("potential") or f"{t['kind']}_formula", t.get("params", {}))
            for t in s["interactions"]]


def term_axis_names(s: dict) -> list[dict]:
    """Per term, the grid-axis name of each of its parameters: <potential>_<parameter>,
    or <potential>_<k>_<parameter> (k = 1, 2, ...) when the potential occurs twice; a
    formula's named parameters as <kind>_formula_<parameter>."""
    terms = system_terms(s)
    names = [name for _, name, _ in terms]
    seen: dict[str, int] = {}
    out = []
    for kind, name, params in terms:
        seen[name] = seen.get(name, 0) + 1
        label = name if names.count(name) == 1 else f"{name}_{seen[name]}"
        keys = params if name.endswith("_formula") else parameter_defaults(name, kind)
        out.append({key: f"{label}_{key}" for key in keys})
    return out


def build_system(s: dict, at: dict | None = None) -> System:
    """The System of a validated [system] table; `at` gives the values of term parameters
    by axis name -- a grid axis, or a family's parameter -- whether [system] wrote them or
    left them at their defaults. A name that is no parameter of the system's terms raises
    ValueError: a value that reached no term would be a silent no-op."""
    masses = s["masses"] if s["masses"] is not None else [1.0] * s["bodies"]
    at = at or {}
    terms, used = [], set()
    entries = s["interactions"] or [{}]
    for (kind, name, params), axis_names, entry in zip(system_terms(s), term_axis_names(s),
                                                       entries):
        values = dict(params)
        for key, axis in axis_names.items():
            if axis in at:
                values[key] = at[axis]
                used.add(axis)
        w = entry.get("mass_weighted", False)
        terms.append(make_expression(kind, entry["expression"], values, w, s["dim"])
                     if "expression" in entry else make_potential(name, values, kind, w))
    if set(at) - used:
        raise ValueError(f"{sorted(set(at) - used)[0]!r} is no parameter of the system's "
                         "terms")
    return System(np.array(masses, dtype=float), s["dim"], tuple(terms))


def indicator_options(i) -> IndicatorOptions:
    """The IndicatorOptions of a validated [indicators] table (records.IndicatorsTable)."""
    return IndicatorOptions(**{f.name: getattr(i, f.name) for f in fields(IndicatorOptions)})


def section_event_for(sec, system: System):
    """The surface of section of a validated [section] table (records.SectionTable)."""
    return section_event(system, sec.coordinate, sec.value, sec.direction,
                         tuple(sec.triplet), sec.coefficients)


def escape_for(out, system: System) -> tuple[float, float] | None:
    """(radius, binding) of the escapes of a validated [outcomes] table
    (records.OutcomesTable) in `system`, or None where none are watched."""
    radius, binding = out.escape_radius, out.escape_binding
    if not out.escape:
        return None
    if not system.translation_invariant:
        return (radius, 0.0) if radius > 0 else None
    if radius > 0 and binding is not None:
        return radius, binding
    derived = escape_defaults(system, radius)
    if derived is None:
        return None
    return derived[0], derived[1] if binding is None else binding
