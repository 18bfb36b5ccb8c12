"""Interaction terms a researcher writes as a formula, read as data: a whitelist grammar of
numbers, the term's variables, its named parameters, + - * / **, parentheses and a fixed
list of functions. The text is never given to eval, sympify or parse_expr (they run
Python); anything outside the grammar -- a stray character, an unknown name, a call of
anything not listed, attribute access, a text too long or nested too deep -- is one
ValueError naming it and where it stands, before any work.

A parsed formula is a tree of tuples: ("num", value), ("name", name),
("call", function, argument), ("neg", a), and (op, a, b) for op in + - * / **. The tree
is evaluated in plain floats here (`evaluate`: the checks before a run, such as a
triplet term's symmetry) and differentiated exactly to compiled kernels elsewhere.
"""
from __future__ import annotations

import difflib
import functools
import math
import random
import re
from typing import NamedTuple

import numpy as np

from ..machine import portable
from ..machine.jit import helper, leaf

# the functions a formula may call, each with its evaluation in floats (the kernels use
# machine.portable's, whose bits are the same on every machine)
FUNCTIONS = {
    "exp": math.exp, "log": math.log, "sqrt": math.sqrt, "sin": math.sin, "cos": math.cos,
    "tan": math.tan, "atan": math.atan, "sinh": math.sinh, "cosh": math.cosh,
    "tanh": math.tanh, "abs": abs,
}
CONSTANTS = {"pi": math.pi}
# what each kind of term is a function of: a pair's distance, a triangle's sides (with
# its perimeter P and area A = |signed area| as names too), one body's coordinates
VARIABLES = {
    "pair": ("r",),
    "triplet": ("a", "b", "c", "P", "A"),
    "external": ("x", "y", "z"),
}
MAX_LENGTH = 2000          # characters of one formula
MAX_DEPTH = 40             # nesting of parentheses, calls and operators
MAX_NODES = 2000

_TOKEN = re.compile(r"\s*(?:(?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)"
                    r"|(?P<name>[A-Za-z_][A-Za-z_0-9]*)|(?P<op>\*\*|[-+*/(),]))")


def _tokens(text: str) -> list[tuple[str, str, int]]:
    """(kind, text, position) of each token; a character outside the grammar is an error
    naming it."""
    out, at = [], 0
    while at < len(text):
        m = _TOKEN.match(text, at)
        if m is None or m.end() == at:
            if text[at:].strip() == "":
                break
            bad = text[at:].lstrip()[0]
            where = len(text) - len(text[at:].lstrip())
            hint = {"^": " (powers are written **)", ".": " (attribute access is not "
                    "allowed)", "[": " (indexing is not allowed)", "=": "", ";": "",
                    "'": " (strings are not allowed)", '"': " (strings are not allowed)"}
            raise ValueError(f"unexpected {bad!r} at character {where + 1}"
                             f"{hint.get(bad, '')}: a formula holds numbers, names, "
                             "+ - * / **, parentheses and calls of " + ", ".join(FUNCTIONS))
        kind = m.lastgroup
        out.append((kind, m.group(kind), m.start(kind)))
        at = m.end()
    out.append(("end", "", len(text)))
    return out


class _Parser:
    """Recursive descent, lowest precedence first: sums, products, signs, powers (right
    associative, binding tighter than a sign on their left: -x**2 is -(x**2)), atoms."""

    def __init__(self, text: str, names: tuple[str, ...]):
        self.tokens = _tokens(text)
        self.i = 0
        self.names = names
        self.nodes = 0

    def peek(self):
        return self.tokens[self.i]

    def take(self):
        token = self.tokens[self.i]
        self.i += 1
        return token

    def node(self, *parts) -> tuple:
        self.nodes += 1
        if self.nodes > MAX_NODES:
            raise ValueError(f"is longer than {MAX_NODES} operations")
        return parts

    def expect(self, text: str, what: str):
        kind, got, at = self.take()
        if got != text:
            raise ValueError(f"expected {what} at character {at + 1}, found "
                             + (f"{got!r}" if kind != "end" else "the end"))

    def parse(self) -> tuple:
        tree = self.sum(0)
        kind, got, at = self.peek()
        if kind != "end":
            raise ValueError(f"unexpected {got!r} at character {at + 1}")
        return tree

    def check_depth(self, depth: int):
        if depth > MAX_DEPTH:
            raise ValueError(f"is nested deeper than {MAX_DEPTH} levels")

    def sum(self, depth):
        self.check_depth(depth)
        left = self.product(depth + 1)
        while self.peek()[1] in ("+", "-"):
            op = self.take()[1]
            left = self.node(op, left, self.product(depth + 1))
        return left

    def product(self, depth):
        self.check_depth(depth)
        left = self.signed(depth + 1)
        while self.peek()[1] in ("*", "/"):
            op = self.take()[1]
            left = self.node(op, left, self.signed(depth + 1))
        return left

    def signed(self, depth):
        self.check_depth(depth)
        if self.peek()[1] in ("+", "-"):
            op = self.take()[1]
            inner = self.signed(depth + 1)
            return inner if op == "+" else self.node("neg", inner)
        return self.power(depth + 1)

    def power(self, depth):
        self.check_depth(depth)
        base = self.atom(depth + 1)
        if self.peek()[1] == "**":
            self.take()
            return self.node("**", base, self.signed(depth + 1))
        return base

    def atom(self, depth):
        self.check_depth(depth)
        kind, text, at = self.take()
        if kind == "num":
            value = float(text)
            if not math.isfinite(value):
                raise ValueError(f"the number {text} at character {at + 1} is not finite")
            return self.node("num", value)
        if text == "(":
            inner = self.sum(depth + 1)
            self.expect(")", "')'")
            return inner
        if kind == "name":
            if self.peek()[1] == "(":
                if text not in FUNCTIONS:
                    raise ValueError(f"{text}(...) at character {at + 1} is not a function "
                                     "a formula may call" + _suggest(text, FUNCTIONS)
                                     + "; they are " + ", ".join(FUNCTIONS))
                self.take()
                argument = self.sum(depth + 1)
                if self.peek()[1] == ",":
                    raise ValueError(f"{text} takes one argument (character "
                                     f"{self.peek()[2] + 1})")
                self.expect(")", f"')' closing {text}(")
                return self.node("call", text, argument)
            if text in CONSTANTS:
                return self.node("num", CONSTANTS[text])
            if text not in self.names:
                known = list(self.names) + list(CONSTANTS)
                raise ValueError(f"unknown name {text!r} at character {at + 1}"
                                 + _suggest(text, known) + "; the names are "
                                 + ", ".join(known) + (
                                     f" ({text} is a function: call it, {text}(...))"
                                     if text in FUNCTIONS else ""))
            return self.node("name", text)
        if kind == "end":
            raise ValueError("ends where a number, a name or '(' should follow")
        raise ValueError(f"unexpected {text!r} at character {at + 1}")


def _suggest(word, options) -> str:
    close = difflib.get_close_matches(word, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def parse(text, names) -> tuple:
    """The tree of a formula in the given names (variables and parameters); ValueError
    naming what is wrong with it."""
    if not isinstance(text, str):
        raise ValueError(f"must be a string (a formula), got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ValueError(f"is {len(text)} characters long; a formula may have at most "
                         f"{MAX_LENGTH}")
    if not text.strip():
        raise ValueError("is empty: give the formula, e.g. \"P**2 / 2\"")
    return _Parser(text, tuple(names)).parse()


def names_in(tree) -> set[str]:
    """The names a tree uses."""
    if tree[0] == "name":
        return {tree[1]}
    if tree[0] == "num":
        return set()
    return set().union(*(names_in(t) for t in tree[1:] if isinstance(t, tuple)))


def evaluate(tree, values: dict) -> float:
    """The tree's value in floats at `values` (name -> number): the checks before a run."""
    op = tree[0]
    if op == "num":
        return tree[1]
    if op == "name":
        return values[tree[1]]
    if op == "call":
        return FUNCTIONS[tree[1]](evaluate(tree[2], values))
    if op == "neg":
        return -evaluate(tree[1], values)
    a, b = evaluate(tree[1], values), evaluate(tree[2], values)
    if op == "+":
        return a + b
    if op == "-":
        return a - b
    if op == "*":
        return a * b
    if op == "/":
        return a / b
    return a ** b


def triangle(a: float, b: float, c: float) -> dict:
    """The triplet variables of a triangle with sides a, b, c: they, P and the area (Heron)."""
    s = 0.5 * (a + b + c)
    return {"a": a, "b": b, "c": c, "P": a + b + c,
            "A": math.sqrt(max(s * (s - a) * (s - b) * (s - c), 0.0))}


def check_symmetric(tree, params: dict, tries: int = 8, seed: int = 0) -> None:
    """A triplet formula must not depend on which side is which (the paper's potentials
    are functions of the triangle): its value under each permutation of a, b, c at random
    triangles, to 1e-10 relative; ValueError naming a pair of sides it tells apart."""
    rng = random.Random(seed)
    swaps = (("a", "b"), ("b", "c"), ("a", "c"))
    for _ in range(tries):
        sides = sorted(rng.uniform(0.5, 2.0) for _ in range(3))
        sides[2] = min(sides[2], 0.95 * (sides[0] + sides[1]))
        rng.shuffle(sides)
        values = {**params, **triangle(*sides)}
        try:
            here = evaluate(tree, values)
        except (ValueError, ZeroDivisionError, OverflowError):
            continue
        for u, v in swaps:
            swapped = {**values, u: values[v], v: values[u]}
            try:
                there = evaluate(tree, swapped)
            except (ValueError, ZeroDivisionError, OverflowError):
                continue
            if abs(here - there) > 1e-10 * max(abs(here), abs(there), 1e-300):
                raise ValueError(f"is not symmetric in the sides: exchanging {u} and {v} "
                                 f"changes it ({here:.6g} -> {there:.6g} at a = "
                                 f"{values['a']:.3g}, b = {values['b']:.3g}, c = "
                                 f"{values['c']:.3g}); a triplet term is a function of "
                                 "the triangle, the same whichever side is called a")


# ---------------------------------------------------------------- exact derivatives as programs

# a program's operations: register machine instructions (op, a, b, out), out = op(R[a], R[b])
(ADD, SUB, MUL, DIV, NEG, IPOW, POW, SQRT, EXP, LOG, SIN, COS, TAN, ATAN, SINH, COSH, TANH,
 ABS, SIGN) = range(19)
_CALLS = {"sqrt": SQRT, "exp": EXP, "log": LOG, "sin": SIN, "cos": COS, "tan": TAN,
          "atan": ATAN, "sinh": SINH, "cosh": COSH, "tanh": TANH, "Abs": ABS, "sign": SIGN}
POSITIVE = {"r", "a", "b", "c", "P"}     # names sympy may assume positive (A may vanish)


class Program(NamedTuple):
    """Straight-line code for a formula and its derivatives: registers R[0:n_in] hold the
    inputs (`inputs`, in order), R[n_in:n_in + consts.size] the constants, the rest the
    instructions' results; `outputs` the registers of U, its gradient in the variables,
    then the upper triangle of its Hessian (row by row), each as `outputs_named` says."""

    inputs: tuple[str, ...]
    consts: np.ndarray
    code: np.ndarray          # (instructions, 4) int64: op, a, b, out
    outputs: np.ndarray       # int64 registers
    registers: int


def _to_sympy(tree, symbols):
    import sympy as sp
    op = tree[0]
    if op == "num":
        value = tree[1]
        return sp.Integer(int(value)) if value == int(value) and abs(value) < 2 ** 53 \
            else sp.Float(repr(value), 17)
    if op == "name":
        return symbols[tree[1]]
    if op == "call":
        f = {"abs": sp.Abs}.get(tree[1]) or getattr(sp, tree[1])
        return f(_to_sympy(tree[2], symbols))
    if op == "neg":
        return -_to_sympy(tree[1], symbols)
    a, b = _to_sympy(tree[1], symbols), _to_sympy(tree[2], symbols)
    return {"+": lambda: a + b, "-": lambda: a - b, "*": lambda: a * b,
            "/": lambda: a / b, "**": lambda: a ** b}[op]()


def program(tree, variables: tuple[str, ...], params: dict) -> Program:
    """The formula (with the parameters' values put in) and its exact first and second
    derivatives in `variables`, differentiated by sympy from the parsed tree (never from
    the text) and compiled to one straight-line Program over common subexpressions.
    ValueError if a derivative needs a function outside the program's operations."""
    import sympy as sp
    symbols = {v: sp.Symbol(v, positive=True) if v in POSITIVE else sp.Symbol(v, real=True)
               for v in variables}
    values = {**symbols, **{k: sp.Float(repr(float(v)), 17) for k, v in params.items()}}
    if tuple(variables) == ("a", "b", "c"):     # a triplet's sides: P and A through them
        a, b, c = xs3 = [symbols[v] for v in variables]
        half = sum(xs3) / 2
        values.update(P=a + b + c, A=sp.sqrt(half * (half - a) * (half - b) * (half - c)))
    U = _to_sympy(tree, values)
    xs = [symbols[v] for v in variables]
    grad = [sp.diff(U, x) for x in xs]
    hess = [sp.diff(grad[i], xs[j]) for i in range(len(xs)) for j in range(i, len(xs))]
    replacements, reduced = sp.cse([U, *grad, *hess], optimizations="basic")
    b = _Builder({symbols[v]: ("in", i) for i, v in enumerate(variables)})
    for sym, expr in replacements:
        b.known[sym] = b.emit(expr)
    outputs = [b.emit(e) for e in reduced]
    n_in, n_const = len(variables), len(b.consts)

    def register(operand):
        kind, i = operand
        return i if kind == "in" else n_in + i if kind == "const" else n_in + n_const + i
    code = [[op, register(x), register(y), n_in + n_const + t]
            for t, (op, x, y) in enumerate(b.code)]
    return Program(tuple(variables), np.array(b.consts, dtype=np.float64),
                   np.array(code, dtype=np.int64).reshape(-1, 4),
                   np.array([register(o) for o in outputs], dtype=np.int64),
                   n_in + n_const + len(b.code))


class _Builder:
    """sympy expressions to instructions over operands ("in" | "const" | "tmp", index),
    numbered into registers when the program is complete."""

    def __init__(self, known):
        self.known = dict(known)
        self.consts: list[float] = []
        self.code: list[tuple] = []

    def const(self, value) -> tuple:
        value = float(value)
        if value not in self.consts:
            self.consts.append(value)
        return ("const", self.consts.index(value))

    def op(self, code, a, b=None) -> tuple:
        self.code.append((code, a, a if b is None else b))
        return ("tmp", len(self.code) - 1)

    def emit(self, e) -> tuple:
        import sympy as sp
        if e in self.known:
            return self.known[e]
        if e.is_Number or e.is_NumberSymbol:
            return self.const(e)
        if e.is_Add:
            out = self.emit(e.args[0])
            for t in e.args[1:]:
                out = self.op(ADD, out, self.emit(t))
            return out
        if e.is_Mul:
            num, den, negative = [], [], False
            for f in e.args:
                if f == -1:
                    negative = not negative
                elif f.is_Pow and f.exp.is_Number and f.exp < 0:
                    den.append(self.emit(f.base ** -f.exp))
                else:
                    num.append(self.emit(f))
            out = num[0] if num else self.const(1.0)
            for f in num[1:]:
                out = self.op(MUL, out, f)
            for f in den:
                out = self.op(DIV, out, f)
            return self.op(NEG, out) if negative else out
        if e.is_Pow:
            base, k = e.base, e.exp
            if k == sp.Rational(1, 2):
                return self.op(SQRT, self.emit(base))
            if k.is_Integer:
                return self.op(IPOW, self.emit(base), self.const(k))
            if k.is_Rational and k.q == 2:
                return self.op(IPOW, self.op(SQRT, self.emit(base)), self.const(k.p))
            return self.op(POW, self.emit(base), self.emit(k))
        name = type(e).__name__
        if name in _CALLS:
            return self.op(_CALLS[name], self.emit(e.args[0]))
        if name == "DiracDelta":        # the derivative of sign or abs: zero but at 0
            return self.const(0.0)
        raise ValueError(f"its derivatives need {name}, which survey does not compile; "
                         "write the formula without it")


@helper
def _apply(op, x, y):
    """One instruction's value, with machine.portable's functions where libm's last bits
    differ between machines (sqrt and the arithmetic are correctly rounded everywhere):
    the arithmetic and exp (the commonest, and small) here, the others in `_elementary`."""
    if op == ADD:
        return x + y
    if op == SUB:
        return x - y
    if op == MUL:
        return x * y
    if op == DIV:
        return x / y
    if op == NEG:
        return -x
    if op == IPOW:
        return portable.ipow(x, int(y))
    if op == SQRT:
        return math.sqrt(x)
    if op == EXP:
        return portable.exp(x)
    if op == ABS:
        return abs(x)
    if op == SIGN:
        return 0.0 if x == 0.0 else math.copysign(1.0, x)
    return _elementary(op, x, y)


@leaf
def _elementary(op, x, y):
    """The instructions of machine.portable's other elementary functions, each function
    called at one place (exp at two): compiled once, called by `run_program` and the
    lanes' `_apply_lanes`. Inlined into both at each instruction that takes it (seven copies of
    exp, two or three of each other function), they cost a formula's first run about 30 s
    of compiling (a Hénon-Heiles orbit's first run 100 s, now 70)."""
    if op == POW:
        return portable.power(x, y)
    if op == LOG:
        return portable.log(x)
    if op == ATAN:
        return portable.atan(x)
    if op == SIN or op == COS or op == TAN:
        s = portable.sin(x) if op != COS else 0.0
        c = portable.cos(x) if op != SIN else 0.0
        return s if op == SIN else c if op == COS else s / c
    # SINH, COSH, TANH
    e = portable.exp(-2.0 * abs(x) if op == TANH else x)
    if op == TANH:
        return math.copysign((1.0 - e) / (1.0 + e), x)
    f = portable.exp(-x)
    return 0.5 * (e - f) if op == SINH else 0.5 * (e + f)


class Programs(NamedTuple):
    """A system's programs packed for the kernels (a field of physics.system.Model): their
    instructions on one shared register file (`regs`, constants in place), each
    program's instructions start[t]:start[t + 1], its inputs' registers (up to 3, -1 past
    its variables) and its outputs' (U, the gradient, the Hessian's upper triangle; -1
    past them)."""

    code: np.ndarray          # (I, 4) int64
    start: np.ndarray         # (T + 1,) int64
    inputs: np.ndarray        # (T, 3) int64
    outputs: np.ndarray       # (T, 10) int64
    regs: np.ndarray          # (R,) float64
    forces_end: np.ndarray    # (T,) int64: start[t]:forces_end[t] give all but U


def forces_first(prog: Program) -> tuple[np.ndarray, int]:
    """The program's instructions reordered so that those its derivatives need come
    first (in their order), then those only U needs: (code, how many come first). Each
    instruction is the same operation on the same operands, so every output keeps its
    bits; the forces in the lanes run the first part alone (`P**2/2`'s derivatives need
    none of its two instructions)."""
    made = {int(c[3]): i for i, c in enumerate(prog.code)}
    needed = set()
    todo = [int(o) for o in prog.outputs[1:]]
    while todo:
        r = todo.pop()
        i = made.get(r)
        if i is not None and i not in needed:
            needed.add(i)
            todo += [int(prog.code[i, 1]), int(prog.code[i, 2])]
    order = sorted(needed) + [i for i in range(len(prog.code)) if i not in needed]
    return prog.code[order].reshape(-1, 4), len(needed)


def pack(programs) -> Programs:
    """Programs of a system's formula terms, in order, on one register file: each
    program's registers moved past those of the ones before, its instructions those its
    derivatives need first (`forces_first`)."""
    code, start, inputs, outputs, regs, forces = [], [0], [], [], [], []
    for prog in programs:
        base = len(regs)
        n_in = len(prog.inputs)
        block = np.zeros(prog.registers)
        block[n_in:n_in + prog.consts.size] = prog.consts
        regs.extend(block)
        ordered, first = forces_first(prog)
        shifted = ordered.copy()
        shifted[:, 1:] += base
        code.extend(shifted.tolist())
        forces.append(start[-1] + first)
        start.append(start[-1] + len(prog.code))
        inputs.append([base + i for i in range(n_in)] + [-1] * (3 - n_in))
        outputs.append([base + int(o) for o in prog.outputs]
                       + [-1] * (10 - prog.outputs.size))
    return Programs(np.array(code, dtype=np.int64).reshape(-1, 4),
                    np.array(start, dtype=np.int64),
                    np.array(inputs, dtype=np.int64).reshape(-1, 3),
                    np.array(outputs, dtype=np.int64).reshape(-1, 10),
                    np.array(regs, dtype=np.float64), np.array(forces, dtype=np.int64))


@leaf
def run_program(X, t, x0, x1, x2):
    """Program t of a Programs X at inputs (x0, x1, x2) (those past its variables
    ignored): its outputs are then in X.regs[X.outputs[t]]. Compiled once and called,
    not inlined: each inlined copy of the instructions' functions cost a cold start
    seconds of compilation."""
    regs, inputs = X.regs, X.inputs[t]
    regs[inputs[0]] = x0
    if inputs[1] >= 0:
        regs[inputs[1]] = x1
    if inputs[2] >= 0:
        regs[inputs[2]] = x2
    code = X.code
    for i in range(X.start[t], X.start[t + 1]):
        regs[code[i, 3]] = _apply(code[i, 0], regs[code[i, 1]], regs[code[i, 2]])


@helper
def _apply_lanes(op, x, y, out, tmp, L):
    """`_apply` on L lanes: the operation chosen once, each arithmetic one a loop the
    compiler turns into SIMD instructions (the same operations, so the same bits; tmp: a
    row of scratch). Inlined into `run_program_lanes`: called once an instruction, a
    compiled function of its own cost a formula's orbit-step a third more (LJ pairs)."""
    if op == ADD:
        for k in range(L):
            out[k] = x[k] + y[k]
    elif op == SUB:
        for k in range(L):
            out[k] = x[k] - y[k]
    elif op == MUL:
        for k in range(L):
            out[k] = x[k] * y[k]
    elif op == DIV:
        for k in range(L):
            out[k] = x[k] / y[k]
    elif op == NEG:
        for k in range(L):
            out[k] = -x[k]
    elif op == SQRT:
        for k in range(L):
            out[k] = math.sqrt(x[k])
    elif op == EXP:         # without branches: SIMD instructions too
        for k in range(L):
            out[k] = portable.exp(x[k])
    elif op == IPOW:        # portable.ipow's products, lane by lane in step: the exponent
        n = int(y[0])       # is a constant, the same in every lane; tmp holds the powers
        for k in range(L):
            out[k] = 1.0
            tmp[k] = x[k]
        e = abs(n)
        while e > 0:
            if e & 1:
                for k in range(L):
                    out[k] *= tmp[k]
            e >>= 1
            if e > 0:
                for k in range(L):
                    tmp[k] *= tmp[k]
        if n < 0:
            for k in range(L):
                out[k] = 1.0 / out[k]
    else:
        for k in range(L):
            out[k] = _apply(op, x[k], y[k])


@leaf
def run_program_lanes(X, t, R, L):
    """`run_program`'s derivatives on L lanes at once (the instructions U alone needs are
    left out: the lanes compute forces): register r of lane k at R[r * L + k] (and a row
    of scratch after them), the constants put there by `constants_lanes`, the inputs' rows
    by the caller; each instruction one `_apply_lanes` over its three rows (distinct: a
    result's register is never an operand's)."""
    code = X.code
    tmp = R[X.regs.size * L:(X.regs.size + 1) * L]
    for i in range(X.start[t], X.forces_end[t]):
        a, b, o = code[i, 1], code[i, 2], code[i, 3]
        _apply_lanes(code[i, 0], R[a * L:(a + 1) * L], R[b * L:(b + 1) * L],
                     R[o * L:(o + 1) * L], tmp, L)


@leaf
def constants_lanes(X, R, L):
    """Every register of X's file (its constants in place) in each of L lanes of R."""
    regs = X.regs
    for r in range(regs.size):
        v = regs[r]
        row = R[r * L:(r + 1) * L]
        for k in range(L):
            row[k] = v


@helper
def output(X, t, k):
    """Output k of program t after `run_program`."""
    return X.regs[X.outputs[t, k]]


def values(prog: Program, point: dict) -> np.ndarray:
    """U, its gradient and Hessian's upper triangle (the program's outputs) at a point
    (name -> value), computed by the compiled program as the kernels run it: the tests'
    and checks' door."""
    X = pack([prog])
    run_program(X, 0, *[float(point[v]) for v in prog.inputs],
                *[0.0] * (3 - len(prog.inputs)))
    return X.regs[X.outputs[0, :prog.outputs.size]]


@functools.lru_cache(maxsize=256)
def term_program(kind: str, expression: str, inputs: tuple, param_names: tuple,
                 params: tuple) -> Program:
    """The Program of a formula term (physics.terms.make_expression's Potential): its
    formula in its inputs, the parameters' values put in. Cached: sympy's derivatives take
    a fraction of a second, and every System of a grid's cells asks again."""
    names = (*(inputs if kind == "external" else VARIABLES[kind]), *param_names)
    return program(parse(expression, names), inputs, dict(zip(param_names, params)))
