"""Is an orbit on a KAM torus, in a resonance, periodic, sticky or chaotic -- and how sure
are we?

Two lines of evidence are computed here from the orbit sampled at a fixed interval (the
`fine` output of the integrator), besides the variational indicators:

- Weighted Birkhoff averages (Das, Saiki, Sander & Yorke, Nonlinearity 30 (2017); Sander &
  Meiss, Physica D 411 (2020); Duignan & Meiss, Physica D 449 (2023) for flows). With the
  weight g(s) = exp(-1/(s(1-s))) the average of a smooth observable converges faster than
  any power of T on a quasi-periodic orbit and like T^-1/2 on a chaotic one. The digits
  dig = -log10 |WB(h; first half) - WB(h; second half)| / rms(h) are computed for each
  observable at T and at T/2 (a torus gains digits with time, chaos does not), capped at
  the precision the integration itself reached (its relative energy error). Observables are
  symmetric in the bodies: the sum of pair distances (the perimeter for three bodies) and
  the moment of inertia. Individual side lengths converge slowly even on tori (the shape
  drifts slowly among permutations), and the kinetic energy's average is pinned by the
  virial theorem on every bounded orbit: neither separates anything.
- Frequency analysis (Laskar, Physica D 67 (1993) 257) with NAFF: the leading
  lines of complex shape signals (three bodies in the plane: sigma + i c p_sigma, eta + i c
  p_eta, phi + i c p_phi; otherwise the perimeter and the moment of inertia) on each half
  of the orbit, a basis of fundamental shape frequencies built from them (a line that is a
  low-order integer combination of the basis so far adds nothing), the rotation frequency
  of theta, the diffusion log10 |nu(2) - nu(1)| / |nu|, and the nearest resonance
  m . nu = 0.

`classify` then decides each cell's regime from all the evidence stored in an archive, so
it can be run again on any archive with other thresholds and no integration.
"""
from __future__ import annotations

import enum
import itertools
import json
import math
from dataclasses import asdict, dataclass, field, fields
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from .status import Status

OBSERVABLES = {
    "perimeter": "sum of all pair distances (the perimeter for three bodies)",
    "inertia": "moment of inertia about the centre of mass",
}


# ---------------------------------------------------------------- weighted Birkhoff averages

def birkhoff_average(h: np.ndarray) -> np.ndarray:
    """Weighted Birkhoff average along the last axis of samples taken at equal intervals,
    midpoint rule with g(s) = exp(-1/(s(1-s))) (its integral is then spectrally accurate)."""
    n = h.shape[-1]
    s = (np.arange(n) + 0.5) / n
    g = np.exp(-1.0 / (s * (1.0 - s)))
    return h @ (g / g.sum())


def birkhoff_digits(h: np.ndarray, cap: float) -> float:
    """-log10 of the relative difference between the weighted averages over the two halves
    of h, at most `cap` (an exact match, or one below the integration's precision)."""
    half = h.size // 2
    if half < 8:
        return np.nan
    scale = math.sqrt(float(np.mean(h * h)))
    diff = abs(birkhoff_average(h[:half]) - birkhoff_average(h[half:2 * half]))
    if scale == 0 or diff == 0:
        return cap
    return min(-math.log10(diff / scale), cap)


def observable(name: str, system, states: np.ndarray) -> np.ndarray:
    q, _ = system.split(states)
    if name == "perimeter":
        N = system.n_bodies
        i, j = np.triu_indices(N, 1)
        return np.linalg.norm(q[..., i, :] - q[..., j, :], axis=-1).sum(axis=-1)
    if name == "inertia":
        return system.moment_of_inertia(states)
    raise ValueError(f"unknown observable {name!r}; choose from {', '.join(OBSERVABLES)}")


# ---------------------------------------------------------------- frequency analysis

def shape_dof(n_bodies: int, dim: int) -> int:
    """Degrees of freedom of the shape: N d minus translations and rotations (3 for three
    bodies in the plane or in space)."""
    return n_bodies * dim - dim - dim * (dim - 1) // 2


def fundamental_names(n_bodies: int, dim: int) -> list[str]:
    """The frequencies stored per cell: a basis of shape frequencies, and for three bodies
    in the plane the rotation frequency of theta."""
    return [f"shape_{k + 1}" for k in range(shape_dof(n_bodies, dim))] + \
        (["rotation"] if (n_bodies, dim) == (3, 2) else [])


def _rms(x):
    return float(np.sqrt(np.mean(x * x)))


def _centred(x, p):
    """x - <x> + i c p with c making the phase portrait round (NAFF then sees one line per
    oscillation, not a +- pair); None if x does not move (a stationary shape)."""
    dx, dp = x - x.mean(), p - p.mean()
    if _rms(dx) <= 1e-9 * max(_rms(x), 1e-300):
        return None
    return dx + 1j * (_rms(dx) / _rms(dp)) * dp if _rms(dp) > 0 else dx + 0j


def signals(system, states: np.ndarray):
    """Complex shape signals (those that move) and the rotation signal (or None)."""
    if system.n_bodies == 3 and system.dim == 2:
        from .coordinates import reduced
        r = reduced(system, states)
        phi = np.unwrap(r.phi)
        shape = [_centred(r.sigma, r.p_sigma), _centred(r.eta, r.p_eta),
                 _centred(phi, r.p_phi) if np.ptp(phi) < 2 * np.pi else np.exp(1j * phi)]
        return [z for z in shape if z is not None], np.exp(1j * r.theta)
    shape = [_centred(observable(name, system, states), np.gradient(
        observable(name, system, states))) for name in OBSERVABLES]
    return [z for z in shape if z is not None], None


def naff(z: np.ndarray, count: int):
    """Laskar's NAFF: the `count` strongest lines of a signal z_n sampled at n = 0..N-1, as
    frequencies in cycles per sample and complex amplitudes, strongest first. Each line is
    the maximum of |sum_n z_n w_n exp(-2 pi i f n)| (w: Hann window squared), found from
    the FFT peak by Newton steps on the exact derivatives, then subtracted from the signal.

    Written here rather than taken from nafflib: nafflib compiles its numba kernels in every
    process with no disk cache (about 1 s per dask worker and survey, more than the whole
    analysis of a short survey); the tests check this one against it."""
    z = np.array(z, dtype=complex)
    N = z.size
    n = np.arange(N, dtype=float)
    w = (1.0 - np.cos(2.0 * np.pi * (n + 0.5) / N)) ** 2
    wsum = w.sum()
    freqs, amps = np.zeros(count), np.zeros(count, dtype=complex)
    for line in range(count):
        zw = z * w
        moments = np.stack([zw, zw * n, zw * n * n])
        k = int(np.argmax(np.abs(np.fft.fft(zw))))
        f = k / N if k <= N // 2 else k / N - 1.0
        for _ in range(30):
            F, F1, F2 = moments @ _phasors(-f, N)
            F1, F2 = -2j * np.pi * F1, -4 * np.pi ** 2 * F2
            grad = 2.0 * (np.conj(F) * F1).real            # d|F|^2/df
            curv = 2.0 * (abs(F1) ** 2 + (np.conj(F) * F2).real)
            step = -grad / curv if curv < 0 else 0.25 * np.sign(grad) / N
            step = float(np.clip(step, -0.5 / N, 0.5 / N))
            f += step
            if abs(step) < 1e-15:
                break
        e = _phasors(f, N)
        amp = (zw @ np.conj(e)) / wsum
        freqs[line], amps[line] = f, amp
        z -= amp * e
    return freqs, amps


def _phasors(f: float, N: int) -> np.ndarray:
    """exp(2 pi i f n), n = 0..N-1, as powers of exp(2 pi i f): a fifth of the cost of N
    complex exponentials; the phase drifts by ~N eps, far below the window's resolution."""
    r = np.full(N, np.exp(2j * np.pi * f))
    r[0] = 1.0
    return np.cumprod(r)


def spectral_lines(z: np.ndarray, dt: float, count: int):
    """The `count` strongest lines of z sampled every dt: frequencies in cycles per unit
    time and amplitudes relative to the strongest."""
    freq, amp = naff(z, count)
    amp = np.abs(amp)
    return freq / dt, amp / amp.max() if amp.max() > 0 else amp


@lru_cache(maxsize=16)
def integer_vectors(dim: int, order: int) -> np.ndarray:
    """Integer vectors m with 1 <= |m|_1 <= order, first nonzero entry positive, by order."""
    out = [m for m in itertools.product(range(-order, order + 1), repeat=dim)
           if 0 < sum(map(abs, m)) <= order and next(x for x in m if x) > 0]
    return np.array(sorted(out, key=lambda m: sum(map(abs, m))), dtype=np.int64).reshape(-1, dim)


def frequency_basis(lines, max_dim: int, order: int, tol: float,
                    resolution: float) -> list[float]:
    """Greedy basis of fundamental frequencies from pooled lines (frequency, relative
    amplitude), strongest first. A line closer than `resolution` (the Fourier resolution of
    the samples, 1/duration) to one already taken is the same line seen in another signal;
    a line within tol (relative) of an integer combination of order <= `order` of the basis
    so far is a harmonic or a combination, not a new frequency."""
    basis: list[float] = []
    taken: list[float] = []
    scale = max((abs(f) for f, _ in lines), default=1.0)
    for f, a in sorted(lines, key=lambda x: -x[1]):
        if a < 1e-6 or abs(f) < 1e-6 * scale:       # noise, or the mean of an angle's drift
            continue
        if any(abs(f - g) < resolution for g in taken):
            continue
        taken.append(f)
        if basis:
            combos = integer_vectors(len(basis), order) @ np.array(basis)
            if np.min(np.abs(np.concatenate([combos, -combos]) - f)) <= tol * scale:
                continue
        basis.append(f)
        if len(basis) == max_dim:
            break
    return basis


class Frequencies(NamedTuple):
    frequency: np.ndarray       # (fundamental,) cycles per unit time, NaN-padded
    change: np.ndarray          # (fundamental,) nu(second half) - nu(first half)
    diffusion: float            # log10 max |nu(2) - nu(1)| / max |nu|
    resonance: np.ndarray       # (fundamental,) integer vector of the nearest resonance
    resonance_order: int        # its |m|_1 (-1: none searched)
    resonance_distance: float   # |m . nu| / (|m| max|nu|)


def frequency_analysis(system, states: np.ndarray, dt: float, lines: int = 5,
                       order: int = 6, tol: float = 1e-6) -> Frequencies:
    """Fundamental frequencies on the two halves of an orbit sampled every dt, their
    diffusion, and the nearest resonance of order <= `order`."""
    names = fundamental_names(system.n_bodies, system.dim)
    k = len(names)
    nan = Frequencies(np.full(k, np.nan), np.full(k, np.nan), np.nan, np.zeros(k, np.int64),
                      -1, np.nan)
    half = states.shape[0] // 2
    if half < 64:
        return nan
    pooled, rotation = [], []
    for part in (slice(0, half), slice(half, 2 * half)):
        shape, rot = signals(system, states[part])
        found = []
        for z in shape:
            f, a = spectral_lines(z, dt, lines)
            found += list(zip(f, a))
        pooled.append(found)
        rotation.append(spectral_lines(rot, dt, 1)[0][0] if rot is not None else np.nan)
    basis = frequency_basis(pooled[0], shape_dof(system.n_bodies, system.dim), order, tol,
                            1.0 / (half * dt))
    second = np.array([f for f, _ in pooled[1]]) if pooled[1] else np.zeros(0)
    nu1, nu2 = [], []
    for b in basis:   # each frequency of the first half, matched to the second half's lines
        nu1.append(b)
        nu2.append(second[np.argmin(np.abs(second - b))] if second.size else np.nan)
    if "rotation" in names:
        nu1.append(rotation[0])
        nu2.append(rotation[1])
    nu1, nu2 = np.array(nu1, float), np.array(nu2, float)
    freq, change = np.full(k, np.nan), np.full(k, np.nan)
    n_shape = len(basis)
    cols = list(range(n_shape)) + ([k - 1] if "rotation" in names else [])
    freq[cols] = 0.5 * (nu1 + nu2)
    change[cols] = nu2 - nu1
    known = np.isfinite(freq)
    if not known.any():
        return nan
    scale = np.max(np.abs(freq[known]))
    diffusion = math.log10(max(float(np.max(np.abs(change[known]))) / scale, 1e-16))
    m, order_found, distance = np.zeros(k, np.int64), -1, np.nan
    if known.sum() >= 2:
        vectors = integer_vectors(int(known.sum()), order)
        dist = np.abs(vectors @ freq[known]) / (np.linalg.norm(vectors, axis=1) * scale)
        best = int(np.argmin(dist))
        m[known] = vectors[best]
        order_found, distance = int(np.abs(vectors[best]).sum()), float(dist[best])
    return Frequencies(freq, change, diffusion, m, order_found, distance)


# ---------------------------------------------------------------- per cell

class TorusEvidence(NamedTuple):
    digits_each: np.ndarray        # (observable,) at T
    digits_each_half: np.ndarray   # (observable,) at T/2
    digits: float                  # combined: mean over observables, at T
    digits_half: float             # at T/2
    frequencies: Frequencies


def analyse(system, fine: np.ndarray, dt: float, energy_error: float, observables,
            lines: int, order: int) -> TorusEvidence:
    """The torus evidence of one orbit sampled every dt (fine: states (k, n), NaN past the
    end reached)."""
    done = fine[~np.isnan(fine[:, 0])]
    cap = -math.log10(max(energy_error, 16 * np.finfo(float).eps)) \
        if np.isfinite(energy_error) else np.nan
    values = [observable(o, system, done) for o in observables]
    at_t = np.array([birkhoff_digits(h, cap) for h in values])
    at_half = np.array([birkhoff_digits(h[:h.size // 2], cap) for h in values])
    return TorusEvidence(at_t, at_half, float(np.mean(at_t)), float(np.mean(at_half)),
                         frequency_analysis(system, done, dt, lines, order))


# ---------------------------------------------------------------- the regime of a cell

class Regime(enum.IntEnum):
    """The regime of a cell (stored as the CF flag variable `regime`)."""

    TORUS = 0
    RESONANT = 1
    PERIODIC = 2
    STICKY = 3
    CHAOTIC = 4
    COLLISION = 5
    INACCESSIBLE = 6
    UNDETERMINED = 7

    @property
    def meaning(self) -> str:
        return REGIME_MEANINGS[self]


REGIME_MEANINGS = {
    Regime.TORUS: "quasi-periodic: every line of evidence regular",
    Regime.RESONANT: "regular, with frequencies on a low-order resonance m . nu = 0 (to "
                     "resonance_width)",
    Regime.PERIODIC: "regular with at most one shape frequency (a relative equilibrium or a "
                     "periodic orbit of the shape)",
    Regime.STICKY: "regular in the first half, chaotic by T: an orbit that clung to tori",
    Regime.CHAOTIC: "every line of evidence chaotic",
    Regime.COLLISION: "the integration stopped at a near collision",
    Regime.INACCESSIBLE: "no start at this grid point",
    Regime.UNDETERMINED: "the lines of evidence disagree, or the run failed",
}


@dataclass(frozen=True)
class Thresholds:
    """Where each line of evidence votes regular or chaotic (between the two: no vote).
    Chosen from this system's histograms at T = 2000 (the paper's equilateral family and
    'sides' orbit; see the README), in line with the literature's values."""

    digits_regular: float = field(default=5.0, metadata={"doc": (
        "Birkhoff digits (mean over observables) at or above which the WBA votes regular; "
        "at T = 2000 the paper's tori reach 6.5-10.7, its chaotic orbits 2.2-2.7")})
    digits_chaotic: float = field(default=3.5, metadata={"doc": (
        "Birkhoff digits at or below which the WBA votes chaotic")})
    megno_regular: float = field(default=2.25, metadata={"doc": (
        "<Y> at or below which MEGNO votes regular (-> 2 on tori, 0 at isochronous periodic "
        "orbits; 1.8-2.0 on this system's tori at T = 2000)")})
    megno_chaotic: float = field(default=3.0, metadata={"doc": (
        "<Y> at or above which MEGNO votes chaotic (~ lambda T / 2; 3.2-20 in the weak "
        "chaos at the onset)")})
    ftle_regular: float = field(default=1.5, metadata={"doc": (
        "FTLE, in units of ln(T)/T (a torus's FTLE), at or below which it votes regular "
        "(0.7-0.9 on this system's tori)")})
    ftle_chaotic: float = field(default=3.0, metadata={"doc": (
        "FTLE in units of ln(T)/T at or above which it votes chaotic")})
    sali_regular: float = field(default=1e-4, metadata={"doc": (
        "SALI at or above which it votes regular (it fluctuates about 1e-2..1 on tori)")})
    sali_chaotic: float = field(default=1e-8, metadata={"doc": (
        "SALI at or below which it votes chaotic (Skokos et al.'s usual cut)")})
    diffusion_regular: float = field(default=-4.0, metadata={"doc": (
        "frequency diffusion log10 |dnu|/|nu| at or below which it votes regular (tori "
        "-8.4..-4.5 at T = 2000)")})
    diffusion_chaotic: float = field(default=-3.0, metadata={"doc": (
        "frequency diffusion at or above which it votes chaotic (chaos -2.4..0)")})
    resonance_order: int = field(default=6, metadata={"doc": (
        "highest order |m|_1 of the resonances m . nu = 0 searched")})
    resonance_width: float = field(default=1e-7, metadata={"doc": (
        "|m . nu| / (|m| max|nu|) at or below which a regular orbit is resonant")})

    def describe(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_table(cls, table: dict | None) -> "Thresholds":
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in (table or {}).items() if k in names})


# each line of evidence: its name, the archive variable, whether larger values are more
# regular (+1) or more chaotic (-1), and the prefix of its thresholds
EVIDENCE = (("wba", "birkhoff_digits", +1, "digits"), ("megno", "megno", -1, "megno"),
            ("ftle", "ftle", -1, "ftle"), ("sali", "sali", +1, "sali"),
            ("diffusion", "frequency_diffusion", -1, "diffusion"))


def evidence_votes(ds, th: Thresholds) -> dict[str, np.ndarray]:
    """Each line of evidence present in the archive as votes: +1 regular, -1 chaotic, 0 no
    vote (between the thresholds), NaN where the evidence is missing. The FTLE is measured
    in units of ln(T)/T, a torus's FTLE at the time reached."""
    votes = {}
    for key, name, sign, prefix in EVIDENCE:
        if name not in ds:
            continue
        x = ds[name].values.astype(float)
        if name == "ftle":
            t_end = ds["t_end"].values
            with np.errstate(invalid="ignore", divide="ignore"):
                x = x / (np.log(t_end) / t_end)
        regular, chaotic = (sign * getattr(th, f"{prefix}_{side}")
                            for side in ("regular", "chaotic"))
        with np.errstate(invalid="ignore"):
            vote = np.where(sign * x >= regular, 1.0, np.where(sign * x <= chaotic, -1.0, 0.0))
        votes[key] = np.where(np.isfinite(x), vote, np.nan)
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
    shape = ds["status"].shape
    status = ds["status"].values
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
    if "resonance_distance" in ds:
        regime[only_regular & on_resonance(ds, th)] = Regime.RESONANT
    if "frequency" in ds:
        labels = [str(x) for x in ds["fundamental_name"].values]
        shape_cols = [i for i, name in enumerate(labels) if name.startswith("shape")]
        n_shape = np.sum(np.isfinite(ds["frequency"].values[..., shape_cols]), axis=-1)
        regime[only_regular & (n_shape <= 1)] = Regime.PERIODIC
    only_chaotic = (chaotic > 0) & (regular == 0)
    regime[only_chaotic] = Regime.CHAOTIC
    confidence[only_chaotic] = share_chaos[only_chaotic]
    mixed = (chaotic > 0) & (regular > 0)
    early = np.zeros(shape, dtype=bool)
    if "birkhoff_digits_half" in ds:
        early |= ds["birkhoff_digits_half"].values >= th.digits_regular
    if "megno_history" in ds:
        times = ds["history_time"].values
        at_half = int(np.argmin(np.abs(times - times[-1] / 2)))
        early |= ds["megno_history"].values[..., at_half] <= th.megno_regular
    late = np.zeros(shape, dtype=bool)
    for name in ("megno", "ftle", "sali"):
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
    order = ds["resonance_order"].values
    with np.errstate(invalid="ignore"):
        return (ds["resonance_distance"].values <= th.resonance_width) & (order > 0) & \
            (order <= th.resonance_order)


def stored_table(ds) -> dict | None:
    """The [tori] table of the config stored in an archive, if any."""
    import tomllib
    try:
        return tomllib.loads(ds.attrs.get("config", "")).get("tori")
    except tomllib.TOMLDecodeError:
        return None


# ---------------------------------------------------------------- what to print first

def summary(ds, regime=None) -> list[str]:
    """Counts of each regime, and for a one-axis grid where it changes from regular to
    chaotic."""
    regime = ds["regime"].values if regime is None else regime
    total = regime.size
    counts = [(r, int(np.sum(regime == r))) for r in Regime]
    lines = ["regimes: " + ", ".join(f"{r.name.lower()} {n} ({100 * n / total:.0f}%)"
                                     for r, n in counts if n)]
    axes = [d for d in ds["status"].dims]
    if len(axes) == 1:
        x = ds[axes[0]].values
        regular = np.isin(regime, [Regime.TORUS, Regime.RESONANT, Regime.PERIODIC])
        chaotic = np.isin(regime, [Regime.CHAOTIC, Regime.STICKY])
        labelled = np.flatnonzero(regular | chaotic)
        for a, b in zip(labelled[:-1], labelled[1:]):
            if regular[a] != regular[b]:
                lines.append(f"{axes[0]}: {Regime(regime[a]).name.lower()} at {x[a]:g} -> "
                             f"{Regime(regime[b]).name.lower()} at {x[b]:g}")
    return lines
