"""Pseudo-arclength continuation, shared by the families of periodic orbits and of relative
equilibria.

The caller owns the equations: `solve(x, row, target)` runs Newton's method on them,
bordered by the one extra row `row . x = target`, from the scaled unknowns x (the
parameter last, scaled so that the requested span is 1), and returns (member, x, A) --
the solution, its unknowns and the Jacobian A of the equations (without the extra row) --
or None. The family's tangent is A's null vector. Here: the steps, the guards against
jumping to a crossing branch, the end, and the bisection of where a test of the members
(a fold, a count of stable modes) changes.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..machine import linalg
from ..physics.equilibria import (
    AXIS_TOLERANCE,
    Bifurcation,
    amended,
    frame,
    relative_equilibrium,
    rotations,
)

TURN_DEGREES = 10.0         # a step whose tangent or chord turns more is halved
TURN = 0.984807753012208    # its cosine
GAP = 1e-6                  # scaled distance beyond which a bisection's ends are two branches
# the changes named by their test alone: a fold, and a branch point (where the orientation
# of the family changes: another family crosses it)
NAMED = ("fold", "branch point")


class Located(NamedTuple):
    """Where a test changes between two members, bisected along the arclength."""

    test: str
    before: object            # the members on either side
    after: object
    x: np.ndarray             # the scaled unknowns there (mean of the last bracket's ends)
    width: float = 0.0        # the last bracket's extent in the scaled parameter
    near: object = None       # the last member solved inside the bracket (None: none)


class Branch(NamedTuple):
    """A followed family: its members [(member, x, t)], where its tests change, whether it
    reached the end value, and if not why it stopped."""

    members: list
    found: list[Located]
    complete: bool
    ended: str                # '' if complete


SMALLEST = 1e-6     # the smallest step, relative to the nominal one: below it the family ends
EDGE_FLOOR = 1e-3   # the smallest step refined where a stability index nears its band's edge


def on_row(row: np.ndarray, x: np.ndarray, target: float) -> bool:
    """Whether x meets the bordering row row . x = target (to rounding): a corrector may
    stop only there, not at a start that already solves the other equations."""
    return abs(target - linalg.dot(row, x)) <= 1e-12 * max(abs(target), 1.0)


def tangent(A: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """The unit null vector of A, oriented along `previous`."""
    t = linalg.svd(A)[1][-1]
    return -t if linalg.dot(t, previous) < 0 else t


def follow(solve: Callable, x0: np.ndarray, to: float, steps: int, tests: dict[str, Callable],
           signature: Callable | None = None, bisect: float = 1e-9,
           max_members: int = 1000, margin: Callable | None = None,
           on_member: Callable | None = None) -> Branch:
    """The family from scaled x0 (its parameter held at x0[-1]) to the scaled parameter
    value `to`. The step advances the parameter by 1/steps where the family runs along it
    (the state by at most 0.1) and is halved where a step fails a check: the corrector
    does not converge; the new tangent or the chord turns by more than 10 degrees, or
    `signature(member)` (e.g. stability indices) moves by more than 0.1 -- signs of a
    jump to another branch; or a test(member, tangent) (a fold: `lambda m, t: t[-1] > 0`,
    a count of stable modes) changes between the members and its bisection along the
    arclength (to `bisect`) does not close up: the members on either side stay apart, a
    gap between two branches rather than a bifurcation on one. A step that fails at the
    smallest size (SMALLEST of the nominal) ends the family there, unreported: nothing
    past a failed check is a member. Also ends at `to` (a last member solved there), at
    max_members, or where it has turned back and run twice the span past its start.
    `margin(member)`: how far each stability index is inside its band (1 - |b|, NaN off
    the real line); a step along which one comes nearer its edge than it moves is halved
    too, down to EDGE_FLOOR of the nominal step, so that an index does not leave the band
    and come back between members unseen (findings.family_stability says where it still
    might). `on_member(count, share)`: called with each member found and the share of the
    parameter's span from its start to `to` covered (a progress display)."""
    direction = np.zeros(x0.size)
    direction[-1] = np.sign(to - x0[-1])
    first = solve(x0, direction, linalg.dot(direction, x0))
    if first is None:
        raise ValueError("the start does not converge as a member of the family")
    member, x, A = first
    members = [(member, x, tangent(A, direction))]
    jacobian = A                # the last member's, for the orientation test
    found: list[Located] = []
    start = x[-1]
    ds = nominal = 1.0 / steps
    while True:
        if len(members) >= max_members:
            return Branch(members, found, False, f"stopped at {max_members} members")
        if abs(members[-1][1][-1] - start) > 2.0:
            return Branch(members, found, False, "turned back and ran twice the span past "
                                                 "its start")
        member, x, t = members[-1]
        got, last = solve(x + ds * t, t, linalg.dot(t, x) + ds), False
        if got is not None and (got[1][-1] - to) * (x[-1] - to) <= 0:   # passed the end
            row = np.zeros(x.size)
            row[-1] = 1.0
            got = solve(x + (to - x[-1]) / t[-1] * t if abs(t[-1]) > 0.1 else got[1], row, to)
            last = True
        problem, located = _step_problem(members[-1], jacobian, got, solve, tests,
                                         signature, bisect)
        if problem:
            ds /= 2
            if ds < SMALLEST * nominal:
                return Branch(members, found, False, problem)
            continue
        if margin is not None and len(located) == 1 and ds > EDGE_FLOOR * nominal and \
                unresolved(margin(members[-1][0]), margin(located[0][0])):
            ds /= 2
            continue
        members.append(located.pop())
        jacobian = got[2]
        if on_member is not None:
            on_member(len(members), (members[-1][1][-1] - start) / (to - start))
        again = next((at for at in located if _seen(at, found)), None)
        if again is not None:
            return Branch(members, found, False, f"it comes back to the {again.test} it "
                          "passed before: a closed loop, followed once round")
        found += located
        if last:
            return Branch(members, found, True, "")
        ds = min(nominal / max(abs(members[-1][2][-1]), 1e-3), 0.1, 2 * ds)


def unresolved(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether between two members with index margins a and b (1 - |b| per index; NaN
    off the real line) an index comes nearer its band's edge than it moves: there it may
    cross and come back between them unseen."""
    with np.errstate(invalid="ignore"):
        near = np.minimum(a, b)
        return bool(np.any((near >= 0) & (near < np.abs(a - b))))


def _seen(at: Located, found: list[Located]) -> bool:
    """Whether the same test changed before at the same parameter (to 1e-6 of the span):
    a family that is a closed loop -- and a loop in one parameter has two folds at least
    -- would otherwise go round again, reporting them once a lap. (Its members' states
    cannot tell: they differ by the phase along the orbit.)"""
    return any(at.test == b.test and abs(at.x[-1] - b.x[-1]) <= 1e-6 for b in found)


def _step_problem(previous, jacobian, got, solve, tests, signature, bisect):
    """(why the step to `got` fails its checks or '', [where tests change..., the new
    member (member, x, t)])."""
    if got is None:
        return "the corrector does not converge", []
    member, x, t = previous
    member2, x2, A2 = got
    t2 = tangent(A2, t)
    chord = (x2 - x) / max(linalg.norm(x2 - x), 1e-300)
    turn = min(linalg.dot(t2, t), linalg.dot(chord, t))
    if turn < TURN:
        return f"the family's tangent turns by more than {TURN_DEGREES:g} degrees", []
    if signature is not None:
        a, b = signature(member), signature(member2)
        moved = np.max(np.abs(a - b), initial=0.0) if a.size == b.size else np.inf
        if moved > 0.1:
            return f"the stability indices jump by {moved:.2g}", []
    located = []
    checks = {name: (lambda m, t, A, test=test: test(m, t)) for name, test in tests.items()}
    checks["branch point"] = _orientation_against(jacobian)
    for name, test in checks.items():
        if test(member, t, None) == test(member2, t2, A2):
            continue
        at, gap, near, width = _bisect(previous, x2, solve, name, test, bisect)
        if gap:
            return (f"where its {name} test changes, the members on either side stay "
                    f"{gap:.1e} apart (scaled) instead of closing up: a jump to another "
                    "branch, not a bifurcation on one", [])
        located.append(Located(name, member, member2, at, width, near))
    return "", located + [(member2, x2, t2)]


def _orientation_against(A1):
    """The test that a member lies on the branch of `previous` as its orientation, the
    sign of det [W A; t] (A the equations' Jacobian, t the tangent, W the row space of the
    previous member's A1, fixed for the step): constant along a branch of regular points,
    folds included, and it changes sign at a branch point, where another family crosses
    -- or across a jump to a nearby branch (an imperfect crossing), which the tangent's
    turn does not see when the other branch runs straight on. A1: the previous member's
    A; called with A = None for that member itself."""
    s, Vt = linalg.svd(A1)
    r = Vt.shape[0] - 1
    W = linalg.dot(A1, Vt[:r].T) / s[:r]       # A1's left singular vectors

    def positive(m, t, A):
        B = linalg.dot(W.T, A1 if A is None else A)
        lam = linalg.eigvals(np.vstack([B, t]))
        return bool(np.cos(np.sum(linalg.argument(lam))) > 0)
    return positive


def _bisect(previous, xb, solve, name, test, bisect):
    """(x where `test` changes between the member `previous` and the unknowns xb, bisected
    along the arclength to `bisect`; how far its bracket's ends stay apart where that is
    more than the bracket's width -- or the corrector fails inside it, so that the ends
    cannot be brought together -- else 0; the last member solved in the bracket; the
    bracket's extent in the scaled parameter). On one branch the ends close up as the
    bracket shrinks; across a jump between two branches they stay a gap apart."""
    a, xa, ta = previous
    lo, hi = 0.0, linalg.dot(ta, xb - xa)
    ends = [xa, xb]
    near = None
    while hi - lo > bisect:
        mid = 0.5 * (lo + hi)
        got = solve(xa + mid * ta, ta, linalg.dot(ta, xa) + mid)
        if got is None:
            return 0.5 * (ends[0] + ends[1]), max(linalg.norm(ends[1] - ends[0]), GAP), \
                near, abs(ends[1][-1] - ends[0][-1])
        side = int(test(got[0], tangent(got[2], ta), got[2]) != test(a, ta, None))
        ends[side], near = got[1], got[0]
        lo, hi = (mid, hi) if side == 0 else (lo, mid)
    apart = linalg.norm(ends[1] - ends[0])
    return 0.5 * (ends[0] + ends[1]), (apart if apart > 10 * (hi - lo) + GAP else 0.0), \
        near, abs(ends[1][-1] - ends[0][-1])


def equilibrium_family(systems: Callable, start, p0: float, to: float, steps: int = 20,
                       angular_momentum: float | None = None,
                       rotation_rate: float | None = None, bisect: float = 1e-9,
                       max_members: int = 1000, spin_parameter: bool = False,
                       on_member: Callable | None = None):
    """The family of the relative equilibrium reached from positions `start` in
    systems(p0), followed by pseudo-arclength continuation in p to `to` at the given J (or
    rate; with `spin_parameter` p is J itself and systems ignores it): the gradient of the
    amended potential in reduced coordinates (physics.
    equilibria.amended) with the rotation pinned, bordered by the parameter's column (finite
    differences) and the arclength; unknowns scaled by |xi| and |to - p0|. Each member is
    polished and linearised by relative_equilibrium. Folds and changes of the number of
    reduced eigenvalues on the imaginary axis are bisected and named (a complex quartet: a
    Krein collision; a real pair). Returns (members [(p, RelativeEquilibrium)],
    bifurcations [Bifurcation], complete)."""
    def spin(p):
        return p if spin_parameter else angular_momentum

    first = relative_equilibrium(systems(p0), start, spin(p0), rotation_rate)
    d = first.positions.shape[1]
    T, w = frame(systems(p0).masses, d)
    xi0 = linalg.dot(T.T, first.positions.ravel() / w)
    span = abs(to - p0)
    if span == 0:
        raise ValueError("the family's end value equals its start")
    scale = np.concatenate([np.full(xi0.size, linalg.norm(xi0)), [span]])

    def equations(p, xi):
        system = systems(p)
        T, w = frame(system.masses, d)
        return system, T, w, amended(system, T, w, xi, spin(p), rotation_rate)

    def solve(x, row, target, max_iter=30):
        best = np.inf
        for _ in range(max_iter):
            xi, p = x[:-1] * scale[:-1], x[-1] * scale[-1]
            try:
                system, T, w, (g, H, size) = equations(p, xi)
                h = 1e-7 * max(abs(p), 1.0)
                col = (equations(p + h, xi)[3][0] - g) / h
            except ValueError:
                return None
            R = rotations(xi, d)
            A = np.vstack([np.hstack([H, col[:, None]]),
                           np.hstack([R, np.zeros((len(R), 1))])]) * scale
            F = np.concatenate([g, np.zeros(len(R))])
            error = linalg.norm(g) / size
            if not np.isfinite(error) or (error > 10 * best and on_row(row, x, target)):
                return None
            if error <= 1e-12 and on_row(row, x, target):
                q = (w * linalg.dot(T, xi)).reshape(first.positions.shape)
                try:
                    eq = relative_equilibrium(system, q, spin(p), rotation_rate)
                except ValueError:
                    return None
                return eq, x, A
            best = min(best, error)
            x = x + linalg.lstsq(np.vstack([A, row]),
                                 np.concatenate([-F, [target - linalg.dot(row, x)]]), 1e-14)
        return None

    tests = {"fold": lambda e, t: bool(t[-1] > 0), "axis": lambda e, t: e.on_axis}
    branch = follow(solve, np.concatenate([xi0, [p0]]) / scale, to / scale[-1], steps, tests,
                    bisect=bisect, max_members=max_members, on_member=on_member)
    values, branch = at_labels(branch, scale[-1], to, lambda p, e: [
        ("J", e.angular_momentum, spin(p)) if spin(p) is not None else
        ("Omega", e.rotation_rate, rotation_rate)], 1e-9)
    found = []
    for at in branch.found:
        p_at = float(at.x[-1] * scale[-1])
        bracket = max(float(at.width * scale[-1]), 1e-12 * abs(p_at))   # and the corrector's
        if at.test in NAMED:
            found.append(Bifurcation(p_at, at.test, accuracy=bracket))
            continue
        off = min((at.before, at.after), key=lambda e: e.on_axis)
        lam = off.eigenvalues
        big = float(np.max(np.abs(lam), initial=0.0)) or 1.0
        quartet = np.any((np.abs(lam.real) > AXIS_TOLERANCE * big)
                         & (np.abs(lam.imag) > AXIS_TOLERANCE * big))
        found.append(Bifurcation(p_at, "complex quartet (Krein collision)" if quartet
                                 else "real pair", accuracy=bracket))
    return EquilibriumFamily([(v, e) for v, (e, _, _) in zip(values, branch.members)], found,
                             branch.complete, branch.ended)


class EquilibriumFamily(NamedTuple):
    members: list             # [(parameter, RelativeEquilibrium)]
    bifurcations: list[Bifurcation]
    complete: bool            # reached the end value
    ended: str                # if not, why it stopped


def at_labels(branch: Branch, scale: float, to: float, held: Callable, rtol: float):
    """(the parameter of each member, unscaled; the branch) -- the branch cut before the
    first member that is not at what it is labelled with: held(p, member) lists (name,
    its value, the value it must have at parameter p), each to `rtol`. The last label is
    `to` where the branch reached it, to the scaling's rounding."""
    values = np.array([x[-1] * scale for _, x, _ in branch.members])
    if branch.complete:
        if not abs(values[-1] - to) <= 1e-12 * max(abs(to), 1.0):
            branch = branch._replace(complete=False, ended=f"its last member is at "
                                                            f"{values[-1]:.10g}, not {to:g}")
        else:
            values[-1] = to
    for k, (p, (member, _, _)) in enumerate(zip(values, branch.members)):
        for name, value, wanted in held(p, member):
            if not abs(value - wanted) <= rtol * max(abs(wanted), 1.0):
                if k == 0:
                    raise ValueError(f"the start has {name} = {value:.10g}, not {wanted:.10g}")
                kept = {id(m) for m, _, _ in branch.members[:k]}
                return values[:k], Branch(
                    branch.members[:k], [f for f in branch.found if id(f.after) in kept],
                    False, f"the member labelled {p:.10g} has {name} = {value:.10g}, not "
                           f"{wanted:.10g}: it and the rest are dropped")
    return values, branch
