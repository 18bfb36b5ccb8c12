"""Stable and unstable manifolds of a hyperbolic fixed point of an area-preserving map of
the plane (a Poincare section's return map): the curves whose tangle is the chaotic sea
around the fixed point.

A branch is grown from the eigenvector: a fundamental domain of seeds x* + s0 |mu|^sigma v,
sigma in [0, 1] (the map takes its start sigma = 0 close to its end sigma = 1, so the
domain's images, level by level, join into one curve), mapped forward (the unstable
manifold) or by the inverse map (the stable one, whose multiplier under the inverse is
1/mu). Errors off the manifold shrink as the map stretches along it, so the linear seed
costs only its quadratic error, ~ s0^2 of the curvature. Each level's points are the
images of the last level's; where two neighbours of a level lie more than `gap` apart, or
the curve turns by more than `turn` at a point, the seed between them (the mean of their
sigmas) is mapped to that level too, so the curve stays smooth to the eye and its chords
to the tolerance. A map with a negative multiplier (inverse hyperbolic) swaps the two
halves of a branch at each step: its square is used instead.

The first homoclinic intersection of an unstable and a stable branch is where their
polylines first cross (by arclength along the unstable one), refined by bisecting both
segments in their seeds until the chords are shorter than `precision`.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..machine.portable import vatan2, vexp, vlog

FIRST = 1e-5        # s0: the seeds' distance from the fixed point (their quadratic error,
#                     ~1e-10, and the eigenvector's shrink as the map stretches the branch)
SEEDS = 9           # seeds of the fundamental domain before refinement
BENT = 0.9888       # the cosine of the most a curve may turn at a point (8.6 degrees)
SHORT = 0.05        # of the gap: segments shorter than this are not split for turning
FLOOR = 1e-12       # seeds closer than this in sigma are not split (a cusp, a lost orbit)


class Branch(NamedTuple):
    """One half of a stable or unstable manifold: its points in order from the fixed
    point, their arclength along it, the level (iterates of the fundamental domain) and
    the seed sigma each is the image of."""

    kind: str               # "unstable" or "stable"
    side: int               # +1 or -1: the half of the eigenvector it leaves along
    points: np.ndarray      # (n, 2)
    arclength: np.ndarray   # (n,), from the fixed point
    level: np.ndarray       # (n,) int
    seed: np.ndarray        # (n,) sigma in [0, 1]
    resolved: bool          # False: the point budget ran out before `length` was reached


class Homoclinic(NamedTuple):
    """A point where an unstable and a stable branch cross: an orbit asymptotic to the
    fixed point both ways."""

    point: np.ndarray       # (2,)
    accuracy: float         # the chords' sagitta there over the sine of the crossing angle
    unstable: int           # indices of the branches in the list given
    stable: int
    arclength_unstable: float
    arclength_stable: float
    angle: float            # between the curves, radians


class Seeds(NamedTuple):
    """How a branch's points are made: P^n(x* + s0 |mu|^sigma v), P (`step`) applied one
    point at a time, so that a point depends on (sigma, n) alone, not on the order the
    refinement asked for it (a sample of a branch can be computed again bit for bit)."""

    fixed: np.ndarray
    vector: np.ndarray      # the unit eigenvector, on the branch's side
    stretch: float          # |mu| (of the map's square if mu < 0)
    step: Callable          # x -> P(x) (P^2 if mu < 0), or None where its orbit stops

    def seed(self, sigma: float) -> np.ndarray:
        return self.fixed + FIRST * vexp(np.array([sigma * vlog(np.array([self.stretch]))[0]]))[0] \
            * self.vector

    def point(self, sigma: float, level: int):
        """P^level of seed(sigma), or None."""
        return self.onwards(self.seed(sigma), level)[-1]

    def onwards(self, x, n: int) -> list:
        """x and its next n images (None from where its orbit stops)."""
        out = [x]
        for _ in range(n):
            out.append(None if out[-1] is None else self.step(out[-1]))
        return out


def seeds(step: Callable, fixed, vector, multiplier: float, side: int) -> Seeds:
    """A branch's seeds along side * vector from the fixed point, for the map `step`
    (x -> its image or None) whose eigenvalue along `vector` is `multiplier` (|mu| > 1);
    a negative multiplier swaps the halves at each step, so its square is used."""
    v = side * np.asarray(vector, dtype=np.float64)
    v = v / np.sqrt(v @ v)
    fixed = np.asarray(fixed, dtype=np.float64)
    if multiplier < 0:
        return Seeds(fixed, v, multiplier * multiplier,
                     lambda x: None if (y := step(x)) is None else step(y))
    return Seeds(fixed, v, float(multiplier), step)


def grow(seeds: Seeds, kind: str, side: int, length: float, gap: float,
         most: int = 20000) -> Branch:
    """A branch to arclength `length`, or until `most` points or no more images."""
    orbits = {float(s): [seeds.seed(s)] for s in np.linspace(0.0, 1.0, SEEDS)}
    born = dict.fromkeys(orbits, 0)                # the level a seed was first needed at
    levels, total, resolved = 0, 0.0, True
    while total < length:
        level = levels + 1
        for points in orbits.values():             # the last level's points, one step on
            if len(points) == level and (x := seeds.step(points[-1])) is not None:
                points.append(x)
        for _ in range(60):                        # refine the new level where needed
            sigmas = [s for s in sorted(orbits) if len(orbits[s]) > level]
            wanted = _splits(sigmas, [orbits[s][level] for s in sigmas], gap)
            if not wanted or len(orbits) + len(wanted) > most:
                resolved = not wanted
                break
            for sigma in wanted:
                chain = seeds.onwards(seeds.seed(sigma), level)
                orbits[sigma] = [x for x in chain if x is not None]
                born[sigma] = level
        if not resolved or not any(len(p) > level for p in orbits.values()):
            break
        levels = level
        total = _curve(orbits, born, seeds.fixed, levels)[1][-1]
    points, arclength, level, sigma = _curve(orbits, born, seeds.fixed, levels)
    keep = np.searchsorted(arclength, length, side="right") + 1
    return Branch(kind, side, points[:keep], arclength[:keep], level[:keep], sigma[:keep],
                  resolved)


def _splits(sigmas, points, gap) -> list[float]:
    """The seeds to insert between neighbours of one level: where they are more than
    `gap` apart or the curve turns by more than TURN at either (not between seeds closer
    than FLOOR)."""
    if len(points) < 2:
        return []
    p = np.array(points)
    d = np.diff(p, axis=0)
    size = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    far = size > gap
    dot = d[:-1, 0] * d[1:, 0] + d[:-1, 1] * d[1:, 1]
    bent = (dot < BENT * size[:-1] * size[1:]) & (np.minimum(size[:-1], size[1:]) > gap * SHORT)
    far[:-1] |= bent
    far[1:] |= bent
    s = np.array(sigmas)
    split = far & (np.diff(s) > FLOOR)
    return [float(0.5 * (a + b)) for a, b in zip(s[:-1][split], s[1:][split])]


def _curve(orbits, born, fixed, levels):
    """The branch as one curve: level by level, each in its seeds' order (sigma = 1 of a
    level is sigma = 0 of the next: it ends only the last), with its arclength from the
    fixed point; a level holds the seeds needed there or before (a seed a later level
    needed is in the earlier ones' orbits too, but adds nothing to them)."""
    points, level, sigma = [], [], []
    for n in range(levels + 1):
        for s in sorted(orbits):
            if len(orbits[s]) > n and born[s] <= n and (s < 1.0 or n == levels):
                points.append(orbits[s][n])
                level.append(n)
                sigma.append(s)
    p = np.array(points)
    d = np.diff(np.vstack([fixed, p]), axis=0)
    return p, np.cumsum(np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])), \
        np.array(level, dtype=np.int64), np.array(sigma)


def first_homoclinic(branches: list[Branch], unstable: int, stable: int, made: list[Seeds],
                     precision: float = 1e-11) -> Homoclinic | None:
    """The first crossing (by arclength along the unstable branch) of two branches of
    one fixed point, refined by bisecting both segments in their seeds until the chords
    are within `precision` of the curves (their sagitta); None if they do not cross. made: each branch's Seeds
    (those it was grown from, or others -- a looser tolerance -- to see the point move)."""
    u, s = branches[unstable], branches[stable]
    hit = _crossing(u.points, s.points)
    if hit is None:
        return None
    ends = []
    for branch, k, seeds in ((u, hit[0], made[unstable]), (s, hit[1], made[stable])):
        n, lo, hi = branch.level[k], branch.seed[k], branch.seed[k + 1]
        if branch.level[k + 1] != n:            # across a join: the next level's 0 is 1
            hi = 1.0
        ends.append([lambda sigma, n=n, seeds=seeds: seeds.point(sigma, n), lo, hi,
                     branch.points[k], branch.points[k + 1]])
    sag = [np.inf, np.inf]
    for _ in range(80):
        if max(sag) < precision:
            break
        for e, (f, x0, x1, p, q) in enumerate(ends):      # halve each segment
            mid = 0.5 * (x0 + x1)
            m = f(mid)
            if m is None:
                return None
            chord = q - p
            sag[e] = abs(chord[0] * (m - p)[1] - chord[1] * (m - p)[0]) / \
                max(_length(chord), 1e-300) / 4            # the halves' sagitta
            other = ends[1 - e]
            if _segments(p, m, other[3], other[4]) is not None:
                ends[e] = [f, x0, mid, p, m]
            elif _segments(m, q, other[3], other[4]) is not None:
                ends[e] = [f, mid, x1, m, q]
            else:                                      # lost: the chords' error is larger
                return None
    (_, _, _, pa, qa), (_, _, _, pb, qb) = ends
    t = _segments(pa, qa, pb, qb)
    if t is None:
        return None
    point = pa + t[0] * (qa - pa)
    da, db = qa - pa, qb - pb
    cross, dot = abs(da[0] * db[1] - da[1] * db[0]), abs(da[0] * db[0] + da[1] * db[1])
    angle = float(vatan2(np.array([cross]), np.array([dot]))[0])
    sine = cross / max(_length(da) * _length(db), 1e-300)
    i, j = hit
    return Homoclinic(point, float(sum(sag) / max(sine, 1e-300)), unstable, stable,
                      float(u.arclength[i] + _length(point - u.points[i])),
                      float(s.arclength[j] + _length(point - s.points[j])), angle)


def _length(d) -> float:
    return float(np.sqrt(d[0] * d[0] + d[1] * d[1]))


def _segments(p, q, r, s):
    """(t, u) in [0, 1]^2 where segments p-q and r-s cross, or None."""
    d, e, w = q - p, s - r, r - p
    den = d[0] * e[1] - d[1] * e[0]
    if den == 0.0:
        return None
    t = (w[0] * e[1] - w[1] * e[0]) / den
    u = (w[0] * d[1] - w[1] * d[0]) / den
    return (t, u) if 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0 else None


def _crossing(a, b):
    """(i, j): the first segment a[i]-a[i+1] (by i) crossing some segment b[j]-b[j+1]
    (the first such j), or None."""
    p, d = a[:-1], np.diff(a, axis=0)
    r, e = b[:-1], np.diff(b, axis=0)
    for i in range(len(p)):
        w = r - p[i]
        den = d[i, 0] * e[:, 1] - d[i, 1] * e[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den
            u = (w[:, 0] * d[i, 1] - w[:, 1] * d[i, 0]) / den
        ok = np.flatnonzero((den != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1))
        if ok.size:
            return i, int(ok[0])
    return None
