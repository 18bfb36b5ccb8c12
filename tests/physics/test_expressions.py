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
