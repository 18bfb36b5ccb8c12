"""Is a cell on a KAM torus, in a resonance, periodic, sticky or chaotic -- and how sure are
we? `classify` decides each cell's regime from the evidence an archive stores (the status,
Birkhoff digits, MEGNO, FTLE, SALI, frequency diffusion and resonance), so it can be run
again on any archive with other thresholds and no integration; at half a cell's horizon
too, from the histories, which is how a verdict in doubt is found (and extended by the
survey). It reads an xarray Dataset, or `Table`: the workers' plain arrays."""
from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ..catalog.indicators import BY_NAME, REGISTRY, TANGENT
from ..catalog.regimes import IRREGULAR, REGULAR, Regime, Thresholds
from .findings import resonant
from ..catalog.status import Status
from ..catalog.variables import START_COORDINATES, V
from .refine import as_grid, refined_axes

# the lines of evidence (catalog.indicators.REGISTRY): (name, how it votes)
EVIDENCE = tuple((i.name, i.vote) for i in REGISTRY if i.vote is not None)
# the Lyapunov-type lines, read from deviation vectors: chaotic by T means an orbit left
# its torus, whatever the first half looked like
LYAPUNOV = tuple(name for name, _ in EVIDENCE if BY_NAME[name].source == TANGENT)


class Table(dict):
    """Arrays by variable name, cells first (and the coordinates classify reads), read the
    way classify reads a Dataset: `name in table`, `table[name].values`."""

    def __getitem__(self, name):
        return _Column(dict.__getitem__(self, name))


class _Column(NamedTuple):
    values: np.ndarray

    @property
    def shape(self):
        return self.values.shape


def horizon(ds) -> np.ndarray:
    """Each cell's horizon: regime_horizon where stored, else the archive's t_final (the
    last history time)."""
    if V.regime_horizon in ds:
        return ds[V.regime_horizon].values
    return np.full(ds[V.status].shape, float(ds["history_time"].values[-1]))


def at_half_horizon(ds, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(values, times) of a history variable at the history time nearest half each cell's
    horizon."""
    times = ds["history_time"].values
    half = 0.5 * horizon(ds)
    with np.errstate(invalid="ignore"):
        index = np.argmin(np.abs(times - np.nan_to_num(half, nan=-1.0)[..., None]), axis=-1)
    values = np.take_along_axis(ds[name].values, index[..., None], axis=-1)[..., 0]
    return np.where(np.isfinite(half), values, np.nan), times[index]


def _evidence(ds, half: bool):
    """(key, Vote, values) of each line of evidence present in the archive, as its vote
    reads them (the FTLE in units of ln(T)/T; at half each cell's horizon with `half`)."""
    for key, vote in EVIDENCE:
        name = vote.half if half else vote.variable
        if not name or name not in ds:
            continue
        if half and ds[name].values.ndim > len(ds[V.status].shape):
            x, t = at_half_horizon(ds, name)
        else:
            x = ds[name].values.astype(float)
            t = ds[V.t_end].values if vote.per_torus_rate else None
        if vote.per_torus_rate:
            with np.errstate(invalid="ignore", divide="ignore"):
                x = x / (np.log(t) / t)
        yield key, vote, x


def evidence_votes(ds, th: Thresholds, half: bool = False) -> dict[str, np.ndarray]:
    """Each line of evidence present in the archive as votes: +1 regular, -1 chaotic, 0 no
    vote (between the thresholds), NaN where the evidence is missing. The FTLE is measured
    in units of ln(T)/T, a torus's FTLE at the time reached. With `half`, the evidence at
    half each cell's horizon (Vote.half: its history there, or the variable stored for it);
    a line with none has no vote."""
    votes = {}
    for key, vote, x in _evidence(ds, half):
        regular, chaotic = (vote.sign * getattr(th, f"{vote.thresholds}_{side}")
                            for side in ("regular", "chaotic"))
        with np.errstate(invalid="ignore"):
            cast = np.where(vote.sign * x >= regular, 1.0,
                            np.where(vote.sign * x <= chaotic, -1.0, 0.0))
        votes[key] = np.where(np.isfinite(x), cast, np.nan)
    return votes


def threshold_margins(ds, th: Thresholds) -> dict[str, np.ndarray]:
    """Each line of evidence's distance to the nearer of its two thresholds, relative to
    that threshold (NaN where missing): a vote within a small margin would change with a
    small change of the evidence, so a verdict resting on it is named as such."""
    out = {}
    for key, vote, x in _evidence(ds, False):
        ends = [getattr(th, f"{vote.thresholds}_{side}") for side in ("regular", "chaotic")]
        with np.errstate(invalid="ignore", divide="ignore"):
            out[key] = np.min([np.abs(x - e) / max(abs(e), 1e-300) for e in ends], axis=0)
    return out


def classify(ds, thresholds: Thresholds | None = None, half: bool = False):
    """(regime, confidence) of every cell of an archive, from the evidence it stores:
    the status, WBA digits (at T and T/2), MEGNO (and its history at T/2), FTLE, SALI,
    frequency diffusion and resonance. Works on archives missing some of it (old ones, or
    [indicators] which = []): absent evidence has no vote. With `half`: the verdict at
    half each cell's horizon, from the evidence there (evidence_votes); the frequencies and
    the first half's digits are not known there, so regular is torus and mixed votes are
    undetermined.

    Each line of evidence votes regular, chaotic or not at all (Thresholds). Then:
    regular votes only -> periodic (at most one shape frequency), resonant (a resonance of
    order <= resonance_order holding to resonance_width) or torus; chaotic votes only ->
    chaotic; both -> sticky if the first half looked regular (digits at T/2 or <Y> at T/2
    on the regular side) while a Lyapunov-type indicator is chaotic by T, else
    undetermined. The confidence is the share of the lines of evidence
    present that support the regime (0 for undetermined and for failed runs; 1 for
    collision and inaccessible, which the status states)."""
    th = thresholds or Thresholds.from_table(stored_table(ds))
    shape = ds[V.status].shape
    status = ds[V.status].values
    votes = evidence_votes(ds, th, half)
    stack = np.stack(list(votes.values())) if votes else np.full((1,) + shape, np.nan)
    present = np.sum(np.isfinite(stack), axis=0)
    regular = np.sum(stack == 1, axis=0)
    chaotic = np.sum(stack == -1, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        share_reg = np.where(present > 0, regular / present, 0.0)
        share_chaos = np.where(present > 0, chaotic / present, 0.0)

    regime = np.full(shape, Regime.UNDETERMINED, dtype=np.int8)
    confidence = np.zeros(shape)
    only_regular = (regular > 0) & (chaotic == 0)
    regime[only_regular] = Regime.TORUS
    confidence[only_regular] = share_reg[only_regular]
    if V.resonance_distance in ds and not half:
        regime[only_regular & on_resonance(ds, th)] = Regime.RESONANT
    if V.frequency in ds and not half:
        labels = [str(x) for x in ds["fundamental_name"].values]
        cols = [i for i, name in enumerate(labels) if name.startswith("shape")]
        change = ds[V.frequency_change].values[..., cols] if V.frequency_change in ds else \
            np.zeros(ds[V.frequency].values[..., cols].shape)
        regime[only_regular & harmonic(ds[V.frequency].values[..., cols], change, th)] = \
            Regime.PERIODIC
    if V.moving_shapes in ds and not half:
        regime[only_regular & (ds[V.moving_shapes].values == 0)] = Regime.EQUILIBRIUM
    only_chaotic = (chaotic > 0) & (regular == 0)
    regime[only_chaotic] = Regime.CHAOTIC
    confidence[only_chaotic] = share_chaos[only_chaotic]
    mixed = (chaotic > 0) & (regular > 0)
    early = np.zeros(shape, dtype=bool)
    if V.birkhoff_digits_half in ds and not half:
        early |= ds[V.birkhoff_digits_half].values >= th.digits_regular
    if V.megno_history in ds and not half:
        early |= at_half_horizon(ds, V.megno_history)[0] <= th.megno_regular
    late = np.zeros(shape, dtype=bool)
    for name in LYAPUNOV:
        if name in votes:
            late |= votes[name] == -1
    sticky = mixed & early & late
    regime[sticky] = Regime.STICKY
    confidence[sticky] = share_chaos[sticky]

    regime[status == Status.INACCESSIBLE] = Regime.INACCESSIBLE
    regime[status == Status.COLLISION] = Regime.COLLISION
    regime[status == Status.ESCAPED] = Regime.ESCAPED
    known = [Status.INACCESSIBLE, Status.COLLISION, Status.ESCAPED]
    failed = ~np.isin(status, [Status.OK, Status.EVENT, *known])
    regime[failed] = Regime.UNDETERMINED
    confidence[np.isin(status, known)] = 1.0
    confidence[failed | (regime == Regime.UNDETERMINED)] = 0.0
    return regime, confidence


def harmonic(nu: np.ndarray, change: np.ndarray, th: Thresholds) -> np.ndarray:
    """Cells whose shape frequencies nu (..., k; NaN where none) are all harmonics of one:
    every pair in a ratio p/q with p + q <= resonance_order, to harmonic_width or to their
    own uncertainty, the change between the orbit's halves `change` (the figure-eight's
    lines are 2 and 3 times its frequency). A single frequency is; none is not (a shape
    that does not move is an equilibrium)."""
    nu, change = np.abs(nu), np.nan_to_num(np.abs(change), nan=np.inf)
    known = np.isfinite(nu)
    out = known.sum(axis=-1) >= 1
    scale = np.max(np.where(known, nu, 0.0), axis=-1)
    k = nu.shape[-1]
    for i in range(k):
        for j in range(i + 1, k):
            both = known[..., i] & known[..., j]
            fit = np.zeros(out.shape, dtype=bool)
            for q in range(1, th.resonance_order):
                with np.errstate(invalid="ignore", divide="ignore"):
                    p = np.round(q * nu[..., i] / nu[..., j])
                    miss = np.abs(q * nu[..., i] - p * nu[..., j])
                    tol = np.maximum(th.harmonic_width * np.hypot(p, q) * scale,
                                     q * change[..., i] + p * change[..., j])
                    fit |= (p >= 1) & (p + q <= th.resonance_order) & (miss <= tol)
            out &= ~both | fit
    return out


def verdict_class(regime) -> np.ndarray:
    """The class a verdict's stability is judged by: 1 regular (torus, resonant,
    periodic), 2 irregular (chaotic, sticky), 0 anything else (undetermined, a failed run)
    -- a torus that turns out resonant has not changed its mind."""
    regime = np.asarray(regime)
    return np.where(np.isin(regime, REGULAR), 1, np.where(np.isin(regime, IRREGULAR), 2, 0))


def stable(history) -> np.ndarray:
    """1 where the last verdict of a regime_history (..., horizon; -1 past the last) is of
    the class of the one before, else 0."""
    history = np.asarray(history)
    decided = np.sum(history >= 0, axis=-1)
    last = np.take_along_axis(history, np.maximum(decided - 1, 0)[..., None], -1)[..., 0]
    before = np.take_along_axis(history, np.maximum(decided - 2, 0)[..., None], -1)[..., 0]
    return ((decided >= 2) & (verdict_class(last) == verdict_class(before))).astype(np.int8)


def on_resonance(ds, th: Thresholds) -> np.ndarray:
    """Cells whose nearest resonance of order <= resonance_order holds to resonance_width:
    |m . nu| / (|m| max|nu|) at most that. Tighter than the detuning of small oscillations
    about the rotating triangle from its 1:2 epicyclic degeneracy (~1e-6 at delta = 0.5),
    looser than what NAFF resolves on a locked orbit at T = 2000. And it must pass the
    findings' gate (findings.resonant): within the frequencies' own drift, and not an n:1
    relation between two of them (a harmonic taken for a fundamental, or a symmetry's
    1:1)."""
    order = ds[V.resonance_order].values
    with np.errstate(invalid="ignore"):
        near = (ds[V.resonance_distance].values <= th.resonance_width) & (order > 0) & \
            (order <= th.resonance_order)
    if V.resonance in ds and V.frequency in ds and V.frequency_change in ds:
        near &= resonant(ds[V.resonance].values, ds[V.frequency].values,
                         ds[V.frequency_change].values)
    return near


def stored_config(ds) -> dict:
    """The config an archive was run with, as TOML tables: the resolved one, every default
    filled in (`config_resolved`: pipeline.config.Config.resolved_text), which archives
    written before it lack -- `python -m survey report` and `plot` fill it in for them --
    else the config as written. {} where there is none, or it cannot be read (not TOML,
    or nested deeper than the parser's recursion)."""
    import tomllib
    try:
        return tomllib.loads(str(ds.attrs.get("config_resolved", ds.attrs.get("config", ""))))
    except (tomllib.TOMLDecodeError, RecursionError):
        return {}


def stored_table(ds, table: str = "tori") -> dict | None:
    """A table ([tori] by default) of the config stored in an archive, if any."""
    return stored_config(ds).get(table)


def summary(ds, regime=None) -> list[str]:
    """Counts of each regime, and for a one-axis grid of a family parameter where it
    changes from regular to chaotic."""
    ds = as_grid(ds)
    regime = ds[V.regime].values if regime is None else regime
    total = regime.size
    counts = [(r, int(np.sum(regime == r))) for r in Regime]
    lines = ["regimes: " + ", ".join(f"{r.name.lower()} {n} ({100 * n / total:.0f}%)"
                                     for r, n in counts if n)]
    axes = [d for d in ds[V.status].dims]
    if len(axes) == 1 and axes[0] not in START_COORDINATES and not refined_axes(ds):
        x = ds[axes[0]].values
        regular = np.isin(regime, REGULAR)
        chaotic = np.isin(regime, IRREGULAR)
        labelled = np.flatnonzero(regular | chaotic)
        for a, b in zip(labelled[:-1], labelled[1:]):
            if regular[a] != regular[b]:
                lines.append(f"{axes[0]}: {Regime(regime[a]).name.lower()} at {x[a]:g} -> "
                             f"{Regime(regime[b]).name.lower()} at {x[b]:g}")
    return lines


def wilson(k, n, level: float = 0.95):
    """The Wilson score interval (95% by default) of binomial shares k / n (arrays or
    numbers; NaN where n = 0)."""
    from statistics import NormalDist
    z = NormalDist().inv_cdf(0.5 + level / 2)
    k, n = np.asarray(k, dtype=float), np.asarray(n, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        p, q = k / n, z * z / n
        centre = (p + q / 2) / (1 + q)
        half = z / (1 + q) * np.sqrt(p * (1 - p) / n + q / (4 * n))
    # exactly 0 and 1 at k = 0 and k = n (the formula's rounding falls a few ulps short)
    low = np.where((k == 0) & (n > 0), 0.0, np.maximum(0.0, centre - half))
    high = np.where((k == n) & (n > 0), 1.0, np.minimum(1.0, centre + half))
    return (low, high) if low.ndim else (float(low), float(high))


def regular_share(ds, regime=None):
    """Over a grid with a `seed` axis (several seeded starts per point): at each point of
    the other axes the starts decided (regular or irregular), those regular, their share
    and its 95% Wilson interval -- the starts are a random sample, the share an estimate
    of the regular part of what the family draws from. An xarray Dataset."""
    import xarray as xr
    regime = ds[V.regime] if regime is None else regime
    decided = regime.isin(list(REGULAR + IRREGULAR)).sum("seed")
    regular = regime.isin(list(REGULAR)).sum("seed")
    low, high = wilson(regular.values, decided.values)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = regular / decided.where(decided > 0)
    return xr.Dataset({"decided": decided, "regular": regular, "share": share,
                       "share_low": (decided.dims, low), "share_high": (decided.dims, high)})


def threshold_variants(ds, th: Thresholds):
    """Each vote threshold of the evidence an archive holds moved a quarter of the way
    towards its partner and as far away from it (in log10 for SALI, which spans decades):
    (threshold name, its moved value, Thresholds) -- a regular share that moves much
    under these rests on where a threshold sits, not on the orbits."""
    base = dataclasses.asdict(th)
    present = {vote.thresholds: vote.log for _, vote, _ in _evidence(ds, False)}
    for prefix, log in present.items():
        ends = {side: base[f"{prefix}_{side}"] for side in ("regular", "chaotic")}
        scale = (lambda v: np.log10(v)) if log else (lambda v: v)
        step = (scale(ends["chaotic"]) - scale(ends["regular"])) / 4
        for side, sign in (("regular", 1), ("regular", -1), ("chaotic", -1), ("chaotic", 1)):
            moved = scale(ends[side]) + sign * step
            value = float(10.0 ** moved if log else moved)
            yield f"{prefix}_{side}", value, Thresholds(**{**base, f"{prefix}_{side}": value})


def share_sensitivity(ds, th: Thresholds):
    """The regular share of a seeded sample (`regular_share`) as archived, then decided
    again from the evidence each cell's run stored (no orbit integrated again) with each
    of `threshold_variants`, and at half each cell's horizon: [(label, share Dataset)]."""
    def share(regime):
        return regular_share(ds, ds[V.status].copy(data=regime))
    rows = [("as archived", regular_share(ds))]
    rows += [(f"{name} = {value:.3g}", share(classify(ds, moved)[0]))
             for name, value, moved in threshold_variants(ds, th)]
    rows.append(("at half each cell's horizon", share(classify(ds, th, half=True)[0])))
    return rows


def separation_share(ds, crossings: int, growth: float):
    """The regular share a short-horizon separation criterion gives on an archive's
    orbits (as Henon & Heiles decided theirs): a start counts as regular if its deviation
    vector grew by less than `growth` by the time of its `crossings`-th section crossing
    -- the growth exp(t FTLE(t)) interpolated in t FTLE(t) between history times (from 0
    at t = 0) -- irregular if by more, undecided with fewer crossings. A `regular_share`
    Dataset."""
    times = np.concatenate([[0.0], ds["history_time"].values])
    log_growth = ds[V.ftle_history].values * ds["history_time"].values
    when = ds[V.crossing_time].values[..., crossings - 1]
    flat_log, flat_when = log_growth.reshape(-1, times.size - 1), when.ravel()
    grown = np.full(flat_when.shape, np.nan)
    for i, (row, t) in enumerate(zip(flat_log, flat_when)):
        known = np.concatenate([[True], np.isfinite(row)])
        if np.isfinite(t) and t <= times[known][-1]:
            grown[i] = np.interp(t, times[known], np.concatenate([[0.0], row])[known])
    verdict = np.where(np.isnan(grown), Regime.UNDETERMINED,
                       np.where(grown < np.log(growth), Regime.TORUS, Regime.CHAOTIC))
    return regular_share(ds, ds[V.status].copy(data=verdict.reshape(when.shape)))
