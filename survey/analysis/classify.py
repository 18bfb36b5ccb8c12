"""Is a cell on a KAM torus, in a resonance, periodic, sticky or chaotic -- and how sure are
we? `classify` decides each cell's regime from the evidence an archive stores (the status,
Birkhoff digits, MEGNO, FTLE, SALI, frequency diffusion and resonance), so it can be run
again on any archive with other thresholds and no integration."""
from __future__ import annotations

import numpy as np

from ..catalog.indicators import BY_NAME, REGISTRY, TANGENT
from ..catalog.regimes import IRREGULAR, REGULAR, Regime, Thresholds
from ..catalog.status import Status
from ..catalog.variables import V

# the lines of evidence (catalog.indicators.REGISTRY): (name, how it votes)
EVIDENCE = tuple((i.name, i.vote) for i in REGISTRY if i.vote is not None)
# the Lyapunov-type lines, read from deviation vectors: chaotic by T means an orbit left
# its torus, whatever the first half looked like
LYAPUNOV = tuple(name for name, _ in EVIDENCE if BY_NAME[name].source == TANGENT)


def evidence_votes(ds, th: Thresholds) -> dict[str, np.ndarray]:
    """Each line of evidence present in the archive as votes: +1 regular, -1 chaotic, 0 no
    vote (between the thresholds), NaN where the evidence is missing. The FTLE is measured
    in units of ln(T)/T, a torus's FTLE at the time reached."""
    votes = {}
    for key, vote in EVIDENCE:
        if vote.variable not in ds:
            continue
        x = ds[vote.variable].values.astype(float)
        if vote.per_torus_rate:
            t_end = ds[V.t_end].values
            with np.errstate(invalid="ignore", divide="ignore"):
                x = x / (np.log(t_end) / t_end)
        regular, chaotic = (vote.sign * getattr(th, f"{vote.thresholds}_{side}")
                            for side in ("regular", "chaotic"))
        with np.errstate(invalid="ignore"):
            cast = np.where(vote.sign * x >= regular, 1.0,
                            np.where(vote.sign * x <= chaotic, -1.0, 0.0))
        votes[key] = np.where(np.isfinite(x), cast, np.nan)
    return votes


def classify(ds, thresholds: Thresholds | None = None):
    """(regime, confidence) of every cell of an archive, from the evidence it stores:
    the status, WBA digits (at T and T/2), MEGNO (and its history at T/2), FTLE, SALI,
    frequency diffusion and resonance. Works on archives missing some of it (old ones, or
    [indicators] which = []): absent evidence has no vote.

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
    votes = evidence_votes(ds, th)
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
    if V.resonance_distance in ds:
        regime[only_regular & on_resonance(ds, th)] = Regime.RESONANT
    if V.frequency in ds:
        labels = [str(x) for x in ds["fundamental_name"].values]
        shape_cols = [i for i, name in enumerate(labels) if name.startswith("shape")]
        n_shape = np.sum(np.isfinite(ds[V.frequency].values[..., shape_cols]), axis=-1)
        regime[only_regular & (n_shape <= 1)] = Regime.PERIODIC
    only_chaotic = (chaotic > 0) & (regular == 0)
    regime[only_chaotic] = Regime.CHAOTIC
    confidence[only_chaotic] = share_chaos[only_chaotic]
    mixed = (chaotic > 0) & (regular > 0)
    early = np.zeros(shape, dtype=bool)
    if V.birkhoff_digits_half in ds:
        early |= ds[V.birkhoff_digits_half].values >= th.digits_regular
    if V.megno_history in ds:
        times = ds["history_time"].values
        at_half = int(np.argmin(np.abs(times - times[-1] / 2)))
        early |= ds[V.megno_history].values[..., at_half] <= th.megno_regular
    late = np.zeros(shape, dtype=bool)
    for name in LYAPUNOV:
        if name in votes:
            late |= votes[name] == -1
    sticky = mixed & early & late
    regime[sticky] = Regime.STICKY
    confidence[sticky] = share_chaos[sticky]

    regime[status == Status.INACCESSIBLE] = Regime.INACCESSIBLE
    regime[status == Status.COLLISION] = Regime.COLLISION
    failed = ~np.isin(status, [Status.OK, Status.EVENT, Status.INACCESSIBLE, Status.COLLISION])
    regime[failed] = Regime.UNDETERMINED
    confidence[(status == Status.INACCESSIBLE) | (status == Status.COLLISION)] = 1.0
    confidence[failed | (regime == Regime.UNDETERMINED)] = 0.0
    return regime, confidence


def on_resonance(ds, th: Thresholds) -> np.ndarray:
    """Cells whose nearest resonance of order <= resonance_order holds to resonance_width:
    |m . nu| / (|m| max|nu|) at most that. Tighter than the detuning of small oscillations
    about the rotating triangle from its 1:2 epicyclic degeneracy (~1e-6 at delta = 0.5),
    looser than what NAFF resolves on a locked orbit at T = 2000."""
    order = ds[V.resonance_order].values
    with np.errstate(invalid="ignore"):
        return (ds[V.resonance_distance].values <= th.resonance_width) & (order > 0) & \
            (order <= th.resonance_order)


def stored_table(ds) -> dict | None:
    """The [tori] table of the config stored in an archive, if any."""
    import tomllib
    try:
        return tomllib.loads(ds.attrs.get("config", "")).get("tori")
    except tomllib.TOMLDecodeError:
        return None


def summary(ds, regime=None) -> list[str]:
    """Counts of each regime, and for a one-axis grid where it changes from regular to
    chaotic."""
    regime = ds[V.regime].values if regime is None else regime
    total = regime.size
    counts = [(r, int(np.sum(regime == r))) for r in Regime]
    lines = ["regimes: " + ", ".join(f"{r.name.lower()} {n} ({100 * n / total:.0f}%)"
                                     for r, n in counts if n)]
    axes = [d for d in ds[V.status].dims]
    if len(axes) == 1:
        x = ds[axes[0]].values
        regular = np.isin(regime, REGULAR)
        chaotic = np.isin(regime, IRREGULAR)
        labelled = np.flatnonzero(regular | chaotic)
        for a, b in zip(labelled[:-1], labelled[1:]):
            if regular[a] != regular[b]:
                lines.append(f"{axes[0]}: {Regime(regime[a]).name.lower()} at {x[a]:g} -> "
                             f"{Regime(regime[b]).name.lower()} at {x[b]:g}")
    return lines
