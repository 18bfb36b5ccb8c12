"""The step-end indicators (numerics.tangents.STEP_END), each against a computation that
does not use the driver's accumulators: finite differences of two orbits, densely sampled
tangent vectors integrated without renormalisation, quadratures of their definitions. An
entry without a check here fails the battery."""
import math

import numpy as np
import pytest

from survey.numerics.indicators import deviation_vectors
from survey.numerics.integrate import Outcome, integrate
from survey.numerics.tangents import STEP_END, layout, offsets, width
from survey.physics.families import initial_state
from survey.physics.system import rhs

T = 30.0      # ln|w| of both vectors then well below its largest value (the FLI)
SAMPLES = 15001


@pytest.fixture(scope="module")
def runs(paper_system):
    """A chaotic orbit ('sides') with two tangent vectors: renormalised every 0.5 (the
    accumulators' path), and not at all with dense samples of the vectors (the reference)."""
    y0 = initial_state(paper_system, "sides")
    w0 = deviation_vectors(paper_system, y0, 2, seed=0)
    t = np.linspace(0.0, T, SAMPLES)
    common = dict(megno=True, t_eval=t, sample_tangents=True, rtol=1e-12, atol=1e-12)
    renormalised = integrate(paper_system, y0, T, tangents=w0, renorm_interval=0.5, **common)
    plain = integrate(paper_system, y0, T, tangents=w0, renorm_interval=1e9, **common)
    n = paper_system.n
    w = plain.samples[:, n:].reshape(SAMPLES, 2, n)
    L = np.log(np.linalg.norm(w, axis=2))           # |w0| = 1
    return paper_system, y0, w0, t, renormalised, plain, L


def check_log_growth(runs):
    system, y0, w0, t, out, plain, L = runs
    assert out.log_growth == pytest.approx(L[-1], abs=1e-7)
    assert out.sample_log_growth == pytest.approx(L, abs=1e-7)
    # and the tangent vector against two orbits a small distance apart, over a short span
    eps, short = 1e-7, 3.0
    a = integrate(system, y0, short, rtol=1e-13, atol=1e-13)
    b = integrate(system, y0 + eps * w0[0], short, rtol=1e-13, atol=1e-13)
    lin = integrate(system, y0, short, tangents=w0[:1], renorm_interval=0.1,
                    rtol=1e-13, atol=1e-13)
    assert lin.log_growth[0] == pytest.approx(math.log(np.linalg.norm(b.y - a.y) / eps),
                                              abs=1e-5)


def check_fli(runs):
    *_, out, plain, L = runs
    top = L.max(axis=0)
    assert np.all(top - L[-1] > 0.5)                # the span tells the max from the end
    assert np.all(out.fli <= top + 1e-7)      # the max over step ends, below the dense one
    assert out.fli == pytest.approx(top, abs=2e-3)


def check_ftle_wba(runs):
    *_, t, out, plain, L = runs
    s = 0.5 * (t[1:] + t[:-1]) / T
    g = np.exp(-1.0 / (s * (1.0 - s)))
    wba = np.sum(g * np.diff(L[:, 0])) / np.sum(g * np.diff(t))
    assert out.ftle_wba == pytest.approx(wba, rel=1e-3)


def check_megno_sums(runs):
    """<Y>(t) = (1/t) int_0^t Y with Y(t) = (2/t) int_0^t u (w'.w)/|w|^2 du, the rate from
    the right-hand side at the sampled states -- never from L at step ends."""
    from scipy.integrate import cumulative_trapezoid
    system, y0, w0, t, out, plain, L = runs
    n = system.n
    system_model = system.model
    rate = np.empty(t.size)
    for k, state in enumerate(plain.samples):
        state = np.ascontiguousarray(state[:2 * n])
        dy = np.zeros(2 * n)
        rhs(t[k], state, dy, system_model, 1)
        rate[k] = state[n:] @ dy[n:] / (state[n:] @ state[n:])
    Y = np.divide(2 * cumulative_trapezoid(t * rate, t, initial=0.0), t,
                  out=np.zeros_like(t), where=t > 0)
    mean_Y = cumulative_trapezoid(Y, t, initial=0.0)
    assert out.megno_sums[1] / out.t == pytest.approx(mean_Y[-1] / T, rel=1e-3)
    late = t > T / 4
    assert out.sample_megno[late, 1] / t[late] == pytest.approx(mean_Y[late] / t[late],
                                                                rel=1e-3)
    assert out.sample_megno[late, 0] / t[late] == pytest.approx(Y[late] / 2, rel=1e-2,
                                                                abs=1e-2)


CHECKS = {"log_growth": check_log_growth, "fli": check_fli, "ftle_wba": check_ftle_wba,
          "megno_sums": check_megno_sums}


def test_every_step_end_indicator_has_a_check():
    assert [e.name for e in STEP_END] == list(CHECKS)


@pytest.mark.parametrize("entry", STEP_END, ids=lambda e: e.name)
def test_step_end_indicator(entry, runs):
    assert entry.name in Outcome._fields
    assert not entry.sample_name or entry.sample_name in Outcome._fields
    CHECKS[entry.name](runs)


@pytest.mark.parametrize("n_tan", [0, 1, 3])
def test_compiled_offsets_follow_the_layout(n_tan):
    at, sampled = layout(n_tan), layout(n_tan, sampled=True)
    assert offsets(n_tan) == (at["log_growth"].start, at["fli"].start, at["ftle_wba"].start,
                              at["megno_sums"].start, sampled["megno_sums"].start)
    assert sampled["log_growth"].start == 0
    assert width(n_tan) == 2 * n_tan + 4 and width(n_tan, True) == n_tan + 2
