"""Every key a survey config may hold, declared once: its type, default, unit, allowed
range and meaning (data: pipeline.config validates against it, the documentation's configuration
tables are generated from it, and the tests check both)."""
from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any


from ..catalog import defaults
from ..catalog.indicators import INDICATORS, IndicatorOptions
from ..catalog.regimes import Thresholds
from ..catalog.variables import OBSERVABLES, V
from ..numerics.dop853 import RTOL_MIN
from ..numerics.sections import SURFACES
from ..physics.families import FAMILIES


_IND = IndicatorOptions()      # one set of defaults: the Python API's and the config's


@dataclass(frozen=True)
class Key:
    kind: str            # "int", "float", "bool", "str", "floats", "ints", "strs", "table"
    default: Any
    doc: str
    unit: str = ""
    low: float | None = None        # inclusive lower bound
    above: float | None = None      # exclusive lower bound
    choices: tuple | None = None
    high: float | None = None       # inclusive upper bound
    hint: str = ""                  # why the bounds are what they are, added to range errors


SCHEMA: dict[str, dict[str, Key]] = {
    "survey": {
        "name": Key("str", "survey", "name of the survey: archive title and default file name"),
        "output": Key("str", "", "archive path (default runs/<name>.nc, outside version control); its folder is "
                                 "created; checkpoints go to <output>.checkpoints/"),
    },
    "system": {
        "bodies": Key("int", defaults.BODIES, "number of bodies N (3 or more with a triplet "
                                              "term, 2 with pair terms, 1 in an external "
                                              "field alone)", low=1),
        "dim": Key("int", defaults.DIM, "dimension of space", choices=(2, 3)),
        "masses": Key("floats", None, "masses, one per body (default all 1)", "mass",
                      low=1e-100, high=1e100, hint="their products and squares (gravity's "
                      "m_i m_j, the kinetic energy) must stay finite in double precision"),
        "potential": Key("str", defaults.POTENTIAL, "triplet potential <measure>_<profile> "
                                                    "or axilrod_teller"),
        "params": Key("table", {}, "potential parameters, e.g. {coupling = 1, exponent = 2}; "
                                   "any may be a grid axis named <potential>_<parameter>"),
        "interactions": Key("terms", None, "the potential as a sum of terms, instead of "
                                           "potential/params: [{kind = \"pair\" or "
                                           "\"triplet\", potential = NAME, params = {...}}, "
                                           "...]; every parameter is given, any may be a grid "
                                           "axis named <potential>_<parameter>; a pair term "
                                           "with mass_weighted = true is U(r_ij) m_i m_j "
                                           "(the gravity term always is). A term written as a "
                                           "formula: {kind = \"pair\" (in r), \"triplet\" "
                                           "(symmetric in the sides a, b, c; P and A too) or "
                                           "\"external\" (in x, y, z, on every body), "
                                           "expression = \"...\", params = {name = value}}, "
                                           "its parameters' axes named "
                                           "<kind>_formula_<parameter>"),
    },
    "initial": {
        "family": Key("str", None, "initial-condition family", choices=tuple(FAMILIES)),
        "energy": Key("axis", None, "target energy: rescales centre-of-mass-frame velocities "
                                    "so that K + U = energy (cells with U > energy are "
                                    "inaccessible); a number or a grid axis", "energy"),
        "starts_per_cell": Key("int", 1, "seeded starts per grid point, for a family with a "
                                         "seed: a last grid axis `seed` of that many values "
                                         "from the family's seed; maps and reports give "
                                         "each point's regular share", low=1),
    },
    "integration": {
        "t_final": Key("float", defaults.T_FINAL, "integration time of every cell", "time",
                       above=0),
        "rtol": Key("float", defaults.RTOL, "relative tolerance of DOP853 (at least 10 eps = "
                                            "2.2e-15)", low=RTOL_MIN, high=1e-3,
                    hint="double precision cannot honour a smaller relative tolerance, and a "
                         "looser one gives orbits whose indicators mean nothing (1e-8 to "
                         "1e-13 are usual)"),
        "atol": Key("float", defaults.ATOL, "absolute tolerance of DOP853", above=0,
                    high=1e-3, hint="a looser tolerance gives orbits whose indicators mean "
                                    "nothing; 1e-8 to 1e-13 are usual"),
        "max_steps": Key("int", defaults.MAX_STEPS, "step attempts per orbit before "
                                                    "step_limit", low=1),
        "cell_time_limit": Key("float", 0.0, "wall-clock budget of each orbit of a cell "
                                             "(they run side by side as lanes), 0 for none; "
                                             "cells past it get status time_limit", "s",
                               low=0),
        "control_tangents": Key("bool", False, "include tangent vectors in the error norm"),
    },
    "indicators": {
        "which": Key("strs", list(INDICATORS), "indicators to compute; [] integrates "
                     "the orbit alone", choices=INDICATORS),
        "deviations": Key("int", _IND.deviations, "seeded deviation vectors per orbit (sali "
                                                  "and gali2 need 2)", low=1, high=64,
                           hint="each is integrated beside the orbit; more than a handful "
                                "add nothing to the exponent"),
        "seed": Key("int", _IND.seed, "seed of the deviation vectors and perturbed starts (with the cell's start)",
                    low=0),
        "renorm_interval": Key("float", _IND.renorm_interval, "time between "
                               "renormalisations of the deviation vectors", "time", above=0),
        "history_points": Key("int", _IND.history_points, "points of the convergence "
                                                          "histories", low=2),
        "project_flow": Key("bool", _IND.project_flow, "project deviation vectors off the "
                                                       "flow and grad H"),
        "perturbations": Key("int", _IND.perturbations, "orbits started perturbation_size "
                                                        "away, for the spread of ftle and "
                                                        "megno", low=0, high=1000,
                              hint="each is a whole orbit per cell; the spread converges "
                                   "like 1/sqrt(n)"),
        "perturbation_size": Key("float", _IND.perturbation_size, "relative size of those "
                                                                  "perturbations", above=0),
        "nudge": Key("float", _IND.nudge, "relative size of a seeded displacement of each "
                                          "cell's nominal start: the same survey with "
                                          "other last bits (a [check] run's; 0: none)",
                     low=0, high=1e-6),
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
    "outcomes": {
        "escape": Key("bool", True, "stop a cell where a body escapes (at escape_radius); "
                                    "false: every orbit runs on to t_final"),
        "escape_radius": Key("float", 0.0, "a body escapes when its distance from the others' "
                                          "centre of mass (in an external field: from the "
                                          "origin) rises through this radius with the kinetic "
                                          "energy of their relative motion above "
                                          "escape_binding: the cell stops there, status and "
                                          "regime escaped; 0: derived for bodies with pair "
                                          "terms (and the triple dipole) that have a well "
                                          "(twice the distance where the pair energy falls "
                                          "below 1e-3 of the well's depth), else none",
                              "length", low=0),
        "escape_binding": Key("float", None, "kinetic energy of the relative motion above "
                                             "which a body at escape_radius escapes "
                                             "(default: (N - 1) times the largest pair energy "
                                             "beyond half the radius; 0 in a field)", "energy",
                              low=0),
        "exits": Key("floats", None, "in an external field, directions (degrees in the x-y "
                                     "plane, from the x axis) of the exits of an open "
                                     "potential: escape_exit is the one nearest the direction "
                                     "the body escapes in (Henon-Heiles: 90, 210, 330)"),
        "thin": Key("float", 0.1, "a triangle is thin where |A|/P^2 is below this share of "
                                  "the equilateral's sqrt(3)/36: thin_share is the share of "
                                  "the run during which one was", above=0, high=1),
    },
    "tori": {
        "analyse": Key("bool", True, "weighted Birkhoff digits and frequency analysis of "
                                     "every orbit (needs 128 samples or more)"),
        "sample_interval": Key("float", defaults.SAMPLE_INTERVAL, "time between the orbit "
                               "samples they are computed from (NAFF sees frequencies up to "
                               "1/(2 interval))", "time", above=0),
        "observables": Key("strs", None, "observables of the Birkhoff averages (default: "
                                         "perimeter, inertia; in an external field the "
                                         "centre of mass's x, y (z) besides)",
                           choices=tuple(OBSERVABLES)),
        "lines": Key("int", defaults.NAFF_LINES, "NAFF lines per shape signal and half orbit",
                     low=1, high=50),
        "extend": Key("int", defaults.EXTEND, "a cell whose verdict changed from t_final / 2 "
                                              "to t_final, or whose evidence sits between "
                                              "a regular and a chaotic threshold, is "
                                              "integrated again to extend x t_final and "
                                              "decided again; 0: never",
                      low=0, high=16),
        "extend_rounds": Key("int", defaults.EXTEND_ROUNDS, "how many times a verdict still "
                                                            "in doubt is extended again "
                                                            "(each by the factor extend)",
                             low=1, high=4),
        **{f.name: Key(f.type if f.type in ("int", "float") else "float", f.default,
                       f.metadata["doc"]) for f in fields(Thresholds)},
    },
    "check": {
        "variants": Key("strs", list(defaults.CHECK_VARIANTS), "what each second run of the same "
                        "survey changes, one archive <output>_check_<variant>.nc each: "
                        + "; ".join(f"{k}: {v}" for k, v in defaults.CHECK_VARIANTS.items())
                        + "; the report gives each one's onset shift and their total",
                        choices=tuple(defaults.CHECK_VARIANTS)),
        "seed": Key("int", -1, "seed of the seed variant, with another ensemble "
                               "(-1: [indicators].seed + 1)", low=-1),
        "perturbations": Key("int", -1, "perturbed orbits per cell of the seed variant (-1: "
                                        "twice [indicators].perturbations, at least 8)",
                             low=-1, high=1000),
        "nudge": Key("float", 1e-13, "relative size of the displacement of each cell's "
                                     "nominal start in the seed and rounding variants "
                                     "([indicators] nudge): their orbits take other last "
                                     "bits, so every line of evidence can move, not only "
                                     "the ensemble's", low=0, high=1e-6),
        "tolerance": Key("float", 100.0, "factor on rtol and atol of the tolerance variant",
                         low=2.0, high=1e6),
    },
    "refine": {
        "max_level": Key("int", 4, "refinement steps after the grid: each halves the spacing "
                                   "of the cells it splits (a boundary is then known to the "
                                   "grid step / 2^max_level)", low=1, high=12,
                        hint="2^12 = 4096 halvings of a grid step are beyond what a finite-time "
                             "verdict can resolve"),
        "max_cells": Key("int", 0, "cells in all, the grid's included; a level that would pass "
                                   "it is not added (0: no limit but max_level)", low=0),
        "by": Key("str", "class", "what makes neighbouring cells disagree: their verdict "
                                  "class (regular, irregular, neither) or their regime",
                  choices=("class", V.regime)),
        "indicator": Key("str", "", "also split where this indicator jumps by more than "
                                    "`jump`, or changes by more than the factor `ratio`, "
                                    "between neighbours (its headline variable: ftle, megno, "
                                    "fli, sali, gali2, birkhoff_digits, "
                                    "frequency_diffusion)"),
        "jump": Key("float", 0.0, "that jump, in the indicator's units (0: none)", low=0),
        "ratio": Key("float", 0.0, "that factor, for positive indicators spanning decades "
                                   "such as ftle (0: none)", low=0),
        "tolerance": Key("float", 0.0, "one axis: a boundary is bisected until its interval "
                                       "is no wider than this (0: down to max_level)", low=0),
    },
    "reference": {
        "source": Key("str", "", "who published the regular shares below, and how they "
                                 "measured them (quoted beside them in the report)"),
        "axis": Key("str", "energy", "the grid axis the published values are at (the "
                                     "survey's one axis besides the seeds)"),
        "at": Key("floats", None, "the axis values they are at, each one of the grid's"),
        "regular_share": Key("floats", None, "the published regular share at each (0 to 1): "
                                             "the report sets each beside the survey's with "
                                             "its interval and says whether they agree"),
        "spread": Key("float", 0.0, "their stated spread, or how closely they can be read "
                                    "off a figure (absolute, 0 to 1)", low=0, high=1),
        "crossings": Key("int", 0, "the published shares were decided by how far two "
                                   "nearby orbits separated over this many crossings of "
                                   "the section: the report applies that criterion to "
                                   "survey's own orbits too (their deviation's growth by "
                                   "each cell's crossing of that number; needs [section] "
                                   "and the ftle indicator; 0: none)", low=0),
        "growth": Key("float", 0.0, "the largest growth of that separation the publication "
                                    "counted as regular", low=0),
    },
    "dask": {
        "workers": Key("int", 2, "local worker processes (1 thread each)", low=1, high=512,
                       hint="more workers than cores only queue; for more machines give "
                            "[dask].scheduler"),
        "scheduler": Key("str", "", "address of an existing dask scheduler, e.g. "
                                    "tcp://host:8786 (then workers is ignored)"),
        "connect_timeout": Key("float", 30.0, "seconds to wait for that scheduler to answer",
                               "s", above=0, high=3600),
        "chunk_size": Key("int", 0, "cells per task, whose orbits run as SIMD lanes; 0 "
                                    "picks four rounds of lanes (64 orbits, 128 where "
                                    "512-bit vectors run in full), or about 64 tasks per "
                                    "worker on large grids (at most 256 cells each), at "
                                    "least one task per worker, and a multiple of the "
                                    "workers of tasks where they are few; chunks interleave "
                                    "the grid so that every task mixes cheap and costly cells",
                          low=0),
        "retries": Key("int", 2, "retries of a task whose worker raised", low=0, high=100,
                       hint="a task that fails 100 times will fail again"),
    },
}


FLAGS = ("section_enabled", "check_enabled", "refine_enabled", "reference_enabled")   # whether a table was given
TYPES = {"str": "str", "int": "int", "float": "float", "bool": "bool",
         "floats": "list[float] | None", "ints": "list[int] | None", "strs": "list[str]",
         "table": "dict", "terms": "list[dict] | None", "axis": "Any"}


def record_name(table: str) -> str:
    return f"{table.title()}Table"


def records_source() -> str:
    """The text of pipeline/records.py: a frozen record per table of SCHEMA, its fields the
    table's keys with their types and meanings, and `Settings`, every table by name (what
    Config.settings holds, so that code outside the config module reads
    config.settings.integration.rtol, which a reader and a tool can follow, never a
    string-keyed table)."""
    out = ['"""The validated config as typed records, one per table of pipeline.schema.SCHEMA.',
           "",
           "Generated from the schema (python -m survey.pipeline.schema writes this file; the",
           'tests check it is current): edit the schema, not this file."""',
           "from __future__ import annotations", "", "from dataclasses import dataclass",
           "from typing import Any", ""]
    for table, keys in SCHEMA.items():
        out += ["", "@dataclass(frozen=True)", f"class {record_name(table)}:",
                f'    """[{table}]"""', ""]
        for key, spec in keys.items():
            field = f"    {key}: {TYPES[spec.kind]}".ljust(40)
            doc, room = " ".join(spec.doc.split()), 98 - len(field)
            out.append(field + "# " + (doc if len(doc) <= room else
                                       doc[:room - 3].rstrip() + "..."))
        out.append("")
    out += ["", "@dataclass(frozen=True)", "class Settings:",
            '    """Every table of a validated config, and whether the optional ones were',
            '    given."""', ""]
    out += [f"    {table}: {record_name(table)}" for table in SCHEMA]
    out += [f"    {flag}: bool" for flag in FLAGS]
    return "\n".join(out) + "\n"


if __name__ == "__main__":     # regenerate records.py beside this module
    from pathlib import Path
    Path(__file__).with_name("records.py").write_text(records_source())
