"""Interaction terms: which potentials exist, their parameters and the integer codes the
compiled kernels select them by.

A perimetric or areal triplet potential is U(x) of one shape measure x of the triangle: its
perimeter P ("perimetric") or the magnitude of its area |A| ("areal"). The Axilrod-Teller-
Muto triple dipole depends on the whole triangle. A pair potential is U(r) of a pair's
distance. The kernels take integer codes and a parameter array, so one compiled (and cached)
kernel serves every choice made at run time: numba cannot cache kernels that take other
jitted functions as arguments.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


# what a term depends on: a triangle's perimeter or area, the whole triangle (ATM), or a
# pair's distance; NONE marks "no perimetric or areal term" in the kernels' arguments
NONE, PERIMETER, AREA, TRIANGLE, DISTANCE = -1, 0, 1, 2, 3


POWER, YUKAWA, BARRIER, LENNARD_JONES = 0, 1, 2, 3


MEASURES = {"perimetric": PERIMETER, "areal": AREA}


# profile name -> (code, formula, ordered parameters with defaults)
PROFILES = {
    "power": (POWER, "coupling * {x}**exponent / exponent  (coupling * log({x}) if exponent == 0)",
              {"coupling": 1.0, "exponent": 2.0}),
    "yukawa": (YUKAWA, "-coupling * exp(-gamma * {x}) / {x}", {"coupling": 1.0, "gamma": 1.0}),
    "barrier": (BARRIER, "alpha / {x} + beta * {x}**2", {"alpha": 2.0, "beta": 1.0}),
}


ATM = "axilrod_teller"


ATM_FORMULA = "strength * (1 + 3 cos t_i cos t_j cos t_k) / (r_ij r_jk r_ki)**3"


TRIPLET_NAMES = tuple(f"{m}_{p}" for m in MEASURES for p in PROFILES) + (ATM,)


POTENTIAL_NAMES = TRIPLET_NAMES      # the [system].potential shorthand: one triplet term


# pair potential name -> (profile code, formula, ordered parameters with defaults); the
# repulsive pair Yukawa is the YUKAWA profile with its coupling negated
PAIR_PROFILES = {
    "lennard_jones": (LENNARD_JONES, "4 epsilon ((sigma / r)**12 - (sigma / r)**6)",
                      {"epsilon": 1.0, "sigma": 1.0}),
    "yukawa": (YUKAWA, "coupling * exp(-gamma * r) / r  (repulsive for coupling > 0)",
               {"coupling": 1.0, "gamma": 1.0}),
    "power": (POWER, "coupling * r**exponent / exponent  (coupling * log(r) if exponent == 0)",
              {"coupling": 1.0, "exponent": -1.0}),
}


PAIR_NAMES = tuple(PAIR_PROFILES)


KINDS = ("pair", "triplet")


@dataclass(frozen=True)
class Potential:
    """One term of a system's potential, chosen by kind and name: a triplet potential summed
    over all triangles, e.g. ``perimetric_power`` (the paper's P**2/2 with the defaults),
    ``areal_barrier`` (the paper's 2/|A| + |A|**2) or ``axilrod_teller``, or a pair
    potential summed over all pairs, e.g. ``lennard_jones``."""

    name: str
    measure: int
    profile: int
    params: tuple[float, ...]
    param_names: tuple[str, ...]

    @property
    def kind(self) -> str:
        return "pair" if self.measure == DISTANCE else "triplet"

    @property
    def par(self) -> np.ndarray:
        """The parameters as the kernels read them (a pair Yukawa's coupling negated)."""
        p = np.array(self.params, dtype=np.float64)
        if self.kind == "pair" and self.profile == YUKAWA:
            p[0] = -p[0]
        return p

    def describe(self) -> str:
        if self.kind == "pair":
            formula = PAIR_PROFILES[self.name][1]
        elif self.measure == TRIANGLE:
            formula = ATM_FORMULA
        else:
            x = "P" if self.measure == PERIMETER else "|A|"
            formula = PROFILES[self.name.split("_", 1)[1]][1].format(x=x)
        values = ", ".join(f"{k}={v:g}" for k, v in zip(self.param_names, self.params))
        return f"{self.name} ({self.kind}): U = {formula} with {values}"


def parameter_defaults(name: str, kind: str = "triplet") -> dict:
    """The parameters of a potential with their defaults; unknown names raise ValueError,
    with a hint when the name is a potential of the other kind."""
    if kind not in KINDS:
        raise ValueError(f"unknown interaction kind {kind!r}; choose one of {', '.join(KINDS)}")
    names, other, other_kind = ((PAIR_NAMES, TRIPLET_NAMES, "triplet") if kind == "pair"
                                else (TRIPLET_NAMES, PAIR_NAMES, "pair"))
    if name not in names:
        hint = (f" ({name!r} is a {other_kind} potential: give it kind = \"{other_kind}\")"
                if name in other else "")
        raise ValueError(f"unknown {kind} potential {name!r}; choose one of "
                         f"{', '.join(names)}{hint}")
    if kind == "pair":
        return dict(PAIR_PROFILES[name][2])
    if name == ATM:
        return {"strength": 1.0}
    return dict(PROFILES[name.split("_", 1)[1]][2])


def make_potential(name: str, params: dict | None = None, kind: str = "triplet") -> Potential:
    """Resolve a potential of a kind ("triplet" or "pair"), its name and its parameters;
    anything unknown, missing or out of range raises ValueError naming it."""
    params = dict(params or {})
    defaults = parameter_defaults(name, kind)
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise ValueError(f"potential {name!r} has no parameter {unknown[0]!r}; "
                         f"its parameters are {', '.join(defaults)}")
    values = {}
    for key, default in defaults.items():
        value = params.get(key, default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"potential parameter {key!r} must be a finite number, got {value!r}")
        values[key] = float(value)
    if values.get("gamma", 0.0) < 0:
        raise ValueError("potential parameter 'gamma' must be >= 0 (a screening rate)")
    if values.get("coupling") == 0:      # divides by it, and means "no term"
        raise ValueError("potential parameter 'coupling' must be nonzero")
    for key, what in (("epsilon", "a well depth"), ("sigma", "a length")):
        if key in values and not values[key] > 0:
            raise ValueError(f"potential parameter {key!r} must be > 0 ({what}), "
                             f"got {values[key]:g}")
    if kind == "pair":
        measure, code = DISTANCE, PAIR_PROFILES[name][0]
    elif name == ATM:
        measure, code = TRIANGLE, 0
    else:
        measure, profile_name = name.split("_", 1)
        measure, code = MEASURES[measure], PROFILES[profile_name][0]
    return Potential(name, measure, code, tuple(values.values()), tuple(defaults))
