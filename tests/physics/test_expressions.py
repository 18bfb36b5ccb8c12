"""Formulas as data: the whitelist grammar reads what a researcher writes, refuses everything
else with one message naming it, and evaluates nothing it was not built to."""
import math

import pytest

from survey.physics.expressions import (
    MAX_DEPTH,
    VARIABLES,
    check_symmetric,
    evaluate,
    names_in,
    parse,
    triangle,
)

XY = VARIABLES["external"]


@pytest.mark.parametrize("text,values,expected", [
    ("(x**2 + y**2)/2 + x**2*y - y**3/3", {"x": 0.1, "y": 0.2},
     0.025 + 0.002 - 0.008 / 3),                                   # Henon-Heiles
    ("-x**2", {"x": 3.0}, -9.0),                                   # a sign binds looser
    ("2**3**2", {}, 512.0),                                        # right associative
    ("1 - 2 - 3", {}, -4.0), ("8 / 4 / 2", {}, 1.0),               # left associative
    ("exp(-y) * cos(x) + sqrt(abs(y - 5)) + tanh(0.5) - pi", {"x": 0.3, "y": 1.0},
     math.exp(-1) * math.cos(0.3) + 2.0 + math.tanh(0.5) - math.pi),
    ("1.5e-1 + .5 + 2.", {}, 2.65),
])
def test_formulas_read_as_written(text, values, expected):
    assert evaluate(parse(text, XY), values) == pytest.approx(expected, rel=1e-15)


def test_toda_reads_with_its_parameters():
    toda = ("(exp(2*y + 2*sqrt(3)*x) + exp(2*y - 2*sqrt(3)*x) + exp(-4*y)) / 24 - 1/8")
    tree = parse(toda, XY)
    assert names_in(tree) == {"x", "y"}
    assert evaluate(tree, {"x": 0.0, "y": 0.0}) == pytest.approx(0.0, abs=1e-16)
    scaled = parse("k * x**2", (*XY, "k"))
    assert evaluate(scaled, {"x": 2.0, "k": 0.5}) == 2.0


@pytest.mark.parametrize("text,message", [
    ("x^2", "powers are written **"),
    ("__import__('os').system('true')", "strings are not allowed"),
    ("__import__(x)", "__import__(...) at character 1 is not a function"),
    ("x.real", "attribute access"),
    ("x[0]", "indexing"),
    ("eval(x)", "eval(...) at character 1 is not a function"),
    ("exp(x, y)", "exp takes one argument"),
    ("q + 1", "unknown name 'q'"),
    ("exq(x)", "did you mean 'exp'"),
    ("exp + 1", "exp is a function"),
    ("x +", "ends where"),
    ("(x + 1", "expected ')'"),
    ("x + 1)", "unexpected ')'"),
    ("1e999", "not finite"),
    ("", "is empty"),
    ("x" + " + x" * 30000, "at most 2000"),           # 120 kB
    ("(" * (MAX_DEPTH + 1) + "x" + ")" * (MAX_DEPTH + 1), "nested deeper"),
    ("-" * 100 + "x", "nested deeper"),
    ("2" + "**2" * 100, "nested deeper"),
    ("lambda: x", "unexpected ':'"),
])
def test_anything_outside_the_grammar_is_one_clear_error(text, message):
    with pytest.raises(ValueError, match=None) as caught:
        parse(text, XY)
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_a_formula_must_be_text():
    with pytest.raises(ValueError, match="must be a string"):
        parse(3.0, XY)


def test_triplet_formulas_must_not_tell_the_sides_apart():
    names = VARIABLES["triplet"] + ("k",)
    for text in ("P**2 / 2", "k * A**2 + a*b*c", "exp(-P) / A", "a**2 + b**2 + c**2",
                 "1 / (a*b*c)**3 * (1 + 0*a)"):
        check_symmetric(parse(text, names), {"k": 2.0})
    for text, pair in (("a**2 * b", "a and b"), ("a - c", "a and b"), ("b * c**2", "a and b")):
        with pytest.raises(ValueError, match=f"not symmetric in the sides: exchanging {pair}"):
            check_symmetric(parse(text, names), {"k": 2.0})


def test_a_triangles_names():
    t = triangle(3.0, 4.0, 5.0)
    assert t["P"] == 12.0 and t["A"] == pytest.approx(6.0, rel=1e-15)


# ----------------------------------------------------------------- exact derivatives

from survey.physics.expressions import program, values  # noqa: E402
import numpy as np  # noqa: E402

HENON_HEILES = "(x**2 + y**2)/2 + x**2*y - y**3/3"
TODA = "(exp(2*y + 2*sqrt(3)*x) + exp(2*y - 2*sqrt(3)*x) + exp(-4*y)) / 24 - 1/8"


def test_henon_heiles_derivatives_are_its_closed_forms():
    prog = program(parse(HENON_HEILES, ("x", "y")), ("x", "y"), {})
    for x, y in ((0.3, -0.2), (-0.1, 0.45), (0.0, 0.0)):
        expected = [(x * x + y * y) / 2 + x * x * y - y ** 3 / 3, x + 2 * x * y,
                    y + x * x - y * y, 1 + 2 * y, 2 * x, 1 - 2 * y]
        np.testing.assert_allclose(values(prog, {"x": x, "y": y}), expected, rtol=1e-15,
                                   atol=1e-16)


@pytest.mark.parametrize("text,variables,params", [
    (TODA, ("x", "y"), {}),
    ("k * exp(-g * r) / r", ("r",), {"k": 1.5, "g": 0.7}),
    ("4*e*((s/r)**12 - (s/r)**6)", ("r",), {"e": 1.0, "s": 1.1}),
    ("P**2/2 + w / A + A**2", ("a", "b", "c"), {"w": 2.0}),
    ("sqrt(a*b*c) * tanh(P) + log(a + b + c) + abs(a - b) * abs(b - c) * abs(c - a)",
     ("a", "b", "c"), {}),
    ("sin(x) * cosh(y) + atan(z) * sinh(x) / (2 + cos(y)) + tan(z/2)**2 + x**2.5 * y**0.3",
     ("x", "y", "z"), {}),
])
def test_derivatives_against_finite_differences(text, variables, params):
    """Gradient by central differences of U, Hessian by central differences of the
    gradient, at random points (a triplet's in its sides, P and A through them)."""
    names = VARIABLES["triplet"] if variables == ("a", "b", "c") else variables
    prog = program(parse(text, (*names, *params)), variables, params)
    rng = np.random.default_rng(1)
    n = len(variables)
    upper = [(i, j) for i in range(n) for j in range(i, n)]
    for _ in range(5):
        point = dict(zip(variables, rng.uniform(0.8, 1.6, n)))
        out = values(prog, point)
        shape = triangle(*point.values()) if names != variables else {}
        assert out[0] == pytest.approx(evaluate(parse(text, (*names, *params)),
                                                {**point, **shape, **params}), rel=1e-13)
        h = 1e-5
        for i, v in enumerate(variables):
            up, down = values(prog, {**point, v: point[v] + h}), \
                values(prog, {**point, v: point[v] - h})
            assert out[1 + i] == pytest.approx((up[0] - down[0]) / (2 * h), rel=1e-7,
                                               abs=1e-9)
            for k, (a, b) in enumerate(upper):
                if a == i:
                    fd = (up[1 + b] - down[1 + b]) / (2 * h)
                    assert out[1 + n + k] == pytest.approx(fd, rel=1e-6, abs=1e-8)
