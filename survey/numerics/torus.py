"""Is an orbit on a KAM torus? Two lines of evidence computed from the orbit sampled at a
fixed interval (the `fine` output of the integrator), in the worker beside the variational
indicators:

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

`survey.analysis.classify` then decides each cell's regime from all the evidence an archive
stores.

Like the integrator, the analysis gives the same bits on every machine: its sums run in
compiled loops in a fixed order, its exponentials and trigonometric functions are
survey.machine.portable's (numpy's SIMD versions, BLAS's products and libm's complex
exponential round by the CPU). Only the FFT that seeds NAFF's lines comes from numpy
(pocketfft, compiled for the baseline CPU), and only the index of its largest bin is used.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from ..catalog import defaults
from ..catalog.regimes import Thresholds
from ..catalog.variables import OBSERVABLES, fundamental_names, shape_dof
from ..machine import portable
from ..physics.jacobi import reduced
from ..machine.jit import helper, kernel, lanes

TWO_PI = 2.0 * math.pi


def birkhoff_average(h):
    """Weighted Birkhoff average of samples h taken at equal intervals, midpoint rule with
    g(s) = exp(-1/(s(1-s))) (its integral is then spectrally accurate)."""
    return _weighted_mean(h, _birkhoff_weights(h.size))


def _once_per_length(make):
    """make(n), computed once per length n and read-only: every cell of a task analyses
    orbit halves (and quarters) of the same lengths."""
    @lru_cache(maxsize=8)
    def cached(n: int) -> np.ndarray:
        w = make(n)
        w.flags.writeable = False
        return w
    return cached


@kernel
def _weights(n):
    """g at the n midpoints."""
    g = np.empty(n)
    for i in range(n):
        s = (i + 0.5) / n
        g[i] = portable.exp(-1.0 / (s * (1.0 - s)))
    return g


_birkhoff_weights = _once_per_length(_weights)


@kernel
def _weighted_mean(h, g):
    total, weight = 0.0, 0.0
    for i in range(h.size):
        total += h[i] * g[i]
        weight += g[i]
    return total / weight


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
    return min(-log10(diff / scale), cap)


def log10(x: float) -> float:
    """log10 from the portable natural logarithm (libm's log10 differs by the CPU)."""
    return portable.log(x) / math.log(10.0)


def observable(name: str, system, states: np.ndarray) -> np.ndarray:
    if name == "perimeter":
        states = np.ascontiguousarray(states, dtype=np.float64)
        out = np.empty(states.shape[0])
        _pair_distances(states, system.n_bodies, system.dim, out)
        return out
    if name == "inertia":
        return system.moment_of_inertia(states)
    if name in ("x", "y", "z"):
        return system.centre_of_mass(states)[..., "xyz".index(name)]
    raise ValueError(f"unknown observable {name!r}; choose from {', '.join(OBSERVABLES)}")


@kernel
def _pair_distances(y, N, d, out):
    """The sum of the N(N-1)/2 distances between bodies of states y (M, n), pairs in
    np.triu_indices order, each distance and the total summed from 0.0 (NumPy's order)."""
    for r in range(y.shape[0]):
        total = 0.0
        for i in range(N):
            for j in range(i + 1, N):
                s = 0.0
                for c in range(d):
                    x = y[r, i * d + c] - y[r, j * d + c]
                    s += x * x
                total += math.sqrt(s)
        out[r] = total


def _rms(x):
    return float(np.sqrt(np.mean(x * x)))


def _complex(re, im):
    """re + i im (im may be a number), in one compiled pass: numpy's strided stores into
    .real and .imag cost 10x more."""
    re = np.ascontiguousarray(re, dtype=np.float64)
    return _pack(re, np.ascontiguousarray(np.broadcast_to(im, re.shape), dtype=np.float64),
                 1.0, np.empty(re.shape, dtype=np.complex128))


@kernel
def _pack(re, im, w, out):
    """out = (re + i im) w, w a number or an array (the products numpy's complex times real
    makes, (re w, im w))."""
    for i in range(out.size):
        wi = w if isinstance(w, float) else w[i]
        out[i] = complex(re[i] * wi, im[i] * wi)
    return out


def _unit(angle):
    """exp(i angle) from the portable cosine and sine."""
    s, c = portable.vsincos(angle)
    return _complex(c, s)


def _centred(x, p):
    """x - <x> + i c p with c making the phase portrait round (NAFF then sees one line per
    oscillation, not a +- pair); None if x does not move (a stationary shape)."""
    dx, dp = x - x.mean(), p - p.mean()
    if _rms(dx) <= 1e-9 * max(_rms(x), 1e-300):
        return None
    return _complex(dx, (_rms(dx) / _rms(dp)) * dp if _rms(dp) > 0 else 0.0)


@kernel
def unwrap(p):
    """np.unwrap(p) of a 1-D angle, the same bits in one pass (numpy's makes seven arrays:
    4x slower): a jump d = p[i] - p[i-1] of at least pi is corrected by
    (d + pi) mod 2 pi - pi - d (the floored mod, as numpy's; a jump of exactly +pi stays
    +pi), the corrections summed in order."""
    up = np.empty(p.size)
    if p.size == 0:
        return up
    up[0] = p[0]
    total = 0.0
    for i in range(1, p.size):
        d = p[i] - p[i - 1]
        if abs(d) >= math.pi or d != d:
            wrapped = (d - (-math.pi)) % TWO_PI + (-math.pi)     # Python's floored mod
            if wrapped == -math.pi and d > 0.0:
                wrapped = math.pi
            total += wrapped - d
        up[i] = p[i] + total
    return up


def signals(system, states: np.ndarray):
    """Complex shape signals (those that move) and the rotation signal (or None); in an
    external field, every Cartesian coordinate with its momentum."""
    if not system.translation_invariant:     # a field: every coordinate and its momentum
        q, p = system.split(states)
        q, p = q.reshape(len(states), -1), p.reshape(len(states), -1)
        shape = [_centred(np.ascontiguousarray(q[:, k]), np.ascontiguousarray(p[:, k]))
                 for k in range(q.shape[1])]
        return [z for z in shape if z is not None], None
    if system.n_bodies == 3 and system.dim == 2:
        r = reduced(system, states)
        phi = unwrap(r.phi)
        shape = [_centred(r.sigma, r.p_sigma), _centred(r.eta, r.p_eta),
                 _centred(phi, r.p_phi) if np.ptp(phi) < 2 * np.pi else _unit(phi)]
        theta = unwrap(r.theta)
        # a shape that does not turn has no rotation line (NAFF on a constant would find a
        # spurious one near 0 whose change between halves looks like diffusion)
        turns = np.ptp(theta) > 1e-9
        return [z for z in shape if z is not None], _unit(r.theta) if turns else None
    values = (observable(name, system, states) for name in ("perimeter", "inertia"))
    shape = [_centred(h, np.gradient(h)) for h in values]
    return [z for z in shape if z is not None], None


def naff(z: np.ndarray, count: int):
    """Laskar's NAFF: the `count` strongest lines of a signal z_n sampled at n = 0..N-1, as
    frequencies in cycles per sample and complex amplitudes, strongest first. Each line is
    the maximum of |sum_n z_n w_n exp(-2 pi i f n)| (w: Hann window squared), found from
    the FFT peak by Newton steps on the exact derivatives, then subtracted from the signal.

    Written here rather than taken from nafflib: nafflib compiles its numba kernels in every
    process with no disk cache (in every dask worker and survey, more than the whole
    analysis of a short survey), and its sums round by the CPU; the tests check this one
    against it."""
    N = np.size(z)
    w, wsum = _window_of(N), _window_sum(N)
    z = np.ascontiguousarray(z, dtype=complex)
    # the windowed signal, lines taken out of it; (re, im) pairs for the compiled loops
    zw = _pack(z.real, z.imag, w, np.empty(N, dtype=complex))
    v = zw.view(np.float64)
    freqs, amps = np.zeros(count), np.zeros(count, dtype=complex)
    spectrum = np.fft.fft(zw)
    for line in range(count):
        k = _peak(spectrum)
        f = k / N if k <= N // 2 else k / N - 1.0
        freqs[line], amps[line] = _line(v, w, wsum, f)
        if line + 1 < count:
            if N > 4 * SPECTRUM_BINS:
                _take_from_spectrum(spectrum, freqs[line], amps[line])
            else:
                spectrum = np.fft.fft(zw)
    return freqs, amps


@kernel
def _peak(S):
    """The first index of the largest |S_k| (compared as re^2 + im^2: no square roots, and
    the same on every CPU, where numpy's SIMD abs rounds by the CPU)."""
    best, k = -1.0, 0
    for i in range(S.size):
        a = S[i].real * S[i].real + S[i].imag * S[i].imag
        if a > best:
            best, k = a, i
    return k


# A found line is taken out of the FFT that seeds the next one at the 2 SPECTRUM_BINS + 1
# bins around it, by the window's exact transform: beyond them its leakage is below 4e-11
# of its peak (the squared Hann window's falls as bins^-5), far under the 1e-6 at which
# a line counts (frequency_basis) -- an FFT per line cost 4x more than NAFF's sums.
SPECTRUM_BINS = 128


@kernel
def _take_from_spectrum(S, f, a):
    """S_k -= a sum_n w_n exp(2 pi i (f - k/N) n) at the bins k around f N (S: the FFT of
    the windowed signal, w the squared Hann window): the line a exp(2 pi i f n) taken out.
    With theta_n = 2 pi (n + 1/2) / N, w_n = 3/2 - 2 cos theta_n + cos(2 theta_n) / 2, so
    the sum is five Dirichlet kernels G(u) = sum_n exp(2 pi i u n / N) = exp(i pi u (N-1) /
    N) sin(pi u) / sin(pi u / N) at u = f N - k + m, m = -2..2."""
    N = S.size
    x = f * N
    k0 = int(np.floor(x + 0.5))
    K = SPECTRUM_BINS
    G = np.empty(2 * K + 5, dtype=np.complex128)          # G at u = x - (k0 + j - K - 2)
    for j in range(2 * K + 5):
        u = x - (k0 + j - K - 2)
        den = portable.cis(math.pi * u / N)[1]
        r = portable.cis(math.pi * u)[1] / den if den != 0.0 else float(N)
        c, s = portable.cis(math.pi * u * (N - 1) / N)
        G[j] = complex(r * c, r * s)
    c, s = portable.cis(math.pi / N)
    c1 = complex(c, s)
    c, s = portable.cis(2.0 * math.pi / N)
    c2 = complex(c, s)
    for j in range(2, 2 * K + 3):                 # bin k = k0 + j - K - 2: its u is G[j]'s;
        D = 1.5 * G[j] - (c1 * G[j - 1] + c1.conjugate() * G[j + 1]) \
            + 0.25 * (c2 * G[j - 2] + c2.conjugate() * G[j + 2])       # u + m is G[j - m]
        S[(k0 + j - K - 2) % N] -= a * D


@kernel
def _window(N):
    """(1 - cos(2 pi (n + 1/2) / N))^2, n = 0..N-1: the Hann window squared."""
    w = np.empty(N)
    for n in range(N):
        c = 1.0 - portable.cis(TWO_PI * (n + 0.5) / N)[0]
        w[n] = c * c
    return w


_window_of = _once_per_length(_window)


@lru_cache(maxsize=8)
def _window_sum(N: int) -> float:
    return math.fsum(_window_of(N))     # correctly rounded: the same on every machine


# The sums over a signal's samples run as BLOCK interleaved recurrences (lane j takes the
# samples n = j mod BLOCK), so that they compile to SIMD loops (a single phase recurrence
# is a serial chain: 4.5x slower); each lane's phase advances by exp(-+ 2 pi i f BLOCK)
# per block, and the lanes' partial sums are added in a fixed order at the end.
BLOCK = 16


@kernel
def _phases(f, sign, E):
    """E[:BLOCK] + i E[BLOCK:2 BLOCK] = exp(sign 2 pi i f j), j < BLOCK, and E[2 BLOCK:] the
    step exp(sign 2 pi i f BLOCK), from the portable cosine and sine."""
    for j in range(BLOCK):
        c, s = portable.cis(TWO_PI * f * j)
        E[j], E[BLOCK + j] = c, sign * s
    c, s = portable.cis(TWO_PI * f * BLOCK)
    E[2 * BLOCK], E[2 * BLOCK + 1] = c, sign * s


@lanes
def _block_sums(v, N, E, acc):
    """acc[q BLOCK + j] += lane j's part of the q-th sum (q = 0..5: re and im of sum_n
    z_n w_n e_n n^p, p = 0, 1, 2), over the samples of v (windowed signal, (re, im) pairs);
    the whole blocks, then the rest."""
    cr, ci = E[2 * BLOCK], E[2 * BLOCK + 1]
    blocks = N // BLOCK
    for m in range(blocks):
        for j in range(BLOCK):
            _add_sample(v, m * BLOCK + j, j, E, acc, cr, ci)
    for j in range(N - blocks * BLOCK):
        _add_sample(v, blocks * BLOCK + j, j, E, acc, cr, ci)


@helper
def _add_sample(v, n, j, E, acc, cr, ci):
    ar, ai = v[2 * n], v[2 * n + 1]
    er, ei = E[j], E[BLOCK + j]
    tr, ti = ar * er - ai * ei, ar * ei + ai * er
    x = float(n)
    acc[j] += tr
    acc[BLOCK + j] += ti
    acc[2 * BLOCK + j] += tr * x
    acc[3 * BLOCK + j] += ti * x
    acc[4 * BLOCK + j] += tr * x * x
    acc[5 * BLOCK + j] += ti * x * x
    E[j], E[BLOCK + j] = er * cr - ei * ci, er * ci + ei * cr


@lanes
def _block_subtract(v, w, N, E, ar, ai):
    """v_n -= w_n (ar + i ai) e_n: a line taken out of the windowed signal."""
    cr, ci = E[2 * BLOCK], E[2 * BLOCK + 1]
    blocks = N // BLOCK
    for m in range(blocks):
        for j in range(BLOCK):
            _take_sample(v, w, m * BLOCK + j, j, E, ar, ai, cr, ci)
    for j in range(N - blocks * BLOCK):
        _take_sample(v, w, blocks * BLOCK + j, j, E, ar, ai, cr, ci)


@helper
def _take_sample(v, w, n, j, E, ar, ai, cr, ci):
    er, ei = E[j], E[BLOCK + j]
    v[2 * n] -= w[n] * (ar * er - ai * ei)
    v[2 * n + 1] -= w[n] * (ar * ei + ai * er)
    E[j], E[BLOCK + j] = er * cr - ei * ci, er * ci + ei * cr


@kernel
def _sums(v, f, E, acc):
    """sum_n z_n w_n e_n n^p, p = 0, 1, 2, with e_n = exp(-2 pi i f n): the window-weighted
    transform at f and its first two derivatives' sums, (re, im) each."""
    _phases(f, -1.0, E)
    acc[:] = 0.0
    _block_sums(v, v.size // 2, E, acc)
    out = np.zeros(6)
    for q in range(6):
        for j in range(BLOCK):
            out[q] += acc[q * BLOCK + j]
    return out


@kernel
def _line(v, w, wsum, f):
    """Refine the line near frequency f (cycles per sample) to the maximum of |F(f)|^2 by
    Newton steps, then subtract it from the windowed signal v (in place): (f, its
    amplitude)."""
    N = w.size
    E = np.empty(2 * BLOCK + 2)
    acc = np.empty(6 * BLOCK)
    for _ in range(30):
        s = _sums(v, f, E, acc)
        F0r, F0i = s[0], s[1]
        # F1 = -2 pi i S1, F2 = -4 pi^2 S2
        F1r, F1i = TWO_PI * s[3], -TWO_PI * s[2]
        F2r, F2i = -TWO_PI * TWO_PI * s[4], -TWO_PI * TWO_PI * s[5]
        grad = 2.0 * (F0r * F1r + F0i * F1i)                 # d|F|^2/df
        curv = 2.0 * ((F1r * F1r + F1i * F1i) + (F0r * F2r + F0i * F2i))
        if curv < 0.0:
            step = -grad / curv
        else:
            step = 0.25 / N if grad > 0.0 else (-0.25 / N if grad < 0.0 else 0.0)
        step = min(max(step, -0.5 / N), 0.5 / N)
        f += step
        if abs(step) < 1e-15:
            break
    s = _sums(v, f, E, acc)
    ar, ai = s[0] / wsum, s[1] / wsum
    _phases(f, 1.0, E)
    _block_subtract(v, w, N, E, ar, ai)
    return f, complex(ar, ai)


def spectral_lines(z: np.ndarray, dt: float, count: int):
    """The `count` strongest lines of z sampled every dt: frequencies in cycles per unit
    time and amplitudes relative to the strongest."""
    freq, amp = naff(z, count)
    amp = np.sqrt(amp.real * amp.real + amp.imag * amp.imag)
    return freq / dt, amp / amp.max() if amp.max() > 0 else amp


@lru_cache(maxsize=16)
def integer_vectors(dim: int, order: int) -> np.ndarray:
    """Integer vectors m with 1 <= |m|_1 <= order, first nonzero entry positive, by order
    and then lexicographically: built order by order (resonance_count of them), not
    filtered from the (2 order + 1)^dim vectors of the cube."""
    def norm(prefix, left, budget, signed):
        if left == 0:
            if budget == 0:
                out.append(prefix)
            return
        for v in range(-budget if signed else 0, budget + 1):
            norm(prefix + (v,), left - 1, budget - abs(v), signed or v != 0)
    out: list[tuple] = []
    for n in range(1, order + 1):
        norm((), dim, n, False)
    return np.array(out, dtype=np.int64).reshape(-1, dim)


def resonance_count(dim: int, order: int) -> int:
    """How many vectors integer_vectors(dim, order) holds: half the nonzero lattice points
    of the cross-polytope |m|_1 <= order, sum_k 2^k C(dim, k) C(order, k) / 2."""
    return sum(2 ** k * math.comb(dim, k) * math.comb(order, k)
               for k in range(1, min(dim, order) + 1)) // 2


def frequency_basis(lines, max_dim: int, order: int, tol: float,
                    resolution: float) -> list[float]:
    """Greedy basis of fundamental frequencies from pooled lines (frequency, relative
    amplitude), strongest first. A line closer than `resolution` (the Fourier resolution of
    the samples, 1/duration) to one already taken is the same line seen in another signal;
    a line within tol (relative) of an integer combination of order <= `order` of the basis
    so far is a harmonic or a combination, not a new frequency. Magnitudes: a line and its
    mirror (the same oscillation seen turning the other way in another signal) are one."""
    basis: list[float] = []
    taken: list[float] = []
    scale = max((abs(f) for f, _ in lines), default=1.0)
    for f, a in sorted(((abs(f), a) for f, a in lines), key=lambda x: -x[1]):
        if a < 1e-6 or abs(f) < 1e-6 * scale:       # noise, or the mean of an angle's drift
            continue
        if any(abs(f - g) < resolution for g in taken):
            continue
        taken.append(f)
        if basis:
            combos = _combinations(integer_vectors(len(basis), order), np.array(basis))
            if np.min(np.abs(np.concatenate([combos, -combos]) - f)) <= tol * scale:
                continue
        basis.append(f)
        if len(basis) == max_dim:
            break
    return basis


def _combinations(vectors: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """m . nu for each row m of `vectors`, summed in order (a matrix product would sum as
    the CPU's BLAS does)."""
    return (vectors * nu).sum(axis=1)


class Frequencies(NamedTuple):
    frequency: np.ndarray       # (fundamental,) cycles per unit time, NaN-padded
    change: np.ndarray          # (fundamental,) nu(second half) - nu(first half)
    diffusion: float            # log10 max |nu(2) - nu(1)| / max |nu|
    resonance: np.ndarray       # (fundamental,) integer vector of the nearest resonance
    resonance_order: int        # its |m|_1 (-1: none searched)
    resonance_distance: float   # |m . nu| / (|m| max|nu|)
    moving: int                 # shape signals that move (-1: not analysed)


def frequency_analysis(system, states: np.ndarray, dt: float, lines: int = defaults.NAFF_LINES,
                       order: int = Thresholds.resonance_order, tol: float = 1e-6) -> Frequencies:
    """Fundamental frequencies on the two halves of an orbit sampled every dt, their
    diffusion, and the nearest resonance of order <= `order` among the shape frequencies.
    Frequencies are magnitudes (NAFF's sign only says which way a signal's phase portrait
    turns, and flips within a family); the rotation, a reconstruction phase of the reduced
    flow rather than one of its frequencies, takes part in the diffusion but in no
    resonance."""
    field = not system.translation_invariant
    names = fundamental_names(system.n_bodies, system.dim, field)
    k = len(names)
    nan = Frequencies(np.full(k, np.nan), np.full(k, np.nan), np.nan, np.zeros(k, np.int64),
                      -1, np.nan, -1)
    half = states.shape[0] // 2
    if half < 64:
        return nan
    pooled, rotation, moving = [], [], 0
    for part in (slice(0, half), slice(half, 2 * half)):
        shape, rot = signals(system, states[part])
        moving = max(moving, len(shape))
        found = []
        for z in shape:
            f, a = spectral_lines(z, dt, lines)
            found += list(zip(f, a))
        pooled.append(found)
        rotation.append(spectral_lines(rot, dt, 1)[0][0] if rot is not None else np.nan)
    basis = frequency_basis(pooled[0], shape_dof(system.n_bodies, system.dim, field), order, tol,
                            1.0 / (half * dt))
    second = np.array([abs(f) for f, _ in pooled[1]]) if pooled[1] else np.zeros(0)
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
    freq[cols] = 0.5 * (np.abs(nu1) + np.abs(nu2))
    change[cols] = np.abs(nu2) - np.abs(nu1)
    known = np.isfinite(freq)
    if not known.any():
        return nan._replace(moving=moving)
    scale = np.max(np.abs(freq[known]))
    diffusion = log10(max(float(np.max(np.abs(change[known]))) / scale, 1e-16))
    m, order_found, distance = np.zeros(k, np.int64), -1, np.nan
    shape = known & np.array([name.startswith("shape") for name in names])
    if shape.sum() >= 2:
        nu = freq[shape]
        vectors = integer_vectors(int(shape.sum()), order)
        dist = np.abs(_combinations(vectors, nu)) / (
            np.sqrt(np.sum(vectors * vectors, axis=1)) * np.max(nu))
        # the lowest order among the vectors equally near (multiples of one vector, or
        # vectors on a frequency that is ~0): a tie is not left to rounding
        best = int(np.flatnonzero(dist <= dist.min() * (1.0 + 1e-9) + 1e-15)[0])
        m[shape] = vectors[best]
        order_found, distance = int(np.abs(vectors[best]).sum()), float(dist[best])
    return Frequencies(freq, change, diffusion, m, order_found, distance, moving)


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
    ended = np.isnan(fine[:, 0])
    done = fine[~ended] if ended.any() else fine       # a complete orbit: no copy
    cap = -log10(max(energy_error, 16 * np.finfo(float).eps)) \
        if np.isfinite(energy_error) else np.nan
    values = [observable(o, system, done) for o in observables]
    at_t = np.array([birkhoff_digits(h, cap) for h in values])
    at_half = np.array([birkhoff_digits(h[:h.size // 2], cap) for h in values])
    return TorusEvidence(at_t, at_half, float(np.mean(at_t)), float(np.mean(at_half)),
                         frequency_analysis(system, done, dt, lines, order))
