"""Elementary functions that give the same bits on every x86-64 machine.

glibc's exp, log, pow, sin and cos pick an implementation by the CPU's features (FMA, AVX2),
and numpy's pick SIMD versions (AVX-512 on some machines, none on others): the same orbit
then rounds differently on another machine, and a chaotic orbit amplifies that into any
digit. The functions here use only IEEE-754 addition, multiplication, division, square
root, fused multiply-add (`fma`) and exact scaling by powers of two -- each correctly
rounded, so every CPU and every compiler target returns the same bits -- in the classic argument reductions (Cody-Waite,
as in fdlibm) with series long enough for about one ulp.

Scalar versions inline into kernels; `vexp`, `vlog`, `vsin`, `vcos`, `vsincos`, `vatan2`
apply them elementwise to arrays for Python code (the trigonometric ones as branch-free SIMD
loops with the same bits), and `vnorm` and `vdot` are the Euclidean norm and the dot product
along the last axis summed in order (numpy's and BLAS's sums change their order with the
CPU); `linalg` builds the portable matrix algorithms on them.
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from .jit import helper, kernel, leaf



@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c rounded once: IEEE-754's fusedMultiplyAdd, correctly rounded like + and *,
    so the same bits on every CPU (one instruction wherever the CPU has FMA, as every x86-64
    since 2013 does; libm's exact emulation elsewhere). numba never fuses a * b + c by
    itself; on CPUs whose multiplications and additions share two pipes (Intel's) a sum of
    products then runs at half the machine's rate."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)
    return sig, codegen


# ln 2 split so that k * LN2_HI is exact for |k| < 2^20 (fdlibm's constants; the test
# checks them against ln 2 to 50 digits)
LN2_HI = 0.6931471803691238
LN2_LO = 1.9082149292705877e-10
INV_LN2 = 1.4426950408889634
# pi/2 in three pieces of 33 bits, so that k * PIO2_1 and k * PIO2_2 are exact for |k| < 2^20
PIO2_1 = 1.5707963267341256
PIO2_2 = 6.077100506303966e-11
PIO2_3 = 2.0222662487959506e-21
TWO_OVER_PI = 0.6366197723675814
TRIG_MAX = 1.0e5           # |x| beyond this: glibc (reduction by three pieces loses bits)
SQRT_HALF = 0.7071067811865476
EXP_MAX = 709.782712893384
EXP_MIN = -745.1332191019412
# series coefficients, highest power first (each 1/n! correctly rounded)
EXP_SERIES = tuple(1.0 / math.factorial(n) for n in range(13, 1, -1))             # r^13..r^2
LOG_SERIES = tuple(2.0 / n for n in range(23, 1, -2))                          # z^10..z^0 of R/z
SIN_SERIES = tuple((-1.0) ** (n // 2) / math.factorial(n) for n in range(19, 2, -2))  # z^8..z^1
COS_SERIES = tuple((-1.0) ** (n // 2) / math.factorial(n) for n in range(18, 3, -2))  # z^7..z^2
# atan's reduction points 1/2, 1, 3/2 and infinity: atan of each split in two (hi exact to
# double, hi + lo to about 1e-33), and the Taylor series of 1 - atan(z)/z in z^2 for
# |z| <= 7/16, to z^50 (the next term is below 2^-60 of the sum)
ATAN_HI = (0.4636476090008061, 0.7853981633974483, 0.982793723247329, 1.5707963267948966)
ATAN_LO = (2.2698777452961687e-17, 3.061616997868383e-17, 1.3903311031230998e-17,
           6.123233995736766e-17)
ATAN_SERIES = tuple((-1.0) ** (n + 1) / (2 * n + 1) for n in range(25, 0, -1))  # z^50..z^2
PI_HI, PI_LO = 3.141592653589793, 1.2246467991473532e-16


@helper
def _two_to(k):
    """2^k, exactly, for an integer -1022 <= k <= 1023: its bits (libm's ldexp is a call,
    which keeps a loop of exp or log from running as SIMD instructions)."""
    return np.int64((k + 1023) << 52).view(np.float64)


@helper
def exp(x):
    """e^x: x = k ln2 + r, |r| <= ln2/2, e^r by its Taylor series to r^13, times 2^k as
    two powers of two (the first product exact, the second rounding once where the result
    is subnormal, as ldexp does). Without branches, so that a loop of it is vectorised."""
    inside = x > EXP_MIN and x < EXP_MAX
    xc = x if inside else 0.0
    k = math.floor(xc * INV_LN2 + 0.5)
    r_hi = xc - k * LN2_HI
    r = r_hi - k * LN2_LO
    p = 0.0
    for c in EXP_SERIES:
        p = p * r + c
    e = 1.0 + (r + r * r * p)
    a = k >> 1
    scaled = (e * _two_to(a)) * _two_to(k - a)
    outside = 0.0 if x <= EXP_MIN else (x if x != x else math.inf)
    return scaled if inside else outside


@helper
def log(x):
    """ln x: x = 2^k m with m in [sqrt(1/2), sqrt(2)), f = m - 1, s = f / (2 + f),
    ln m = f - (f^2/2 - s (f^2/2 + R(s^2))) with R the atanh series (fdlibm's form). m and
    k from x's bits (a subnormal x scaled by 2^54 first), without branches, so that a loop
    of it is vectorised."""
    inside = x > 0.0 and x < math.inf
    tiny = x < 2.2250738585072014e-308
    xs = (x * 18014398509481984.0 if tiny else x) if inside else 1.0
    bits = np.float64(xs).view(np.int64)
    k = ((bits >> 52) & 0x7FF) - 1022 - (54 if tiny else 0)
    m = np.int64((bits & 0x800FFFFFFFFFFFFF) | (1022 << 52)).view(np.float64)
    low = m < SQRT_HALF
    m = m * 2.0 if low else m
    k = k - 1 if low else k
    f = m - 1.0
    s = f / (2.0 + f)
    z = s * s
    R = 0.0
    for c in LOG_SERIES:
        R = R * z + c
    R = R * z
    hfsq = 0.5 * f * f
    dk = float(k)
    value = dk * LN2_HI - ((hfsq - (s * (hfsq + R) + dk * LN2_LO)) - f)
    outside = x if x == math.inf else (-math.inf if x == 0.0 else math.nan)
    return value if inside else outside


@helper
def _reduce(x):
    """x = k pi/2 + r, |r| <= pi/4 (about), for |x| <= TRIG_MAX; returns (k mod 4, r)."""
    k = math.floor(x * TWO_OVER_PI + 0.5)
    r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3
    return int(k) & 3, r


@helper
def _sin_series(r):
    z = r * r
    p = 0.0
    for c in SIN_SERIES:
        p = p * z + c
    return r + r * z * p


@helper
def _cos_series(r):
    z = r * r
    p = 0.0
    for c in COS_SERIES:
        p = p * z + c
    return 1.0 - (0.5 * z - z * z * p)


@helper
def sin(x):
    """sin x by reduction to |r| <= pi/4 and Taylor series (to r^19)."""
    if not abs(x) <= TRIG_MAX:
        return math.sin(x)
    q, r = _reduce(x)
    if q == 0:
        return _sin_series(r)
    if q == 1:
        return _cos_series(r)
    if q == 2:
        return -_sin_series(r)
    return -_cos_series(r)


@helper
def cos(x):
    """cos x by reduction to |r| <= pi/4 and Taylor series (to r^18)."""
    if not abs(x) <= TRIG_MAX:
        return math.cos(x)
    q, r = _reduce(x)
    if q == 0:
        return _cos_series(r)
    if q == 1:
        return -_sin_series(r)
    if q == 2:
        return -_cos_series(r)
    return _sin_series(r)


@leaf
def cis(x):
    """(cos x, sin x), the bits of `cos` and `sin`, as a call: where a kernel takes them a
    few times per call rather than in a SIMD loop, inlining both series at every use made
    its compilation several times longer (the torus analysis's `_take_from_spectrum`,
    `_phases` and `_window`, in every worker on a first run)."""
    return cos(x), sin(x)


@helper
def _atan_series(z):
    w = z * z
    p = 0.0
    for c in ATAN_SERIES[:12]:      # two loops: the compiler unrolls each (one of 25 it
        p = p * w + c               # keeps, and a loop around it then stays scalar)
    for c in ATAN_SERIES[12:]:
        p = p * w + c
    return z * (w * p)      # z - atan(z)


@helper
def _atan_positive(a):
    """atan a for 0 <= a < inf: a reduced to |z| <= 7/16 by atan a = atan c + atan((a - c)/(1 +
    c a)) with c in (0, 1/2, 1, 3/2, infinity), as in fdlibm, then the Taylor series. Each
    interval's reduction is z = (p a - q) / (r + s a) (p a and s a exact, so fdlibm's z)
    with constants chosen by comparisons, which the compiler turns into selects: a loop of
    it runs as SIMD instructions."""
    if a < 0.4375:
        p, q, r, s, hi, lo = 1.0, 0.0, 1.0, 0.0, 0.0, 0.0
    elif a < 0.6875:
        p, q, r, s, hi, lo = 2.0, 1.0, 2.0, 1.0, ATAN_HI[0], ATAN_LO[0]
    elif a < 1.1875:
        p, q, r, s, hi, lo = 1.0, 1.0, 1.0, 1.0, ATAN_HI[1], ATAN_LO[1]
    elif a < 2.4375:
        p, q, r, s, hi, lo = 1.0, 1.5, 1.0, 1.5, ATAN_HI[2], ATAN_LO[2]
    else:
        p, q, r, s, hi, lo = 0.0, 1.0, 0.0, 1.0, ATAN_HI[3], ATAN_LO[3]
    z = (p * a - q) / (r + s * a)
    return hi - ((_atan_series(z) - lo) - z)


@helper
def atan(x):
    """atan x, odd, with atan(+-inf) = +-pi/2."""
    if x != x:
        return x
    a = abs(x)
    r = _atan_positive(a) if a < math.inf else ATAN_HI[3]
    return -r if x < 0.0 else r


@helper
def _quadrant(y, x, z):
    """The angle of (x, y) from z = atan(|y| / |x|)."""
    z = PI_HI - (z - PI_LO) if x < 0.0 else z
    return -z if y < 0.0 else z


@helper
def atan2(y, x):
    """The angle of (x, y) in [-pi, pi], from atan(|y| / |x|) by quadrant; zeros and
    infinities as IEEE's atan2 (glibc's exact special values)."""
    if y != y or x != x:
        return x + y
    if x == 0.0 or y == 0.0 or abs(x) == math.inf or abs(y) == math.inf:
        return math.atan2(y, x)
    return _quadrant(y, x, atan(abs(y) / abs(x)))


@kernel
def sin_cos_into(x, sin_out, cos_out):
    """sin and cos of every x[i], the bits of `sin` and `cos`: one branch-free loop (both
    series, the quadrant's by selects) that runs as SIMD instructions, then libm's where
    |x| > TRIG_MAX or x is not finite, as `sin` and `cos` do."""
    for i in range(x.size):
        xi = x[i]
        q, r = _reduce(xi if abs(xi) <= TRIG_MAX else 0.0)
        s, c = _sin_series(r), _cos_series(r)
        odd = (q & 1) == 1
        v, w = (c if odd else s), (s if odd else c)
        sin_out[i] = -v if q >= 2 else v                  # q: 0 s, 1 c, 2 -s, 3 -c
        cos_out[i] = -w if q == 1 or q == 2 else w        # q: 0 c, 1 -s, 2 -c, 3 s
    for i in range(x.size):
        if not abs(x[i]) <= TRIG_MAX:
            sin_out[i], cos_out[i] = math.sin(x[i]), math.cos(x[i])


@kernel
def atan2_into(y, x, out):
    """out[i] = atan2(y[i], x[i]), the same bits: one branch-free loop that runs as SIMD
    instructions (4x the scalar loop), then `atan2` again where |y/x| is not a positive
    finite number (zeros, infinities, NaN). out must not be y or x."""
    for i in range(out.size):
        out[i] = _quadrant(y[i], x[i], _atan_positive(abs(y[i]) / abs(x[i])))
    for i in range(out.size):
        a = abs(y[i]) / abs(x[i])
        if not (0.0 < a < math.inf):
            out[i] = atan2(y[i], x[i])


@helper
def root8(x):
    """(x^(1/8), x^(1/128)) by chained square roots: the step-size control's powers."""
    s = math.sqrt(math.sqrt(math.sqrt(x)))
    return s, math.sqrt(math.sqrt(math.sqrt(math.sqrt(s))))


@helper
def ipow(x, n):
    """x^n for an integer n by binary powering (the same products on every machine)."""
    result = 1.0
    base = x
    e = abs(n)
    while e > 0:
        if e & 1:
            result *= base
        base *= base
        e >>= 1
    return 1.0 / result if n < 0 else result


@helper
def power(x, y):
    """x^y for x > 0: binary powering for integer y, a square root then powering for
    half-integer y, else exp(y ln x) (a few ulp)."""
    if y == math.floor(y) and abs(y) < 1024.0:
        return ipow(x, int(y))
    if 2.0 * y == math.floor(2.0 * y) and abs(y) < 1024.0:
        return ipow(math.sqrt(x), int(2.0 * y))
    return exp(y * log(x))


EXP, LOG, SIN, COS, ATAN2 = range(5)


@kernel
def _elementwise(code, a, b, out):
    """out[i] = f(a[i]) (atan2: f(a[i], b[i])) for the function of `code`."""
    if code == ATAN2:
        atan2_into(a, b, out)
    elif code == SIN:
        sin_cos_into(a, out, np.empty(out.size))
    elif code == COS:
        sin_cos_into(a, np.empty(out.size), out)
    elif code == EXP:
        for i in range(out.size):
            out[i] = exp(a[i])
    else:
        for i in range(out.size):
            out[i] = log(a[i])


@kernel
def _row_dots(a, b, out):
    """out[r] = sum_i a[r, i] b[r, i], summed in order."""
    for r in range(a.shape[0]):
        s = 0.0
        for i in range(a.shape[1]):
            s += a[r, i] * b[r, i]
        out[r] = s


def _apply(code, *args):
    """The function of `code` over broadcast arrays: an array of their shape (a numpy
    scalar for scalars, as a ufunc gives). A kernel rather than numba's vectorize: a ufunc
    builds its wrapper anew in every process, a kernel loads from the cache."""
    arrays = [np.asarray(a, dtype=np.float64) for a in args]
    if len(arrays) > 1:
        arrays = np.broadcast_arrays(*arrays)
    flat = [np.ascontiguousarray(a).reshape(-1) for a in arrays]
    out = np.empty(flat[0].size)
    _elementwise(code, flat[0], flat[-1], out)
    return out.reshape(arrays[0].shape)[()]


def vexp(x):
    return _apply(EXP, x)


def vlog(x):
    return _apply(LOG, x)


def vsin(x):
    return _apply(SIN, x)


def vcos(x):
    return _apply(COS, x)


def vsincos(x):
    """(sin x, cos x) of an array, from one reduction of each x."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    s, c = np.empty_like(x), np.empty_like(x)
    sin_cos_into(x.reshape(-1), s.reshape(-1), c.reshape(-1))
    return s, c


def vatan2(y, x):
    return _apply(ATAN2, y, x)


def vdot(a, b):
    """The dot products of a and b along their last axis (broadcast), summed in order.
    Arrays of one shape skip numpy's broadcasting, and a norm passes its rows once: a
    cell's outcomes and deviation draws call this thousands of times, each a few
    microseconds of numpy around a kernel of nanoseconds."""
    same = a is b
    a = np.asarray(a, dtype=np.float64)
    b = a if same else np.asarray(b, dtype=np.float64)
    if a.shape != b.shape:
        a, b = np.broadcast_arrays(a, b)
    shape, n = a.shape[:-1], a.shape[-1]
    rows = math.prod(shape)
    out = np.empty(rows)
    a = np.ascontiguousarray(a).reshape(rows, n)
    _row_dots(a, a if same else np.ascontiguousarray(b).reshape(rows, n), out)
    return out.reshape(shape)[()]


def vnorm(a):
    """The Euclidean norms along the last axis, summed in order."""
    return np.sqrt(vdot(a, a))
