"""The portable elementary functions: accurate to about an ulp against references computed
in high-precision decimal arithmetic, exact at their special values, their splitting
constants what they claim. (That they give the same bits on another CPU is tested end to
end in tests/pipeline/test_portable_archives.py.)"""
import math
from decimal import Decimal, getcontext
from fractions import Fraction

import numba
import numpy as np
import pytest

from survey.machine import portable as P

getcontext().prec = 50
PI = Decimal("3.14159265358979323846264338327950288419716939937510582097494459")


def ulps(value, exact: Decimal) -> float:
    return float(abs(Decimal(float(value)) - exact) / Decimal(math.ulp(float(exact))))


def dsin(x: Decimal) -> Decimal:
    """sin by its Taylor series after reduction mod 2 pi, in 50 digits."""
    x = x - 2 * PI * (x / (2 * PI)).to_integral_value()
    term, total, n = x, x, 1
    while abs(term) > Decimal(10) ** -45:
        term *= -x * x / ((n + 1) * (n + 2))
        total += term
        n += 2
    return total


def dcos(x: Decimal) -> Decimal:
    return dsin(x + PI / 2)


def test_splitting_constants_sum_to_ln2_and_pi_over_2_and_multiply_exactly():
    ln2 = Decimal(2).ln()
    # the sum is ln 2 to within half an ulp of LN2_LO
    assert abs(Decimal(P.LN2_HI) + Decimal(P.LN2_LO) - ln2) <= Decimal(math.ulp(P.LN2_LO)) / 2
    assert abs(Decimal(P.PIO2_1) + Decimal(P.PIO2_2) + Decimal(P.PIO2_3) - PI / 2) \
        < Decimal(10) ** -36
    for c, bits in ((P.LN2_HI, 32), (P.PIO2_1, 33), (P.PIO2_2, 33)):
        # at most `bits` significant bits: k * c is exact for |k| < 2^(53 - bits)
        m = Fraction(c)
        assert (m * 2 ** (bits - math.frexp(c)[1])).denominator == 1


def test_exp_and_log_within_one_ulp_over_their_ranges():
    rng = np.random.default_rng(3)
    xs = np.concatenate([rng.uniform(-700, 700, 400), rng.uniform(-1, 1, 400),
                         rng.uniform(-1e-8, 1e-8, 50), [0.0, 1.0, -1.0, 709.7]])
    assert max(ulps(P.vexp(x), Decimal(float(x)).exp()) for x in xs) <= 1.0
    ys = np.concatenate([np.exp(rng.uniform(-700, 700, 400)), rng.uniform(0.5, 2.0, 400),
                         1.0 + rng.uniform(-1e-9, 1e-9, 50), [2.0, 10.0, 5e-324, 1e308]])
    ys = ys[ys != 1.0]
    assert max(ulps(P.vlog(y), Decimal(float(y)).ln()) for y in ys) <= 1.0
    assert P.vlog(1.0) == 0.0 and P.vexp(0.0) == 1.0


def reference_exp(x: float) -> float:
    """The reduction of portable.exp with libm's exact scaling (math.ldexp)."""
    if not x < P.EXP_MAX:
        return x if x != x else math.inf
    if not x > P.EXP_MIN:
        return 0.0
    k = math.floor(x * P.INV_LN2 + 0.5)
    r = (x - k * P.LN2_HI) - k * P.LN2_LO
    p = 0.0
    for c in P.EXP_SERIES:
        p = p * r + c
    e = 1.0 + (r + r * r * p)
    return math.ldexp(math.ldexp(e, k + 600), -600) if k < -1020 else math.ldexp(e, k)


def reference_log(x: float) -> float:
    """The reduction of portable.log with libm's exact frexp."""
    if not x > 0.0:
        return -math.inf if x == 0.0 else math.nan
    if x == math.inf:
        return x
    m, k = math.frexp(x)
    if m < P.SQRT_HALF:
        m, k = 2.0 * m, k - 1
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    R = 0.0
    for c in P.LOG_SERIES:
        R = R * z + c
    R = R * z
    hfsq = 0.5 * f * f
    return k * P.LN2_HI - ((hfsq - (s * (hfsq + R) + k * P.LN2_LO)) - f)


def test_exp_and_log_take_m_and_k_from_the_bits_as_frexp_and_ldexp_would():
    """The kernels' exp and log build 2^k and split x with integer operations on the bits
    (no libm calls, so that their loops run as SIMD instructions): the same bits as the
    reduction written with frexp and ldexp, subnormal arguments and results included."""
    rng = np.random.default_rng(5)
    xs = np.concatenate([rng.uniform(-760, 720, 1500), rng.normal(0, 3, 500),
                         np.linspace(-745.2, -744.4, 300), np.linspace(709.0, 709.79, 100),
                         [-745.1332191019412, 709.782712893384, 0.0, -0.0, math.inf,
                          -math.inf, math.nan]])
    ys = np.concatenate([10.0 ** rng.uniform(-323.5, 308, 1500), rng.uniform(0.6, 1.5, 500),
                         [5e-324, 2.225073858507201e-308, 2.2250738585072014e-308,
                          P.SQRT_HALF, np.nextafter(P.SQRT_HALF, 0), 1.0, 0.0, -1.0,
                          math.inf, math.nan, 1.7976931348623157e308]])
    for f, ref, values in ((P.vexp, reference_exp, xs), (P.vlog, reference_log, ys)):
        with np.errstate(all="ignore"):
            got = f(values)
        want = np.array([ref(float(v)) for v in values])
        same = (got.view(np.int64) == want.view(np.int64)) | (np.isnan(got) & np.isnan(want))
        assert same.all(), (f.__name__, values[~same][:5])


def test_sin_and_cos_within_two_ulps():
    rng = np.random.default_rng(4)
    xs = np.concatenate([rng.uniform(-7, 7, 300), rng.uniform(-1e5, 1e5, 100),
                         [1e-300, 0.5, math.pi / 2, math.pi, 2 * math.pi / 3]])
    for f, ref in ((P.vsin, dsin), (P.vcos, dcos)):
        worst = max(ulps(f(x), ref(Decimal(float(x)))) for x in xs
                    if abs(ref(Decimal(float(x)))) > 1e-3)
        assert worst <= 2.0, (f.__name__, worst)
    assert P.vsin(0.0) == 0.0 and P.vcos(0.0) == 1.0


def test_special_values():
    inf, nan = math.inf, math.nan
    assert list(P.vexp(np.array([inf, -inf, 710.0, -746.0]))) == [inf, 0.0, inf, 0.0]
    assert ulps(P.vexp(-740.0), Decimal(-740).exp()) <= 1.0          # subnormal result
    assert math.isnan(P.vexp(nan)) and math.isnan(P.vlog(nan)) and math.isnan(P.vlog(-1.0))
    assert P.vlog(0.0) == -inf and P.vlog(inf) == inf


@pytest.mark.parametrize("y", [2.0, 3.0, -4.0, 6.0, 0.5, 2.5, -1.5, 1.0 / 3.0, 0.1])
def test_power_exact_for_integers_and_accurate_otherwise(y):
    for x in (0.3, 1.7, 12.5):
        value = P.power(x, y)
        exact = Decimal(x) ** int(y) if y == int(y) else (Decimal(x).ln() * Decimal(y)).exp()
        # integers: binary powering rounds each of its few products; otherwise a few ulp
        assert ulps(value, exact) <= (2.0 if y == int(y) else 4.0), (x, y)


def test_root8_gives_the_eighth_and_128th_roots():
    for x in (1e-10, 0.37, 1.0, 2.0, 1e5):
        r8, r128 = P.root8(x)
        assert r8 == pytest.approx(x ** 0.125, rel=4e-16)
        assert r128 == pytest.approx(x ** (1 / 128), rel=4e-16)


def datan(x: Decimal) -> Decimal:
    """atan by halving the argument (atan x = 2 atan(x / (1 + sqrt(1 + x^2)))) to below
    1e-2, then its Taylor series, in 50 digits."""
    halvings = 0
    while abs(x) > Decimal("0.01"):
        x = x / (1 + (1 + x * x).sqrt())
        halvings += 1
    term, total, n = x, x, 1
    while abs(term) > Decimal(10) ** -48:
        term *= -x * x
        n += 2
        total += term / n
    return total * 2 ** halvings


def test_atan2_within_one_ulp_in_every_quadrant_and_exact_at_its_special_values():
    rng = np.random.default_rng(5)
    ys = rng.normal(size=600) * 10.0 ** rng.uniform(-8, 8, 600)
    xs = rng.normal(size=600) * 10.0 ** rng.uniform(-8, 8, 600)
    # and each reduction interval's edges: |y/x| near 7/16, 11/16, 19/16, 39/16
    edges = np.array([0.4375, 0.6875, 1.1875, 2.4375])
    ys = np.concatenate([ys, np.repeat(edges, 3) * np.tile([1 - 1e-15, 1.0, 1 + 1e-15], 4)])
    xs = np.concatenate([xs, np.ones(12)])
    for y, x in zip(ys, xs):
        t = datan(Decimal(float(abs(y))) / Decimal(float(abs(x))))
        exact = t if x > 0 else PI - t
        exact = -exact if y < 0 else exact
        assert ulps(P.vatan2(y, x), exact) <= 1.0, (y, x)
    inf = math.inf
    for y, x, value in ((0.0, 1.0, 0.0), (0.0, -1.0, math.pi), (1.0, 0.0, math.pi / 2),
                        (-1.0, 0.0, -math.pi / 2), (inf, 1.0, math.pi / 2),
                        (1.0, -inf, math.pi), (-0.0, 1.0, -0.0)):
        assert P.vatan2(y, x) == value and math.copysign(1, P.vatan2(y, x)) == \
            math.copysign(1, value)
    assert math.isnan(P.vatan2(math.nan, 1.0))


def test_the_simd_atan2_gives_the_scalar_bits():
    """atan2 over arrays (a branch-free SIMD loop, then the scalar atan2 where |y/x| is not
    a positive finite number) against the scalar atan2 of the kernels, element by element:
    every quadrant, each reduction interval, and the special values among them."""
    scalar = numba.njit(lambda y, x: P.atan2(y, x))
    rng = np.random.default_rng(6)
    ys = rng.normal(size=997) * 10.0 ** rng.uniform(-5, 5, 997)
    xs = rng.normal(size=997) * 10.0 ** rng.uniform(-5, 5, 997)
    inf, nan = math.inf, math.nan
    ys[:13] = [0.0, -0.0, 1.0, -1.0, inf, 1.0, nan, 1.0, 1e300, 1e-300, 0.0, -inf, 0.6875]
    xs[:13] = [1.0, -1.0, 0.0, -0.0, 1.0, -inf, 1.0, nan, -1e-300, 1e300, -0.0, -inf, -1.0]
    got = P.vatan2(ys, xs)
    want = np.array([scalar(y, x) for y, x in zip(ys, xs)])
    assert got.tobytes() == want.tobytes()


def test_the_simd_sine_and_cosine_give_the_scalar_bits():
    """sin and cos over arrays (both series, the quadrant's by selects; libm beyond
    TRIG_MAX) against the scalar sin and cos of the kernels: every quadrant, zeros, both
    sides of TRIG_MAX, infinity and NaN."""
    both = numba.njit(lambda x: (P.sin(x), P.cos(x)))
    rng = np.random.default_rng(7)
    xs = rng.normal(size=999) * 10.0 ** rng.uniform(-4, 6, 999)
    xs[:9] = [0.0, -0.0, math.pi / 2, -math.pi, P.TRIG_MAX, -P.TRIG_MAX * (1 + 1e-15),
              math.inf, -math.inf, math.nan]
    s, c = P.vsincos(xs)
    want = np.array([both(x) for x in xs])
    assert s.tobytes() == want[:, 0].tobytes() and c.tobytes() == want[:, 1].tobytes()
    assert P.vsin(xs).tobytes() == s.tobytes() and P.vcos(xs).tobytes() == c.tobytes()
