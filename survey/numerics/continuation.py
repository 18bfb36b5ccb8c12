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

from ..physics import linalg
from ..physics.equilibria import (
    AXIS_TOLERANCE,
    Bifurcation,
    amended,
    frame,
    relative_equilibrium,
    rotations,
)

TURN = 0.984807753012208    # cos 10 degrees: a step whose tangent or chord turns more is halved


class Located(NamedTuple):
    """Where a test changes between two members, bisected along the arclength."""

    test: str
    before: object            # the members on either side
    after: object
    x: np.ndarray             # the scaled unknowns there (mean of the last bracket's ends)


def tangent(A: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """The unit null vector of A, oriented along `previous`."""
    t = linalg.svd(A)[1][-1]
    return -t if linalg.dot(t, previous) < 0 else t


def follow(solve: Callable, x0: np.ndarray, to: float, steps: int,
           signature: Callable | None = None, max_members: int = 1000):
    """The members [(member, x, t)] from scaled x0 (its parameter held at x0[-1]) to the
    scaled parameter value `to`, and whether it was reached. The step advances the
    parameter by 1/steps where the family runs along it (the state by at most 0.1),
    halved where the corrector fails, where the new tangent or the chord turns by more
    than 10 degrees, or where `signature(member)` (e.g. stability indices) moves by more
    than 0.1: signs of a jump to another branch. Stops at `to` (a last member solved
    there), at max_members, after ds falls to 1e-4 of its nominal value, or where the
    family has turned back and run twice the span past its start."""
    direction = np.zeros(x0.size)
    direction[-1] = np.sign(to - x0[-1])
    first = solve(x0, direction, linalg.dot(direction, x0))
    if first is None:
        raise ValueError("the start does not converge as a member of the family")
    member, x, A = first
    members = [(member, x, tangent(A, direction))]
    start = x[-1]
    ds = nominal = 1.0 / steps
    while len(members) < max_members and abs(members[-1][1][-1] - start) <= 2.0:
        member, x, t = members[-1]
        found = solve(x + ds * t, t, linalg.dot(t, x) + ds)
        if found is None:
            ds /= 2
            if ds < 1e-4 * nominal:
                break
            continue
        member2, x2, A2 = found
        t2 = tangent(A2, t)
        chord = (x2 - x) / max(linalg.norm(x2 - x), 1e-300)
        moved = 0.0
        if signature is not None:
            a, b = signature(member), signature(member2)
            moved = np.max(np.abs(a - b), initial=0.0) if a.size == b.size else np.inf
        turn = min(linalg.dot(t2, t), linalg.dot(chord, t))
        if (turn < TURN or moved > 0.1) and ds > 1e-3 * nominal:
            ds /= 2
            continue
        if (x2[-1] - to) * (x[-1] - to) <= 0:        # passed the end: solve there
            row = np.zeros(x.size)
            row[-1] = 1.0
            last = solve(x + (to - x[-1]) / t[-1] * t if abs(t[-1]) > 0.1 else x2, row, to)
            if last is not None:
                members.append((last[0], last[1], tangent(last[2], t)))
                return members, True
            break
        members.append((member2, x2, t2))
        ds = min(nominal / max(abs(t2[-1]), 1e-3), 0.1, 2 * ds)
    return members, False


def locate(members, solve: Callable, tests: dict[str, Callable], bisect: float = 1e-9):
    """Every change of each test(member, tangent) between consecutive members, bisected
    along the arclength from the earlier one to `bisect`: [Located] in the family's
    order. A fold is the test `lambda m, t: t[-1] > 0`."""
    found = []
    for (a, xa, ta), (b, xb, tb) in zip(members, members[1:]):
        for name, test in tests.items():
            if test(a, ta) == test(b, tb):
                continue
            lo, hi = 0.0, linalg.dot(ta, xb - xa)
            ends = [xa, xb]
            while hi - lo > bisect:
                mid = 0.5 * (lo + hi)
                got = solve(xa + mid * ta, ta, linalg.dot(ta, xa) + mid)
                if got is None:
                    break
                side = int(test(got[0], tangent(got[2], ta)) != test(a, ta))
                ends[side] = got[1]
                lo, hi = (mid, hi) if side == 0 else (lo, mid)
            found.append(Located(name, a, b, 0.5 * (ends[0] + ends[1])))
    return found


def equilibrium_family(systems: Callable, start, p0: float, to: float, steps: int = 20,
                       angular_momentum: float | None = None,
                       rotation_rate: float | None = None, bisect: float = 1e-9,
                       max_members: int = 1000, spin_parameter: bool = False):
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
            if not np.isfinite(error) or error > 10 * best:
                return None
            if error <= 1e-12:
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

    members, complete = follow(solve, np.concatenate([xi0, [p0]]) / scale, to / scale[-1],
                               steps, max_members=max_members)
    tests = {"fold": lambda e, t: bool(t[-1] > 0), "axis": lambda e, t: e.on_axis}
    found = []
    for at in locate(members, solve, tests, bisect):
        p_at = float(at.x[-1] * scale[-1])
        if at.test == "fold":
            found.append(Bifurcation(p_at, "fold"))
            continue
        off = min((at.before, at.after), key=lambda e: e.on_axis)
        lam = off.eigenvalues
        big = float(np.max(np.abs(lam), initial=0.0)) or 1.0
        quartet = np.any((np.abs(lam.real) > AXIS_TOLERANCE * big)
                         & (np.abs(lam.imag) > AXIS_TOLERANCE * big))
        found.append(Bifurcation(p_at, "complex quartet (Krein collision)" if quartet
                                 else "real pair"))
    values = [float(x[-1] * scale[-1]) for _, x, _ in members]
    if complete:
        values[-1] = float(to)        # solved there; the scaling's rounding aside
    return [(v, e) for v, (e, _, _) in zip(values, members)], found, complete
