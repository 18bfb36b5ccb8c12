"""Interaction terms, each declared once in TERMS: its kind, name, formula, the integer codes
the compiled kernels select it by, and its parameters with their defaults, bounds and
meaning. `make_potential`'s checks, the config's error messages, the documentation's table of
potentials and a test battery run on every term (tests/physics/test_terms.py) all come from
these declarations.

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

# what a term depends on: a triangle's perimeter or area, the whole triangle (ATM), a
# pair's distance, a triangle's three sides (a formula), one body's position (a formula);
# NONE marks "no perimetric or areal term" in the kernels' arguments
NONE, PERIMETER, AREA, TRIANGLE, DISTANCE, SIDES, POSITION = -1, 0, 1, 2, 3, 4, 5
# the profiles U(x) the kernels evaluate (physics.forces.profile); a term written as a
# formula is an EXPRESSION: its values come from its program (physics.expressions), and
# the forces of a formula in one measure take them as the GIVEN profile (U', U'')
POWER, YUKAWA, BARRIER, LENNARD_JONES, EXPRESSION, GIVEN = 0, 1, 2, 3, 4, 5
KINDS = ("pair", "triplet")
EXPRESSION_KINDS = ("pair", "triplet", "external")


@dataclass(frozen=True)
class Parameter:
    """A term's parameter: its default, what it means, and the values it may take."""

    name: str
    default: float
    doc: str
    above: float | None = None      # exclusive lower bound
    low: float | None = None        # inclusive lower bound
    nonzero: bool = False

    def problem(self, value) -> str:
        """Why `value` is not allowed ("" if it is)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            return f"must be a finite number, got {value!r}"
        if self.above is not None and not value > self.above:
            return f"must be > {self.above:g} ({self.doc}), got {value:g}"
        if self.low is not None and value < self.low:
            return f"must be >= {self.low:g} ({self.doc}), got {value:g}"
        if self.nonzero and value == 0:
            return f"must be nonzero ({self.doc}; zero means no term)"
        return ""

    def describe(self) -> str:
        bound = (f" (> {self.above:g})" if self.above is not None else
                 f" (>= {self.low:g})" if self.low is not None else
                 " (nonzero)" if self.nonzero else "")
        return f"{self.name} = {self.default:g}{bound}"


@dataclass(frozen=True)
class Term:
    """A kind of interaction term: `formula` gives U in the variables of `measure`."""

    kind: str                       # "triplet" (summed over triangles) or "pair"
    name: str
    measure: int                    # PERIMETER, AREA, TRIANGLE or DISTANCE
    profile: int                    # POWER, YUKAWA, BARRIER or LENNARD_JONES (0 for ATM)
    formula: str
    parameters: tuple[Parameter, ...]
    note: str = ""                  # the paper's case, or what it models
    weighted: bool = False          # a pair term always weighted by m_i m_j (gravity)

    @property
    def defaults(self) -> dict:
        return {p.name: p.default for p in self.parameters}


def _power(x, exponent):
    return (Parameter("coupling", 1.0, "strength; its sign sets attraction", nonzero=True),
            Parameter("exponent", exponent, "power of " + x))


def _yukawa():
    return (Parameter("coupling", 1.0, "strength; its sign sets attraction", nonzero=True),
            Parameter("gamma", 1.0, "a screening rate", low=0.0))


def _barrier():
    return (Parameter("alpha", 2.0, "strength of the barrier at x -> 0"),
            Parameter("beta", 1.0, "strength of the confining x^2"))


def _triplets(measure, code, x):
    return [
        Term("triplet", f"{measure}_power", code, POWER,
             f"coupling {x}^exponent / exponent (coupling ln {x} for exponent 0)",
             _power(x, 2.0), "the paper's P^2/2" if x == "P" else ""),
        Term("triplet", f"{measure}_yukawa", code, YUKAWA,
             f"-coupling exp(-gamma {x}) / {x}", _yukawa(), "the screened colloid form"),
        Term("triplet", f"{measure}_barrier", code, BARRIER, f"alpha / {x} + beta {x}^2",
             _barrier(), "the paper's 2/|A| + |A|^2" if x == "|A|" else ""),
    ]


TERMS = [
    *_triplets("perimetric", PERIMETER, "P"),
    *_triplets("areal", AREA, "|A|"),
    Term("triplet", "axilrod_teller", TRIANGLE, 0,
         "strength (1 + 3 cos t_i cos t_j cos t_k) / (r_ij r_jk r_ki)^3",
         (Parameter("strength", 1.0, "the triple-dipole strength Z"),),
         "the triple dipole (paper eq. ATMPotential)"),
    Term("pair", "lennard_jones", DISTANCE, LENNARD_JONES,
         "4 epsilon ((sigma/r)^12 - (sigma/r)^6)",
         (Parameter("epsilon", 1.0, "a well depth", above=0.0),
          Parameter("sigma", 1.0, "a length", above=0.0))),
    Term("pair", "yukawa", DISTANCE, YUKAWA, "coupling exp(-gamma r) / r", _yukawa(),
         "repulsive for coupling > 0: the colloids' pair term"),
    Term("pair", "power", DISTANCE, POWER,
         "coupling r^exponent / exponent (coupling ln r for exponent 0)", _power("r", -1.0)),
    Term("pair", "gravity", DISTANCE, POWER, "-G m_i m_j / r",
         (Parameter("G", 1.0, "the gravitational constant", above=0.0),),
         "Newtonian gravity: always weighted by the masses", weighted=True),
]
BY_KIND = {kind: {t.name: t for t in TERMS if t.kind == kind} for kind in KINDS}
TRIPLET_NAMES = tuple(BY_KIND["triplet"])
PAIR_NAMES = tuple(BY_KIND["pair"])


def term(name: str, kind: str = "triplet") -> Term:
    """The declaration of a term; unknown names raise ValueError, with a hint when the name
    is a term of the other kind."""
    if kind not in KINDS:
        raise ValueError(f"unknown interaction kind {kind!r}; choose one of {', '.join(KINDS)}")
    if name not in BY_KIND[kind]:
        other = "pair" if kind == "triplet" else "triplet"
        hint = (f" ({name!r} is a {other} potential: give it kind = \"{other}\")"
                if name in BY_KIND[other] else "")
        raise ValueError(f"unknown {kind} potential {name!r}; choose one of "
                         f"{', '.join(BY_KIND[kind])}{hint}")
    return BY_KIND[kind][name]


def parameter_defaults(name: str, kind: str = "triplet") -> dict:
    """The parameters of a potential with their defaults (see `term`)."""
    return term(name, kind).defaults


@dataclass(frozen=True)
class Potential:
    """One term of a system's potential with its parameter values, e.g. ``perimetric_power``
    (the paper's P**2/2 with the defaults), ``areal_barrier`` (the paper's 2/|A| + |A|**2),
    ``axilrod_teller``, or the pair term ``lennard_jones``."""

    name: str
    measure: int
    profile: int
    params: tuple[float, ...]
    param_names: tuple[str, ...]
    mass_weighted: bool = False     # a pair term's U(r_ij) multiplied by m_i m_j
    expression: str = ""            # a term written as a formula (profile EXPRESSION)
    variables: tuple[str, ...] = ()     # ... and the variables its program takes

    @property
    def kind(self) -> str:
        return ("pair" if self.measure == DISTANCE else "external"
                if self.measure == POSITION else "triplet")

    @property
    def par(self) -> np.ndarray:
        """The parameters as the kernels read them: a pair Yukawa's coupling negated (the
        kernels' YUKAWA profile is the attractive triplet form); gravity as the power
        profile G r^-1 / -1, whose mass weighting makes it -G m_i m_j / r."""
        p = np.array(self.params, dtype=np.float64)
        if self.profile == EXPRESSION:
            return np.zeros(2)          # its values are its program's (system._encode)
        if self.kind == "pair" and self.profile == YUKAWA:
            p[0] = -p[0]
        if self.name == "gravity":
            p = np.array([p[0], -1.0])
        return p

    @property
    def pair(self) -> tuple[float, float]:
        """par as the kernels' profile takes it from Python: a pair of floats, as the
        terms pass theirs (an array compiles a second copy of every profile)."""
        p = self.par
        return float(p[0]), float(p[1]) if p.size > 1 else 0.0

    @property
    def degree(self) -> float | None:
        """k if the term is homogeneous in the positions, U(s q) = s^k U(q), else None (a
        logarithm, a screening length, a barrier or a well sets a scale)."""
        if self.profile != POWER and self.measure != TRIANGLE:
            return None                 # (a formula's degree is not worked out)
        if self.measure == TRIANGLE:
            return -9.0                         # (r_ij r_jk r_ki)^-3
        if self.name == "gravity":
            return -1.0
        k = float(self.params[self.param_names.index("exponent")])
        if k == 0.0:
            return None                         # coupling ln x
        return 2.0 * k if self.measure == AREA else k

    def describe(self) -> str:
        values = ", ".join(f"{k}={v:g}" for k, v in zip(self.param_names, self.params))
        if self.expression:
            return (f"{self.kind} formula U = {self.expression}"
                    + (", times m_i m_j" if self.mass_weighted and self.kind == "pair" else
                       ", times m_i" if self.mass_weighted else "")
                    + (f" with {values}" if values else ""))
        weighted = ("" if term(self.name, self.kind).weighted or not self.mass_weighted
                    else ", times m_i m_j")
        return (f"{self.name} ({self.kind}): U = {term(self.name, self.kind).formula}"
                f"{weighted} with {values}")


def make_potential(name: str, params: dict | None = None, kind: str = "triplet",
                   mass_weighted: bool = False) -> Potential:
    """A term of a kind ("triplet" or "pair") with its parameters (the rest take their
    defaults); anything unknown or outside its declared bounds raises ValueError naming it.
    `mass_weighted`: a pair term's U(r_ij) is multiplied by m_i m_j (gravity always is)."""
    decl = term(name, kind)
    if not isinstance(mass_weighted, bool):
        raise ValueError(f"mass_weighted must be true or false, got {mass_weighted!r}")
    if mass_weighted and kind != "pair":
        raise ValueError(f"mass_weighted applies to pair terms; {name!r} is a triplet "
                         "potential, a function of its triangle alone")
    params = dict(params or {})
    unknown = sorted(set(params) - set(decl.defaults))
    if unknown:
        raise ValueError(f"potential {name!r} has no parameter {unknown[0]!r}; "
                         f"its parameters are {', '.join(decl.defaults)}")
    values = []
    for p in decl.parameters:
        value = params.get(p.name, p.default)
        problem = p.problem(value)
        if problem:
            raise ValueError(f"potential parameter {p.name!r} {problem}")
        values.append(float(value))
    return Potential(name, decl.measure, decl.profile, tuple(values),
                     tuple(p.name for p in decl.parameters), mass_weighted or decl.weighted)


def make_expression(kind: str, expression: str, params: dict | None = None,
                    mass_weighted: bool = False, dim: int = 2) -> Potential:
    """A term written as a formula (physics.expressions): a pair's U(r), a triplet's
    symmetric U(a, b, c) of the sides (P and A, the perimeter and the area, as names too)
    or an external U(x, y[, z]) acting on every body (times its mass with mass_weighted),
    with named parameters. A triplet formula of P alone, or of A alone, runs on the
    perimetric or areal term's forces; one of the sides on its own. ValueError naming what
    is wrong: a token, a name, a parameter, a non-symmetric triplet formula."""
    from .expressions import VARIABLES, check_symmetric, names_in, parse
    if kind not in EXPRESSION_KINDS:
        raise ValueError(f"unknown kind {kind!r} of a formula term; choose one of "
                         f"{', '.join(EXPRESSION_KINDS)}")
    if not isinstance(mass_weighted, bool):
        raise ValueError(f"mass_weighted must be true or false, got {mass_weighted!r}")
    if mass_weighted and kind == "triplet":
        raise ValueError("mass_weighted applies to pair and external terms; a triplet "
                         "formula is a function of its triangle alone")
    params = dict(params or {})
    variables = VARIABLES[kind][:dim] if kind == "external" else VARIABLES[kind]
    for name, value in params.items():
        if not isinstance(name, str) or not name.isidentifier() or name in variables \
                or name in ("pi",):
            raise ValueError(f"parameter name {name!r} must be a name that is not a "
                             f"variable ({', '.join(variables)}) or pi")
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ValueError(f"parameter {name!r} must be a finite number, got {value!r}")
    tree = parse(expression, (*variables, *params))
    used = names_in(tree)
    if not used & set(variables):
        raise ValueError(f"does not depend on {', '.join(variables)}: a constant exerts no "
                         "force")
    measure, inputs = {"pair": (DISTANCE, ("r",)),
                       "external": (POSITION, variables)}.get(kind, (SIDES, ("a", "b", "c")))
    if kind == "triplet":
        check_symmetric(tree, {k: float(v) for k, v in params.items()})
        if used & set(variables) == {"P"}:
            measure, inputs = PERIMETER, ("P",)
        elif used & set(variables) == {"A"}:
            measure, inputs = AREA, ("A",)
    return Potential(f"{kind}_formula", measure, EXPRESSION,
                     tuple(float(v) for v in params.values()), tuple(params),
                     mass_weighted, expression, inputs)
