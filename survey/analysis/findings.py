"""Findings: what a report (and results/README.md) may say about an archive. Each is a
statement with the numbers it rests on, the evidence it used and the test that evidence
had to pass -- with the test's threshold -- so that a sentence is printed only where its
evidence holds, and otherwise as "not established" with the reason. The gates here decide
the words that outran their evidence before: a twist or a twistless torus, a resonance,
a stable stretch of a family, a spread over nearby orbits."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..catalog.regimes import REGULAR, Regime

TWIST_DRIFT = 3.0      # a frequency step counts where it exceeds this times the two cells'
#                        own drift (their change between the orbit's halves)
SAME_FREQUENCY = 0.1   # neighbours whose labelled frequency differs by more than this
#                        fraction are on different fundamentals (a relabelling), not a twist
NO_ORDER = ("seed",)   # axes along which cells have no order: nothing turns along them
SEPARATE = 0.5         # an ensemble is a sample if its orbits separate within this share of
#                        the horizon: ln(1 / perturbation_size) / FTLE below it


@dataclass(frozen=True)
class Finding:
    """A claim about an archive: `statement` is printed only if `passed`; otherwise the
    report says it is not established and why (`reason`). `numbers` are what the text
    quotes (results/README.md fills its numbers from them), `evidence` what it rests on,
    `test` the test it had to pass, with its threshold."""

    key: str
    statement: str
    passed: bool
    test: str
    evidence: str = ""
    reason: str = ""
    numbers: dict = field(default_factory=dict)

    def text(self) -> str:
        return self.statement if self.passed else \
            f"Not established: {self.statement[0].lower()}{self.statement[1:]} -- {self.reason}"


def twists(x, nu, drift, regime, axis: str, names) -> list[Finding]:
    """Where a labelled shape frequency turns along a one-parameter family: d nu / d x
    changes sign between two consecutive steps of three neighbouring regular cells -- a
    twistless torus, where KAM's twist condition fails. A step counts only if it exceeds
    TWIST_DRIFT times the two cells' own drift (below it the frequency is not seen to
    move) and stays on one fundamental (a jump of more than SAME_FREQUENCY of it is a
    relabelling); never across a cell of another regime, and never along an axis whose
    cells have no order (a seed). One Finding per frequency column (`names`: its
    labels): passed where a turn is found, else the statement that it changes
    monotonically, with how many steps could be judged."""
    x = np.asarray(x, dtype=float)
    nu, drift = np.abs(np.asarray(nu, dtype=float)), np.abs(np.asarray(drift, dtype=float))
    regular = np.isin(np.asarray(regime), REGULAR)
    test = (f"|d nu| > {TWIST_DRIFT:g} x the two cells' drift between neighbouring regular "
            f"cells, on one fundamental (jump < {SAME_FREQUENCY:.0%}), sign changes between "
            "consecutive such steps")
    if axis in NO_ORDER:
        return [Finding(f"twist.{axis}", f"Twist along {axis}: the cells are seeded random "
                        "starts in no order, and nothing turns along them", True, test)]
    out = []
    for j, name in enumerate(names):
        if not name.startswith("shape"):
            continue
        a, b = nu[:-1, j], nu[1:, j]
        step = b - a
        with np.errstate(invalid="ignore", divide="ignore"):
            judged = (regular[:-1] & regular[1:] & np.isfinite(step)
                      & (np.abs(step) > TWIST_DRIFT * (drift[:-1, j] + drift[1:, j]))
                      & (np.abs(step) <= SAME_FREQUENCY * np.maximum(a, b)))
        turns = [k for k in range(step.size - 1)
                 if judged[k] and judged[k + 1] and np.sign(step[k]) != np.sign(step[k + 1])]
        where = [f"{axis} = {x[k + 1]:g}" for k in turns]
        steps = int(judged.sum())
        numbers = {"turns": len(turns), "steps": steps,
                   "at": [float(x[k + 1]) for k in turns]}
        if turns:
            out.append(Finding(f"twist.{name}", f"{name} turns (d nu / d {axis} changes "
                               f"sign, a twistless torus) at {', '.join(where)}", True, test,
                               f"{steps} steps between neighbouring regular cells above "
                               "their drift", numbers=numbers))
        elif steps:
            out.append(Finding(f"twist.{name}", f"{name} changes monotonically along "
                               f"{axis} over the {steps} steps that could be judged (no "
                               "twistless torus found)", True, test, numbers=numbers))
        else:
            out.append(Finding(f"twist.{name}", f"{name} twists along {axis}", False, test,
                               reason="no step between neighbouring regular cells exceeds "
                                      f"{TWIST_DRIFT:g} times their drift on one "
                                      "fundamental", numbers=numbers))
    return out


def resonant(m, nu, drift) -> np.ndarray:
    """Where a resonance m . nu = 0 (m: cells' nearest resonance vectors, (..., k)) is one:
    |m . nu| within the measured drift, sum |m_i| |d nu_i| -- NAFF cannot place the
    frequencies closer -- and m not an n:1 relation between two frequencies (one a
    harmonic of the other, or a 1:1 pair a symmetry makes equal): such a "fundamental"
    is not one, and its relation is no resonance of the orbit's torus."""
    m = np.asarray(m)
    nu, drift = np.abs(np.asarray(nu, dtype=float)), np.abs(np.asarray(drift, dtype=float))
    used = m != 0
    with np.errstate(invalid="ignore"):
        value = np.abs(np.sum(np.where(used, m * nu, 0.0), axis=-1))
        spread = np.sum(np.where(used, np.abs(m) * drift, 0.0), axis=-1)
        smallest = np.min(np.where(used, np.abs(m), np.iinfo(np.int64).max), axis=-1)
        relation = (np.sum(used, axis=-1) == 2) & (smallest == 1)
        return used.any(axis=-1) & (value <= spread) & ~relation


def decorrelated(ftle, horizon, size: float, irregular) -> Finding:
    """Whether the ensembles of the irregular cells are samples: orbits started `size`
    (relative) apart separate to the orbit's own scale after about ln(1/size) / FTLE; where
    that exceeds the cell's horizon the perturbed orbits are still one orbit at the end,
    and their spread measures nothing but that. The finding lists how many such cells
    there are and the worst ratio."""
    ftle, horizon = np.asarray(ftle, dtype=float), np.asarray(horizon, dtype=float)
    cells = np.asarray(irregular, dtype=bool) & np.isfinite(ftle) & np.isfinite(horizon)
    test = f"ln(1 / perturbation_size) / FTLE below {SEPARATE:g} of the cell's horizon"
    if not cells.any():
        return Finding("ensembles.decorrelate", "No irregular cell has an ensemble to judge",
                       True, test, numbers={"cells": 0, "slow": 0})
    with np.errstate(divide="ignore"):
        ratio = np.log(1.0 / size) / np.maximum(ftle[cells], 0.0) / horizon[cells]
    slow = int(np.sum(ratio >= SEPARATE))
    numbers = {"cells": int(cells.sum()), "slow": slow, "worst": float(np.max(ratio)),
               "median": float(np.median(ratio))}
    if slow:
        return Finding("ensembles.decorrelate", "The ensembles of the irregular cells are "
                       "samples of nearby orbits", False, test, reason=(
                           f"in {slow} of the {int(cells.sum())} irregular cells orbits "
                           f"started {size:g} apart need more than {SEPARATE:g} of the "
                           f"horizon to separate (ln(1/{size:g}) / FTLE up to "
                           f"{np.max(ratio):.3g} times it): their spread is not that of "
                           "independent orbits"), numbers=numbers)
    return Finding("ensembles.decorrelate", f"The ensembles of all {int(cells.sum())} "
                   f"irregular cells separate early in their horizon (ln(1/{size:g}) / FTLE "
                   f"at most {np.max(ratio):.2g} of it): their spreads are samples", True,
                   test, numbers=numbers)


def family_stability(p, index_real, index_imag, stable, name: str,
                     tol: float = 1e-6) -> list[Finding]:
    """Each stretch of consecutive linearly stable members of a family (parameter p,
    stability indices b = (mu + 1/mu)/2 per member and pair, the members' `stable` flag)
    as a finding "linearly stable for name from a to b": established only where between
    every two neighbouring members each real index stays farther from +-1 than it moves
    (the rule numerics.continuation.unresolved refines the steps by) -- else it may have
    left the band and come back between them unseen, and the stretch is not established,
    with where."""
    p = np.asarray(p, dtype=float)
    real, imag = np.asarray(index_real, dtype=float), np.asarray(index_imag, dtype=float)
    margin = np.where(np.abs(imag) <= tol, 1.0 - np.abs(real), np.nan)
    stable = np.asarray(stable, dtype=bool)
    test = ("between neighbouring members every stability index farther from +-1 than it "
            "moves")
    out = []
    k = 0
    while k < p.size:
        if not stable[k]:
            k += 1
            continue
        end = k
        while end + 1 < p.size and stable[end + 1]:
            end += 1
        close = []
        for i in range(k, end):
            with np.errstate(invalid="ignore"):
                near = np.minimum(margin[i], margin[i + 1])
                gap = np.abs(margin[i] - margin[i + 1])
                bad = (near >= 0) & (near < gap)
            if bad.any():
                close.append((p[i], p[i + 1], float(np.nanmin(near[bad]))))
        lo, hi = sorted((p[k], p[end]))
        statement = (f"linearly stable for {name} from {lo:.10g} to {hi:.10g} "
                     f"({end - k + 1} member{'s' * (end > k)})")
        numbers = {"from": float(lo), "to": float(hi), "members": end - k + 1,
                   "unresolved": len(close)}
        reason = "" if not close else (
            f"between {len(close)} pair{'s' * (len(close) > 1)} of neighbouring members an "
            "index comes nearer +-1 than it moves (" + "; ".join(
                f"{a:.8g} to {b:.8g}, within {m:.1e}" for a, b, m in close[:4])
            + ("; ..." if len(close) > 4 else "") + "): it may leave the band and return "
            "between them unseen")
        out.append(Finding(f"family.stable.{len(out)}", statement[0].upper() + statement[1:],
                           not close, test, reason=reason, numbers=numbers))
        k = end + 1
    return out


def how_many(k: int, n: int, left_out: str = "") -> str:
    """'all 51', 'none of 51', '49 of 51': a quantifier only where the count supports it
    (all and none need every cell counted, and at least one), with the cells left out of
    the count named (`left_out`: e.g. '2 failed')."""
    said = (f"all {n}" if k == n and n > 0 else f"none of {n}" if k == 0 and n > 0
            else f"{k} of {n}")
    return said + (f" ({left_out} left out)" if left_out else "")


def regions(mask: np.ndarray, edge=None) -> list[tuple[np.ndarray, bool]]:
    """The connected regions of True cells of a grid (neighbours along each axis), each as
    (its cells' flat indices, enclosed): enclosed where no cell of it lies on the grid's
    edge or next to an `edge` cell (e.g. inaccessible: the end of the energy shell, not
    another regime), so that cells of another kind bound it on every side -- the only
    case where a region may be called an island, or said to be surrounded."""
    mask = np.asarray(mask, dtype=bool)
    edge = np.zeros(mask.shape, dtype=bool) if edge is None else np.asarray(edge, dtype=bool)
    label = np.full(mask.shape, -1)
    out = []
    for start in zip(*np.nonzero(mask)):
        if label[start] >= 0:
            continue
        label[start] = len(out)
        stack, cells, edge_here = [start], [], False
        while stack:
            cell = stack.pop()
            cells.append(np.ravel_multi_index(cell, mask.shape))
            for axis, size in enumerate(mask.shape):
                edge_here |= cell[axis] in (0, size - 1)
                for step in (-1, 1):
                    other = list(cell)
                    other[axis] += step
                    other = tuple(other)
                    if not 0 <= other[axis] < size:
                        continue
                    edge_here = edge_here or bool(edge[other])
                    if mask[other] and label[other] < 0:
                        label[other] = len(out)
                        stack.append(other)
        out.append((np.sort(np.array(cells)), not edge_here))
    return out


def islands(regime: np.ndarray) -> Finding:
    """Regular regions of a map or scan that the grid encloses: bounded on every side by
    cells of other regimes, not by the grid's edge or the inaccessible cells (where the
    energy shell ends). A region that touches either may go on beyond it, so no
    geometric word is given to it."""
    found = regions(np.isin(regime, REGULAR), np.asarray(regime) == Regime.INACCESSIBLE)
    inside = [cells for cells, enclosed in found if enclosed]
    sizes = sorted((c.size for c in inside), reverse=True)
    test = "a regular region bounded on every side by other regimes within the grid"
    if not inside:
        return Finding("islands", "Regular islands within the grid", False, test, reason=(
            f"none of the {len(found)} regular region{'s' * (len(found) != 1)} is enclosed "
            "within the grid (each touches its edge or an inaccessible cell)" if found
            else "no regular cells"))
    return Finding("islands", f"{len(inside)} regular island{'s' * (len(inside) > 1)} "
                   f"enclosed by other regimes within the grid ({', '.join(map(str, sizes))} "
                   f"cells), and {len(found) - len(inside)} regular region"
                   f"{'s' * (len(found) - len(inside) != 1)} cut by the grid's edge or the "
                   "inaccessible cells", True,
                   test, evidence="the regime of each cell and its neighbours along each axis",
                   numbers={"islands": len(inside), "edge": len(found) - len(inside),
                            "sizes": sizes})


def to_accuracy(x: float, accuracy: float) -> str:
    """x with the decimals its accuracy supports (at most 12): a number printed past its
    accuracy claims digits it does not have."""
    places = 12 if not accuracy > 0 else int(min(max(-np.floor(np.log10(accuracy)), 0), 12))
    return f"{round(x, places) + 0.0:.{places}f}"
