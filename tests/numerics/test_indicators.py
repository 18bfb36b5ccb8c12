"""Chaos indicators against theory: tori, chaos, periodic orbits, scaling laws."""
import math

import numpy as np
import pytest

from survey.catalog.indicators import IndicatorOptions
from survey.numerics.indicators import chaos_indicators, deviation_vectors
from survey.numerics.integrate import integrate
from survey.physics.families import initial_state
from survey.physics.system import System


@pytest.fixture(scope="module")
def regular(paper_system):
    y0 = initial_state(paper_system, "equilateral", delta=3.0)
    return chaos_indicators(paper_system, y0, 5000.0, IndicatorOptions(deviations=2))


@pytest.fixture(scope="module")
def chaotic(paper_system):
    y0 = initial_state(paper_system, "sides")
    return chaos_indicators(paper_system, y0, 2000.0, IndicatorOptions(deviations=2))


def test_regular_orbit_ftle_decays_like_log_t_over_t_and_megno_tends_to_2(regular):
    """On a torus |w| grows linearly: ln|w| ~ ln t, so FTLE ~ ln(t)/t; <Y> -> 2."""
    t, ftle = regular.history_time, regular.ftle_history
    late = t >= t[-1] / 4
    slope = np.polyfit(np.log(t[late]), ftle[late] * t[late], 1)[0]
    assert 0.7 < slope < 1.3                       # d ln|w| / d ln t = 1: linear growth
    assert np.all((ftle * t / np.log(t))[late] < 3)   # FTLE <= 3 ln(t)/t
    assert abs(regular.megno - 2.0) < 0.15
    assert np.all(np.diff(regular.megno_history[len(t) // 4:]) > -0.02)   # approaching 2
    assert abs(regular.megno_slope) < 1e-4
    assert regular.sali > 0.1 and regular.gali2 > 0.1


def test_chaotic_orbit_megno_grows_linearly_at_half_the_exponent(chaotic):
    """<Y>(t) ~ lambda t / 2 in chaos: its least-squares slope matches FTLE/2."""
    assert chaotic.ftle > 0.1
    assert chaotic.megno > 50
    assert chaotic.megno_slope == pytest.approx(chaotic.ftle / 2, rel=0.35)
    assert chaotic.sali < 1e-8 and chaotic.gali2 < 1e-6
    assert chaotic.fli > 100
    # the honest error bar: the orbit and its 16 perturbed starts, 1e-9 apart, disagree at
    # the 10% level at T = 2000
    mean, sd, q05, q50, q95 = chaotic.ftle_ensemble
    assert chaotic.ensemble_orbits == 17
    assert 0.005 < sd < 0.5 * mean and q05 < q50 < q95 and q05 < mean < q95
    assert q95 - q05 > 2 * sd            # 17 orbits: the 5-95% range spans about 3.3 sd


def test_ensemble_statistics_are_mean_sd_and_quantiles():
    from survey.numerics.indicators import ensemble_statistics
    np.testing.assert_allclose(ensemble_statistics([4.0, 1.0, 3.0, 2.0]),
                               [2.5, math.sqrt(5 / 3), 1.15, 2.5, 3.85], rtol=1e-15)
    one = ensemble_statistics([0.3])
    assert one[0] == one[2] == one[4] == 0.3 and math.isnan(one[1])
    assert np.isnan(ensemble_statistics([1.0, math.inf])).all()


@pytest.mark.parametrize("exponent,megno", [(2.0, 0.0), (3.0, 2.0)])
def test_rotating_equilateral_periodic_orbit(exponent, megno):
    """The uniformly rotating triangle is a stable periodic orbit: no exponential growth.
    For U = P^2/2 (homogeneous of degree 2) every nearby motion rotates at the same rate
    omega = 3 whatever the size, so deviations stay bounded and <Y> -> 0, the value of an
    isochronous stable periodic orbit. For U = P^3/3 the rotation rate depends on the size:
    deviations along the family grow linearly (shear) and <Y> -> 2, as on a torus."""
    system = System.create(exponent=exponent)
    y0 = initial_state(system, "equilateral", delta=0.0)
    ci = chaos_indicators(system, y0, 5000.0, IndicatorOptions(deviations=2))
    assert ci.ftle < 1.5 * math.log(5000.0) / 5000.0    # linear growth at most: a torus's
    assert ci.megno == pytest.approx(megno, abs=0.05)
    assert ci.fli < 1.5 * math.log(5000.0)


def test_homogeneous_scaling_rescales_time_and_lyapunov_exponent():
    """U = P^k/k: q -> s q, p -> s^(k/2) p maps orbits to orbits with t -> tau t,
    tau = s^(1 - k/2); tangent vectors map the same way, so the FTLE scales by 1/tau."""
    k, s = 4.0, 1.7
    tau = s ** (1 - k / 2)
    system = System.create(exponent=k)
    y0 = initial_state(system, "sides")
    D = np.concatenate([np.full(6, s), np.full(6, s ** (k / 2))])
    w0 = deviation_vectors(system, y0, 1, seed=3)[0]
    T = 40.0
    a = integrate(system, y0, T, tangents=w0, rtol=1e-13, atol=1e-13)
    b = integrate(system, D * y0, tau * T, tangents=D * w0, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(b.y, D * a.y, rtol=1e-7, atol=1e-7 * np.abs(D * a.y).max())
    np.testing.assert_allclose(b.deviations[0], D * a.deviations[0], rtol=1e-6,
                               atol=1e-6 * np.abs(D * a.deviations[0]).max())
    lam_a, lam_b = a.log_growth[0] / T, b.log_growth[0] / (tau * T)
    assert a.log_growth[0] > 3                      # chaotic: the exponent is measurable
    # |D w| / |w| lies between s and s^(k/2): the only finite-time difference
    assert abs(lam_b * tau - lam_a) <= math.log(s ** (k / 2) / s) / T


def test_deviation_vectors_are_reproducible_and_carry_no_centre_of_mass_motion(paper_system):
    """Seeded by (seed, the start's bits, stream): the same start gives the same vectors,
    a start one ulp away, another seed or another stream others."""
    y0 = initial_state(paper_system, "sides")
    w = deviation_vectors(paper_system, y0, 3, seed=7)
    np.testing.assert_array_equal(w, deviation_vectors(paper_system, y0.copy(), 3, seed=7))
    nudged = y0.copy()
    nudged[0] = np.nextafter(nudged[0], np.inf)
    for other in (deviation_vectors(paper_system, nudged, 3, seed=7),
                  deviation_vectors(paper_system, y0, 3, seed=8),
                  deviation_vectors(paper_system, y0, 3, seed=7, stream=1)):
        assert not np.allclose(w, other)
    q, p = paper_system.split(w)
    np.testing.assert_allclose(np.einsum("kid,i->kd", q, paper_system.masses), 0, atol=1e-14)
    np.testing.assert_allclose(p.sum(axis=1), 0, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, rtol=1e-14)
    wp = deviation_vectors(paper_system, y0, 3, seed=7, project_flow=True)
    f = np.zeros(12)
    from survey.physics.system import rhs
    system_model = paper_system.model
    rhs(0.0, y0, f, system_model, 0)
    gradH = np.concatenate([-f[6:], f[:6]])
    np.testing.assert_allclose(wp @ f, 0, atol=1e-12)
    np.testing.assert_allclose(wp @ gradH, 0, atol=1e-12)


def test_deviation_vectors_keep_the_bits_of_numpys_projection():
    """The compiled projection (`_unconstrained_units`) gives the bits numpy's operations
    give in numpy's order -- every coefficient from the drawn row, each constraint then
    subtracted, the norm summed in order -- for other masses, 3-D, four bodies, the flow
    projected or not, one vector or sixteen: an archive's deviation vectors (and so its
    chaos indicators) do not depend on how they are computed."""
    from survey.machine.portable import vdot, vnorm
    from survey.numerics.indicators import _constraints, state_key
    from survey.physics.terms import make_potential

    rng = np.random.default_rng(5)
    for masses, d in (((1.0, 1.0, 1.0), 2), ((1.0, 2.0, 0.5), 2), ((1.0, 1.5, 0.7, 2.0), 3)):
        system = System(np.array(masses), d, (make_potential("perimetric_power"),))
        for trial in range(20):
            y0 = rng.standard_normal(system.n) * 10 ** rng.uniform(-3, 3)
            for project_flow in (False, True):
                for count in (1, 16):
                    drawn = np.random.default_rng([trial, *state_key(y0), 2]).normal(
                        size=(count, system.n))
                    C = _constraints(system, y0, project_flow)
                    coefficients = vdot(drawn[:, None, :], C[None])
                    for k in range(len(C)):
                        drawn -= coefficients[:, k:k + 1] * C[k]
                    want = drawn / vnorm(drawn)[:, None]
                    got = deviation_vectors(system, y0, count, trial, project_flow, 2)
                    np.testing.assert_array_equal(got.view(np.int64), want.view(np.int64))


def test_histories_and_status_for_an_orbit_that_stops(paper_system):
    """A collision ends the histories with NaN past the end, never raises."""
    system = System.create(exponent=-1.0)
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), v_rot=1e-300)
    y0[6:] = 0.0
    ci = chaos_indicators(system, y0, 10.0)
    assert ci.status.name == "COLLISION" and ci.t < 5
    assert np.isnan(ci.ftle_history[-1]) and np.isfinite(ci.ftle_history[0])


@pytest.mark.parametrize("family,params,t_final", [("equilateral", {"delta": 3.0}, 200.0),
                                                  ("sides", {}, 60.0)])
def test_megno_matches_its_definition(paper_system, family, params, t_final):
    """<Y>(T) from its definition, computed independently: Y(t) = (2/t) int_0^t u
    (w'.w)/|w|^2 du with w' from the right-hand side at densely sampled states, then
    <Y> = (1/T) int Y -- against survey's step-end MEGNO."""
    from survey.physics.system import rhs
    y0 = initial_state(paper_system, family, **params)
    w0 = deviation_vectors(paper_system, y0, 1, seed=0)
    t = np.linspace(0.0, t_final, 200001)
    out = integrate(paper_system, y0, t_final, tangents=w0, megno=True, t_eval=t,
                    sample_tangents=True, renorm_interval=1e9)
    n = paper_system.n
    system_model = paper_system.model
    rate = np.empty(t.size)
    for k, state in enumerate(out.samples):
        dy = np.zeros(2 * n)
        rhs(t[k], np.ascontiguousarray(state), dy, system_model, 1)
        w, wdot = state[n:], dy[n:]
        rate[k] = w @ wdot / (w @ w)
    from scipy.integrate import cumulative_trapezoid
    z1 = cumulative_trapezoid(t * rate, t, initial=0.0)
    Y = np.divide(2 * z1, t, out=np.zeros_like(t), where=t > 0)
    mean_Y = np.trapezoid(Y, t) / t_final
    assert out.megno_sums[1] / out.t == pytest.approx(mean_Y, rel=1e-4)


def test_megno_survives_a_close_approach():
    """Under U = 2/|A| + |A|^2 this orbit passes close to collinear near t = 110, where
    the tangent dynamics spike within one step. MEGNO (from L = ln|w| at step ends, not a
    quadrature of the spiking rate) stays positive, grows like the FTLE says, and does not
    depend on the tolerance -- a quadrature of the rate gave <Y> = -797 at rtol 1e-12 and
    -67 at 1e-13."""
    system = System.create(potential="areal_barrier")
    y0 = initial_state(system, "equilateral", side=math.sqrt(3), delta=0.25, energy=8.0)
    runs = [chaos_indicators(system, y0, 300.0, IndicatorOptions(perturbations=0), rtol=tol,
                             atol=tol) for tol in (1e-12, 1e-13)]
    assert all(ci.status.name == "OK" and ci.ftle > 0.05 for ci in runs)
    assert runs[0].megno == pytest.approx(runs[1].megno, rel=0.05)
    assert np.all(np.diff(runs[0].megno_history[8:]) > -0.5) and runs[0].megno > 5
    assert runs[0].megno_slope == pytest.approx(runs[0].ftle / 2, rel=0.5)


@pytest.mark.parametrize("masses, dim", [((1.0, 1.0, 1.0), 2), ((1.0, 2.0, 3.5), 2),
                                         ((1.0, 2.0, 3.5), 3), ((0.5, 1.0, 1.5, 2.0), 2)])
def test_each_systems_deviations_keep_its_own_centre_of_mass_fixed(masses, dim):
    """The momentum constraints are built once per masses and dimension (a short map's
    cells spent most of their time rebuilding them): drawn one system after another, each
    system's vectors move neither its centre of mass nor its total momentum."""
    system = System.create(masses=masses, dim=dim)
    y0 = np.random.default_rng(len(masses) + dim).normal(size=system.n)
    w = deviation_vectors(system, y0, 4, seed=3)
    q, p = system.split(w)
    np.testing.assert_allclose(np.einsum("kid,i->kd", q, system.masses), 0, atol=1e-14)
    np.testing.assert_allclose(p.sum(axis=1), 0, atol=1e-14)
