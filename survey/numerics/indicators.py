"""Chaos indicators of one orbit, from one integration of the orbit with its tangent vectors.

- FTLE: ln(|w(t)|/|w(0)|)/t with periodic renormalisation and accumulated logs (Benettin
  et al. 1980), for each of several seeded deviation vectors.
- MEGNO: Y(t) = (2/t) int_0^t s (w'.w)/|w|^2 ds and <Y>(t) = (1/t) int_0^t Y ds (Cincotta &
  Simo 2000), accumulated by the driver from L = ln|w| at step ends, integrated by parts (no
  extra ODE components): <Y> -> 2 on tori, -> 0 at isochronous stable periodic orbits,
  ~ lambda t / 2 in chaos.
- FLI: max_{s <= t} ln(|w(s)|/|w(0)|) (Froeschle, Lega & Gonczi 1997).
- SALI = min(|w1^ + w2^|, |w1^ - w2^|) and GALI_2 = |w1^ ^ w2^| of two deviation vectors
  (Skokos 2001; Skokos, Bountis & Antonopoulos 2007): -> 0 exponentially in chaos, stay
  finite on tori.

Single runs of chaotic orbits are not reproducible digit for digit, so each indicator comes
with a spread over an ensemble: the deviation vectors of the orbit, and optionally orbits
started a tiny distance away.
"""
from __future__ import annotations

import functools
import hashlib
import math
import statistics
from typing import NamedTuple, Sequence

import numpy as np

from ..catalog import defaults
from ..catalog.indicators import IndicatorOptions
from ..catalog.status import Status
from ..catalog.variables import ENSEMBLE_QUANTILES, ENSEMBLE_STATISTICS, history_times
from ..machine.jit import leaf
from ..machine.linalg import orthonormal
from ..machine.portable import vnorm
from ..physics.system import System, rhs
from .events import Crossings
from .dop853 import norm_block
from .driver import EVAL, EVENTS, FINE
from .integrate import Outcome, integrate_batch


class ChaosIndicators(NamedTuple):
    status: Status
    t: float
    ftle: float            # the cell's orbit: ln(|w(t)|/|w0|)/t, mean over its vectors
    ftle_ensemble: np.ndarray   # ENSEMBLE_STATISTICS over the orbit and its perturbed starts
    ensemble_orbits: int   # orbits in the ensemble statistics
    megno: float           # <Y>(t) of the cell's orbit
    megno_ensemble: np.ndarray
    megno_slope: float     # least-squares d<Y>/dt over the history's second half (~lambda/2)
    fli: float             # first deviation vector
    sali: float            # nan with one deviation vector
    gali2: float
    history_time: np.ndarray
    ftle_history: np.ndarray     # ensemble mean of the nominal orbit's vectors
    megno_history: np.ndarray
    fli_history: np.ndarray
    sali_history: np.ndarray
    ftle_wba: float        # weighted Birkhoff average of the growth rate, first vector
    energy_error: float    # max |E/E0 - 1| over the history times and the end
    angular_momentum_error: float   # max |J - J0| / max(|J0|, 1)
    n_steps: int
    n_rhs: int
    crossings: Crossings
    n_crossings: int
    outcome: Outcome


def _constraints(system: System, y0, project_flow: bool) -> np.ndarray:
    """Orthonormal rows spanning what a deviation vector must not contain: centre-of-mass
    shifts (sum m_i dq_i) and boosts (sum dp_i) where the potential is translation
    invariant, and optionally the flow f(y0) and grad H."""
    key = (tuple(system.masses), system.dim, system.translation_invariant)
    if not project_flow:
        return _momentum_constraints(*key)
    n = system.n
    f = np.zeros(n)
    rhs(0.0, np.ascontiguousarray(y0, dtype=float), f, system.model, 0)
    rows = _momentum_rows(*key) + [f, np.concatenate([-f[n // 2:], f[:n // 2]])]
    return orthonormal(np.array(rows).reshape(-1, n))


def _momentum_rows(masses: tuple, d: int, invariant: bool) -> list:
    """The centre-of-mass shifts and boosts, one of each per axis where the potential is
    translation invariant."""
    N = len(masses)
    rows = []
    for c in range(d if invariant else 0):
        shift = np.zeros((2, N, d))
        shift[0, :, c] = masses
        boost = np.zeros((2, N, d))
        boost[1, :, c] = 1.0
        rows += [shift.ravel(), boost.ravel()]
    return rows


@functools.lru_cache(maxsize=256)
def _momentum_constraints(masses: tuple, d: int, invariant: bool) -> np.ndarray:
    """`_constraints` without the flow: the masses' and the dimension's alone, so built once
    (rebuilt for each of a cell's 33 deviation draws, it was most of a short map's cost)."""
    C = orthonormal(np.array(_momentum_rows(masses, d, invariant)).reshape(
        -1, 2 * len(masses) * d))
    C.flags.writeable = False
    return C


def deviation_vectors(system: System, y0, count: int, seed: int,
                      project_flow: bool = False, stream: int = 0) -> np.ndarray:
    """`count` unit deviation vectors (count, n), random from (seed, the start y0, stream)
    alone -- the same orbit gets the same vectors in any grid, chunk or worker -- with zero
    total position and momentum deviation (such a vector never grows and reports every
    orbit regular)."""
    rng = np.random.default_rng([seed, *state_key(y0), stream])
    w = rng.normal(size=(count, system.n))
    C = _constraints(system, y0, project_flow)
    _unconstrained_units(w, C, np.empty(len(C)))
    return w


@leaf
def _unconstrained_units(w, C, coefficients):
    """Each row of w without its components along the orthonormal rows of C, then scaled to
    unit norm, in place: every coefficient from the row as drawn, each row of C then
    subtracted in turn, the norm summed in order (`norm_block`) -- numpy's operations in
    numpy's order, so the same bits. One call: a cell's 33 draws were each a few numpy
    calls of microseconds (44% of a short map's task)."""
    for r in range(w.shape[0]):
        row = w[r]
        for k in range(C.shape[0]):
            s = 0.0
            for i in range(row.size):
                s += row[i] * C[k, i]
            coefficients[k] = s
        for k in range(C.shape[0]):
            for i in range(row.size):
                row[i] = row[i] - coefficients[k] * C[k, i]
        size = norm_block(row[::1], np.int64(0), row.size)  # its other calls' types
        for i in range(row.size):
            row[i] = row[i] / size


def state_key(y0) -> list[int]:
    """Four 32-bit words of the SHA-256 of a state's float64 bits: a seed that follows the
    orbit, not its place in a grid."""
    digest = hashlib.sha256(np.ascontiguousarray(y0, dtype="<f8").tobytes()).digest()
    return [int.from_bytes(digest[4 * i:4 * i + 4], "little") for i in range(4)]


def _sali(w1, w2):
    """SALI and GALI_2 of two deviation vectors. For unit a, b: |a + b|^2 |a - b|^2 =
    4 (1 - (a.b)^2), so GALI_2 = |a ^ b| = |a + b| |a - b| / 2 -- from the components,
    without the cancellation of sqrt(1 - c^2) that stops GALI_2 near 1e-8."""
    a = w1 / vnorm(w1)[..., None]
    b = w2 / vnorm(w2)[..., None]
    plus, minus = vnorm(a + b), vnorm(a - b)
    return np.minimum(plus, minus), 0.5 * plus * minus


def ensemble_statistics(values) -> np.ndarray:
    """ENSEMBLE_STATISTICS of one indicator over an ensemble of orbits: the mean and sample
    standard deviation with exact sums (statistics: the same on any CPU; the deviation NaN
    for one orbit) and the 5/50/95% quantiles (linear interpolation between order
    statistics). All NaN if any value is not finite."""
    if not values or not all(map(math.isfinite, values)):
        return np.full(len(ENSEMBLE_STATISTICS), np.nan)
    sd = statistics.stdev(values) if len(values) >= 2 else math.nan
    return np.array([statistics.fmean(values), sd,
                     *np.quantile(np.array(values), ENSEMBLE_QUANTILES)])


def _ls_slope(t, v):
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 2:
        return np.nan
    t0 = t - math.fsum(t) / t.size
    return math.fsum(t0 * (v - math.fsum(v) / v.size)) / math.fsum(t0 * t0)


def conservation_errors(system: System, y0, states):
    """max |E/E0 - 1| and max |J - J0| / max(|J0|, 1) over states (k, n)."""
    E0, J0 = system.energy(y0), system.angular_momentum(y0)
    dJ = np.reshape(system.angular_momentum(states) - J0, (len(states), -1))
    return (float(np.max(np.abs(system.energy(states) / E0 - 1))),
            float(np.max(vnorm(dJ)) / max(float(vnorm(np.reshape(J0, -1))), 1.0)))


NUDGE_STREAM = 2 ** 32 - 1      # the random stream of the nominal start's nudge


class Ensemble(NamedTuple):
    """The orbits a cell's indicators come from, as jobs of one batch (`integrate_batch`):
    first the nominal orbit -- once per deviation vector, each copy giving the bits the
    others give, or once with all of them when they take part in the error control --
    then the orbits started `perturbation_size` away, each with its own vector."""

    starts: np.ndarray        # (J, n)
    tangents: np.ndarray      # (J, n_tan, n)
    record: np.ndarray        # (J,) what each records (driver.EVENTS | EVAL | FINE)
    nominal: int              # the first `nominal` jobs integrate the nominal orbit


def ensemble(system: System, y0, options: IndicatorOptions,
             control_tangents: bool = False) -> Ensemble:
    """The jobs of a cell: deviation vectors and perturbed starts seeded by (seed, y0), so
    a cell's jobs are the same in any grid and whatever the chunk it travels in; with a
    `nudge`, the nominal start itself moved by that (relative, seeded) first. The first
    nominal job records crossings, samples and the fine samples; the other nominal copies
    samples (the histories of their vectors); the perturbed orbits nothing."""
    o = options
    y0 = np.asarray(y0, dtype=float)
    if o.nudge:         # the nominal orbit itself elsewhere by a few last bits
        y0 = y0 + o.nudge * float(vnorm(y0)) * deviation_vectors(
            system, y0, 1, o.seed, stream=NUDGE_STREAM)[0]
    w0 = deviation_vectors(system, y0, o.deviations, o.seed, o.project_flow)
    per_job = o.deviations if control_tangents else 1
    nominal = 1 if control_tangents else o.deviations
    starts = [y0] * nominal
    tangents = [w0] if control_tangents else [w[None] for w in w0]
    record = [EVENTS | EVAL | FINE] + [EVAL] * (nominal - 1)
    distance = o.perturbation_size * float(vnorm(y0))
    for j in range(o.perturbations):
        xi = deviation_vectors(system, y0, 1, o.seed, stream=1 + j)[0]
        yp = y0 + distance * xi
        starts.append(yp)
        tangents.append(deviation_vectors(system, yp, per_job, o.seed, o.project_flow,
                                          stream=1 + j))
        record.append(0)
    return Ensemble(np.array(starts), np.array(tangents), np.array(record, dtype=np.int64),
                    nominal)


def combine(system: System, y0, t_final: float, options: IndicatorOptions, jobs: Ensemble,
            outcomes: Sequence[Outcome]) -> ChaosIndicators:
    """A cell's indicators, ensemble spreads and histories from its jobs' outcomes. The
    perturbed orbits count only if the nominal one finished, and one that ran out of its
    time budget makes the cell's status TIME_LIMIT."""
    o = options
    y0 = np.asarray(y0, dtype=float)
    n = system.n
    history = history_times(t_final, o.history_points)
    out = outcomes[0]
    nominal = outcomes[:jobs.nominal]
    status = out.status
    k = o.deviations
    reached = ~np.isnan(history) & (history <= out.t)
    th = np.where(reached, history, np.nan)
    if jobs.nominal == 1:
        tang = out.samples[:, n:n * (1 + k)].reshape(-1, k, n)
        log_growth, tangents = out.log_growth, out.tangents
        sample_log = out.sample_log_growth
    else:
        tang = np.stack([r.samples[:, n:2 * n] for r in nominal], axis=1)
        log_growth = np.array([r.log_growth[0] for r in nominal])
        tangents = np.array([r.tangents[0] for r in nominal])
        sample_log = np.stack([r.sample_log_growth[:, 0] for r in nominal], axis=1)
    z = out.sample_megno
    ftle_h = sample_log / th[:, None]
    megno_h = z[:, 1] / th

    # one value per orbit: the cell's orbit (its vectors agree to ~1e-4: they share it),
    # then each perturbed start that finished
    ftle = statistics.fmean(log_growth / out.t) if out.t > 0 else np.nan
    megno = out.megno_sums[1] / out.t if out.t > 0 else np.nan
    ftles, megnos = [ftle], [megno]
    for res in outcomes[jobs.nominal:] if status.finished else ():
        if res.status == Status.TIME_LIMIT:
            status = Status.TIME_LIMIT
            break
        if res.ok and res.t > 0:
            ftles.append(res.log_growth[0] / res.t)
            megnos.append(res.megno_sums[1] / res.t)

    if k >= 2:
        sali_h, _ = _sali(tang[:, 0], tang[:, 1])
        sali, gali2 = _sali(tangents[0], tangents[1])
    else:
        sali_h = np.full(history.size, np.nan)
        sali = gali2 = np.nan
    fli_h = np.fmax.accumulate(np.where(reached, out.sample_log_growth[:, 0], -np.inf))
    fli_h[~reached] = np.nan

    dE, dJ = conservation_errors(system, y0, np.concatenate([out.samples[reached, :n], [out.y]]))
    half = history >= 0.5 * t_final
    return ChaosIndicators(
        status=status, t=out.t,
        ftle=ftle, ftle_ensemble=ensemble_statistics(ftles), ensemble_orbits=len(ftles),
        megno=megno, megno_ensemble=ensemble_statistics(megnos),
        megno_slope=_ls_slope(th[half], megno_h[half]),
        fli=float(out.fli[0]), sali=float(sali), gali2=float(gali2), ftle_wba=out.ftle_wba,
        history_time=history, ftle_history=sum(ftle_h.T) / ftle_h.shape[1],
        megno_history=megno_h, fli_history=fli_h, sali_history=sali_h,
        energy_error=dE, angular_momentum_error=dJ,
        n_steps=out.n_steps, n_rhs=out.n_rhs, crossings=out.crossings,
        n_crossings=out.n_crossings, outcome=out)


def batch_options(t_final: float, options: IndicatorOptions, *, events=(), rtol=defaults.RTOL,
                  atol=defaults.ATOL, max_steps=defaults.MAX_STEPS, max_events=100_000,
                  time_limit=0.0, control_tangents=False, t_fine=None,
                  reuse_samples=False, approach=False, thin=0.0) -> dict:
    """integrate_batch's options for the jobs of cells' ensembles."""
    return dict(megno=True, t_eval=history_times(t_final, options.history_points),
                sample_tangents=True, events=events, max_events=max_events, t_fine=t_fine,
                reuse_samples=reuse_samples, approach=approach, thin=thin,
                rtol=rtol, atol=atol, max_steps=max_steps,
                renorm_interval=options.renorm_interval, control_tangents=control_tangents,
                time_limit=time_limit)


def chaos_indicators(system: System, y0, t_final: float, options=IndicatorOptions(), *,
                     lanes=None, **run) -> ChaosIndicators:
    """Integrate y0 to t_final with `options.deviations` tangent vectors (MEGNO of the first,
    summed by the driver at step ends), plus `options.perturbations` nearby orbits, as
    lanes of one batch, and return the indicators, their ensemble spread and convergence
    histories, and any section crossings. run: batch_options' keywords (events, rtol, atol,
    max_steps, max_events, control_tangents, t_fine: the times the nominal orbit is sampled
    at for the torus analysis, Outcome.fine; time_limit: wall-clock seconds per orbit, 0 for
    none -- one that runs out makes the status TIME_LIMIT)."""
    jobs = ensemble(system, y0, options, run.get("control_tangents", False))
    outcomes = integrate_batch(system, jobs.starts, t_final, tangents=jobs.tangents,
                               record=jobs.record, lanes=lanes,
                               **batch_options(t_final, options, **run))
    return combine(system, y0, t_final, options, jobs, outcomes)
