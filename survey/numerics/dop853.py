"""Dormand-Prince 8(5,3) (Hairer's DOP853): its tableau, the stages of one step, the blended
error estimate and the 7th-order dense output, compiled, for L orbits at once stored
variable-major (component i of lane k at y[i * L + k]; L = 1 is one orbit). The driver that
steps the orbits is `driver.dop853`. Sums of products are fused multiply-adds
(`portable.fma`, correctly rounded, the same bits on every CPU), in the tableau's order: on
Intel's CPUs, where multiplications and additions share two pipes, the stage combinations
are bound by them, and fused they run faster (`bench --only step` splits a step's time)."""
from __future__ import annotations

import math

import numpy as np

from ..machine.jit import helper, lanes, leaf
from ..machine import portable
from ..machine.portable import fma
from ..physics.lanes import full_rhs, rhs_lanes, state_size

EPS = np.finfo(np.float64).eps


# Hairer's dop853.f refuses rtol <= 10 uround: below it the local error estimate measures
# roundoff, steps shrink without gaining accuracy and runs end at max_steps.
RTOL_MIN = 10.0 * EPS


# Step control: h_new = h * 0.9 err^-(1/8 - 0.2 BETA) err_old^BETA, factor in [1/3, 6]
# (Hairer's PI "Lund" stabilisation; DOP853 ships BETA = 0, DOPRI5 0.04). Measured on the
# paper's orbits at 1e-12: rejected steps fall from 30% to 19% (chaotic) and 15% to 6%
# (regular), with fewer RHS evaluations and no larger energy error. BETA = 5/128 (not
# 0.04) makes both exponents multiples of 1/128: err^(-15/128) and err_old^(5/128) come from
# square roots and products, the same bits on every CPU (libm's pow is not).
BETA_ROOTS = 5                      # BETA = 5/128: err_old^BETA = (err_old^(1/128))^5
ERR_FLOOR_ROOT = 1e-4                # err_old's floor, 1e-4, to the power 1/128:
for _ in range(7):
    ERR_FLOOR_ROOT = math.sqrt(ERR_FLOOR_ROOT)


# ---------------------------------------------------------------- DOP853 tableau
# E. Hairer, S.P. Norsett, G. Wanner, Solving ODEs I (2nd ed.), Sec. II.5; coefficients of
# dop853.f. Stage s uses A{s}_{j}; stages 14-16 serve only the dense output.
C2 = 0.05260015195876773


C3 = 0.0789002279381516


C4 = 0.1183503419072274


C5 = 0.2816496580927726


C6 = 0.3333333333333333


C7 = 0.25


C8 = 0.3076923076923077


C9 = 0.6512820512820513


C10 = 0.6


C11 = 0.8571428571428571


C12 = 1.0


C13 = 1.0


C14 = 0.1


C15 = 0.2


C16 = 0.7777777777777778


A2_1 = 0.05260015195876773


A3_1 = 0.0197250569845379


A3_2 = 0.0591751709536137


A4_1 = 0.02958758547680685


A4_3 = 0.08876275643042054


A5_1 = 0.2413651341592667


A5_3 = -0.8845494793282861


A5_4 = 0.924834003261792


A6_1 = 0.037037037037037035


A6_4 = 0.17082860872947386


A6_5 = 0.12546768756682242


A7_1 = 0.037109375


A7_4 = 0.17025221101954405


A7_5 = 0.06021653898045596


A7_6 = -0.017578125


A8_1 = 0.03709200011850479


A8_4 = 0.17038392571223998


A8_5 = 0.10726203044637328


A8_6 = -0.015319437748624402


A8_7 = 0.008273789163814023


A9_1 = 0.6241109587160757


A9_4 = -3.3608926294469414


A9_5 = -0.868219346841726


A9_6 = 27.59209969944671


A9_7 = 20.154067550477894


A9_8 = -43.48988418106996


A10_1 = 0.47766253643826434


A10_4 = -2.4881146199716677


A10_5 = -0.590290826836843


A10_6 = 21.230051448181193


A10_7 = 15.279233632882423


A10_8 = -33.28821096898486


A10_9 = -0.020331201708508627


A11_1 = -0.9371424300859873


A11_4 = 5.186372428844064


A11_5 = 1.0914373489967295


A11_6 = -8.149787010746927


A11_7 = -18.52006565999696


A11_8 = 22.739487099350505


A11_9 = 2.4936055526796523


A11_10 = -3.0467644718982196


A12_1 = 2.273310147516538


A12_4 = -10.53449546673725


A12_5 = -2.0008720582248625


A12_6 = -17.9589318631188


A12_7 = 27.94888452941996


A12_8 = -2.8589982771350235


A12_9 = -8.87285693353063


A12_10 = 12.360567175794303


A12_11 = 0.6433927460157636


A14_1 = 0.056167502283047954


A14_7 = 0.25350021021662483


A14_8 = -0.2462390374708025


A14_9 = -0.12419142326381637


A14_10 = 0.15329179827876568


A14_11 = 0.00820105229563469


A14_12 = 0.007567897660545699


A14_13 = -0.008298


A15_1 = 0.03183464816350214


A15_6 = 0.028300909672366776


A15_7 = 0.053541988307438566


A15_8 = -0.05492374857139099


A15_11 = -0.00010834732869724932


A15_12 = 0.0003825710908356584


A15_13 = -0.00034046500868740456


A15_14 = 0.1413124436746325


A16_1 = -0.42889630158379194


A16_6 = -4.697621415361164


A16_7 = 7.683421196062599


A16_8 = 4.06898981839711


A16_9 = 0.3567271874552811


A16_13 = -0.0013990241651590145


A16_14 = 2.9475147891527724


A16_15 = -9.15095847217987


B1 = 0.054293734116568765


B6 = 4.450312892752409


B7 = 1.8915178993145003


B8 = -5.801203960010585


B9 = 0.3111643669578199


B10 = -0.1521609496625161


B11 = 0.20136540080403034


B12 = 0.04471061572777259


BHH1 = 0.244094488188976377952755905512


BHH2 = 0.733846688281611857341361741547


BHH3 = 0.220588235294117647058823529412e-1


ER1 = 0.01312004499419488


ER6 = -1.2251564463762044


ER7 = -0.4957589496572502


ER8 = 1.6643771824549864


ER9 = -0.35032884874997366


ER10 = 0.3341791187130175


ER11 = 0.08192320648511571


ER12 = -0.022355307863886294


D4_1 = -8.428938276109013


D4_6 = 0.5667149535193777


D4_7 = -3.0689499459498917


D4_8 = 2.38466765651207


D4_9 = 2.117034582445028


D4_10 = -0.871391583777973


D4_11 = 2.2404374302607883


D4_12 = 0.6315787787694688


D4_13 = -0.08899033645133331


D4_14 = 18.148505520854727


D4_15 = -9.194632392478356


D4_16 = -4.436036387594894


D5_1 = 10.427508642579134


D5_6 = 242.28349177525817


D5_7 = 165.20045171727028


D5_8 = -374.5467547226902


D5_9 = -22.113666853125306


D5_10 = 7.733432668472264


D5_11 = -30.674084731089398


D5_12 = -9.332130526430229


D5_13 = 15.697238121770845


D5_14 = -31.139403219565178


D5_15 = -9.35292435884448


D5_16 = 35.81684148639408


D6_1 = 19.985053242002433


D6_6 = -387.0373087493518


D6_7 = -189.17813819516758


D6_8 = 527.8081592054236


D6_9 = -11.57390253995963


D6_10 = 6.8812326946963


D6_11 = -1.0006050966910838


D6_12 = 0.7777137798053443


D6_13 = -2.778205752353508


D6_14 = -60.19669523126412


D6_15 = 84.32040550667716


D6_16 = 11.99229113618279


D7_1 = -25.69393346270375


D7_6 = -154.18974869023643


D7_7 = -231.5293791760455


D7_8 = 357.6391179106141


D7_9 = 93.40532418362432


D7_10 = -37.45832313645163


D7_11 = 104.0996495089623


D7_12 = 29.8402934266605


D7_13 = -43.53345659001114


D7_14 = 96.32455395918828


D7_15 = -39.17726167561544


D7_16 = -149.72683625798564


# Each combination of stages: (the rows of K it reads, their coefficients) in the tableau's
# order -- stages 2-12 and 14-16, the 8th-order solution B, the 5th-order error ER and the
# dense output's D4-D7 -- summed by `stage_dot`.
A2 = ((0,), (A2_1,))
A3 = ((0, 1), (A3_1, A3_2))
A4 = ((0, 2), (A4_1, A4_3))
A5 = ((0, 2, 3), (A5_1, A5_3, A5_4))
A6 = ((0, 3, 4), (A6_1, A6_4, A6_5))
A7 = ((0, 3, 4, 5), (A7_1, A7_4, A7_5, A7_6))
A8 = ((0, 3, 4, 5, 6), (A8_1, A8_4, A8_5, A8_6, A8_7))
A9 = ((0, 3, 4, 5, 6, 7), (A9_1, A9_4, A9_5, A9_6, A9_7, A9_8))
A10 = ((0, 3, 4, 5, 6, 7, 8), (A10_1, A10_4, A10_5, A10_6, A10_7, A10_8, A10_9))
A11 = ((0, 3, 4, 5, 6, 7, 8, 9), (A11_1, A11_4, A11_5, A11_6, A11_7, A11_8, A11_9, A11_10))
A12 = ((0, 3, 4, 5, 6, 7, 8, 9, 10),
       (A12_1, A12_4, A12_5, A12_6, A12_7, A12_8, A12_9, A12_10, A12_11))
B = ((0, 5, 6, 7, 8, 9, 10, 11), (B1, B6, B7, B8, B9, B10, B11, B12))
ER = ((0, 5, 6, 7, 8, 9, 10, 11), (ER1, ER6, ER7, ER8, ER9, ER10, ER11, ER12))


def _in_two(rows, coefs):
    """A combination of 12 stages as two of 6, summed by `_dot_long`: the compiler unrolls a
    constant-length loop of up to 10 fused multiply-adds, not 11 (the loops over lanes that
    call it then ran scalar: the dense output's coefficients several times slower)."""
    return (rows[:6], coefs[:6]), (rows[6:], coefs[6:])


A14 = ((0, 6, 7, 8, 9, 10, 11, 12), (A14_1, A14_7, A14_8, A14_9, A14_10, A14_11, A14_12, A14_13))
A15 = ((0, 5, 6, 7, 10, 11, 12, 13), (A15_1, A15_6, A15_7, A15_8, A15_11, A15_12, A15_13, A15_14))
A16 = ((0, 5, 6, 7, 8, 12, 13, 14), (A16_1, A16_6, A16_7, A16_8, A16_9, A16_13, A16_14, A16_15))
D4 = _in_two((0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
             (D4_1, D4_6, D4_7, D4_8, D4_9, D4_10, D4_11, D4_12, D4_13, D4_14,
              D4_15, D4_16))
D5 = _in_two((0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
             (D5_1, D5_6, D5_7, D5_8, D5_9, D5_10, D5_11, D5_12, D5_13, D5_14,
              D5_15, D5_16))
D6 = _in_two((0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
             (D6_1, D6_6, D6_7, D6_8, D6_9, D6_10, D6_11, D6_12, D6_13, D6_14,
              D6_15, D6_16))
D7 = _in_two((0, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
             (D7_1, D7_6, D7_7, D7_8, D7_9, D7_10, D7_11, D7_12, D7_13, D7_14,
              D7_15, D7_16))


@helper
def stage_dot(K, i, comb):
    """sum_j c_j K[r_j, i] over comb = (rows r, coefficients c), as fused multiply-adds in
    order (the loop has a constant length: the compiler unrolls it, and the loops over i that
    call it run as SIMD instructions)."""
    rows, coefs = comb
    s = coefs[0] * K[rows[0], i]
    for j in range(1, len(rows)):
        s = fma(coefs[j], K[rows[j], i], s)
    return s


@helper
def _dot_long(K, i, parts):
    """`stage_dot` of a combination in two parts (`_in_two`): the same fused multiply-adds in the
    same order."""
    rows, coefs = parts[1]
    s = stage_dot(K, i, parts[0])
    for j in range(len(rows)):
        s = fma(coefs[j], K[rows[j], i], s)
    return s


@helper
def _rhs(y, dy, L, model, n_tan, W, rb):
    """The right-hand side of L lanes; one full orbit straight through `rhs` (a call less,
    a third of an evaluation). The systems are autonomous: it is given no time."""
    if rb is None and L == 1:
        full_rhs(0.0, y, dy, model, n_tan, rb)
    else:
        rhs_lanes(0.0, y, dy, L, model, n_tan, W, rb)


@lanes
def stages(model, n_tan, L, y, hh, K, yt, ynew, W, rb):
    """Stages 2..12 of L lanes (variable-major; K[0] holds f(y)) and their 8th-order
    solutions ynew; hh holds each lane's step at each of its components (one flat loop per
    stage vectorises across lanes and components alike). The systems are autonomous: the
    right-hand side is given no time."""
    M = y.size
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A2), y[i])
    _rhs(yt, K[1], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A3), y[i])
    _rhs(yt, K[2], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A4), y[i])
    _rhs(yt, K[3], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A5), y[i])
    _rhs(yt, K[4], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A6), y[i])
    _rhs(yt, K[5], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A7), y[i])
    _rhs(yt, K[6], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A8), y[i])
    _rhs(yt, K[7], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A9), y[i])
    _rhs(yt, K[8], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A10), y[i])
    _rhs(yt, K[9], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A11), y[i])
    _rhs(yt, K[10], L, model, n_tan, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A12), y[i])
    _rhs(yt, K[11], L, model, n_tan, W, rb)
    for i in range(M):
        ynew[i] = fma(hh[i], stage_dot(K, i, B), y[i])


@lanes
def error_norms(y, ynew, K, L, n_err, rtol, atol, h, err, scratch):
    """Hairer's blended 5th/3rd-order error estimate of each lane (into err), RMS over its
    first n_err components: the squared terms of all lanes in one flat loop, then each
    lane's sums in the components' order, as for one orbit, in loops over the lanes (both
    vectorised). scratch: 2 (n_err + 1) L."""
    M = n_err * L
    # two views, not two offsets into scratch: a loop that stores to two places of one
    # array runs several times slower (the compiler's overlap checks)
    sq3, sq5 = scratch[:M], scratch[M:2 * M]
    for i in range(M):
        isk = 1.0 / fma(rtol, max(abs(y[i]), abs(ynew[i])), atol)
        b = stage_dot(K, i, B)
        er3 = fma(-BHH3, K[11, i], fma(-BHH2, K[8, i], fma(-BHH1, K[0, i], b))) * isk
        er5 = stage_dot(K, i, ER) * isk
        sq3[i] = er3 * er3
        sq5[i] = er5 * er5
    e3, e5 = scratch[2 * M:2 * M + L], scratch[2 * M + L:2 * M + 2 * L]
    if L == 1:                      # one orbit: one loop (not one per component)
        a3 = a5 = 0.0
        for i in range(n_err):
            a3 += scratch[i]
            a5 += scratch[M + i]
        e3[0], e5[0] = a3, a5
    else:
        for k in range(L):
            e3[k] = 0.0
            e5[k] = 0.0
        for i in range(n_err):
            # views at each component: an index offset by the outer loop keeps the
            # compiler from vectorising the inner one
            s3, s5 = scratch[i * L:], scratch[M + i * L:]
            for k in range(L):
                e3[k] += s3[k]
                e5[k] += s5[k]
    for k in range(L):
        if e5[k] == 0.0 and e3[k] == 0.0:
            err[k] = 0.0
        else:
            err[k] = abs(h[k]) * e5[k] / math.sqrt(n_err * (e5[k] + 0.01 * e3[k]))


@lanes
def dense_prepare(model, L, nd, y, ynew, hh, K, yt, F, W, rb):
    """Coefficients of the 7th-order interpolants of L lanes over their last steps for
    components < nd (variable-major, so the first nd * L entries: the orbits', or theirs
    and their tangent vectors'); K[12] must hold f(ynew). No flag or count of tangents
    among the arguments: a literal one (the waiting slots hold orbits alone) compiled a
    second copy of this function and its right-hand sides."""
    nt = nd // state_size(model.masses, model.d, rb) - 1
    M = nd * L
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A14), y[i])
    _rhs(yt, K[13], L, model, nt, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A15), y[i])
    _rhs(yt, K[14], L, model, nt, W, rb)
    for i in range(M):
        yt[i] = fma(hh[i], stage_dot(K, i, A16), y[i])
    _rhs(yt, K[15], L, model, nt, W, rb)
    # one view per row stored to: see error_norms
    F0, F1, F2, F3, F4, F5, F6 = F[0], F[1], F[2], F[3], F[4], F[5], F[6]
    for i in range(M):
        dy = ynew[i] - y[i]
        F0[i] = dy
        F1[i] = fma(hh[i], K[0, i], -dy)
        F2[i] = fma(-hh[i], K[12, i] + K[0, i], 2.0 * dy)
        F3[i] = hh[i] * _dot_long(K, i, D4)
        F4[i] = hh[i] * _dot_long(K, i, D5)
        F5[i] = hh[i] * _dot_long(K, i, D6)
        F6[i] = hh[i] * _dot_long(K, i, D7)


@helper
def _interpolant(F, y, i, x, x1):
    """Component i of the interpolant at x (x1 = 1 - x)."""
    inner = fma(x1, fma(x, F[6, i], F[5, i]), F[4, i])
    inner = fma(x1, fma(x, inner, F[3, i]), F[2, i])
    return fma(x, fma(x1, fma(x, inner, F[1, i]), F[0, i]), y[i])


@leaf
def dense_eval(F, y, x, nd, out):
    """Interpolated state at t + x h, x in [0, 1]."""
    x1 = 1.0 - x
    for i in range(nd):
        out[i] = _interpolant(F, y, i, x, x1)


@lanes
def dense_eval_lanes(F, y, xx, M, out):
    """`dense_eval` of lanes (variable-major, the first M entries), each at its own x (xx:
    each lane's x at each of its components): the same bits, in SIMD instructions."""
    for i in range(M):
        out[i] = _interpolant(F, y, i, xx[i], 1.0 - xx[i])


@leaf
def norm_block(y, off, n):
    s = 0.0
    for i in range(off, off + n):
        s += y[i] * y[i]
    return math.sqrt(s)


# The step over every lane at once: each lane's step spread over its components, whether
# its new state is finite, its step factors, and the new states taken where accepted.

@lanes
def spread_steps(h, HH, L, nf):
    """Each lane's value h[k] at each of its components."""
    if L == 1:
        for i in range(nf):
            HH[i] = h[0]
        return
    for i in range(nf):
        for k in range(L):
            HH[i * L + k] = h[k]


@lanes
def finite_lanes(Y, K, L, nf, out):
    """out[k]: finite iff every component of lane k in Y and K is (x * 0 is NaN for inf and
    NaN, and NaN survives the sum)."""
    if L == 1:                 # one orbit: one loop (a loop per component costs more)
        s = 0.0
        for i in range(nf):
            s += Y[i] * 0.0 + K[i] * 0.0
        out[0] = s
        return
    for k in range(L):
        out[k] = 0.0
    for i in range(nf):
        y, dy = Y[i * L:], K[i * L:]
        for k in range(L):
            out[k] += y[k] * 0.0 + dy[k] * 0.0


@lanes
def step_factors(err, err_old, L, grow, err_next, cut):
    """The step control of every lane at once, from its error norm err and the last accepted
    step's err_old: the factor of its step if it is accepted, h 0.9 err^-(1/8 - BETA)
    err_old^BETA in [1/3, 6] (grow), err_old's next value (err_next), and the factor if it
    is rejected, 0.9 err^-1/8 but at least 1/3 (cut). Seven chained square roots and two
    divisions, ~200 cycles of latency for one lane, the same in SIMD for 4; lane by lane
    inside the bookkeeping they took ~3% of a 16-lane step. Meaningful for finite errors
    only."""
    for k in range(L):
        r8, r128 = portable.root8(max(err[k], 1e-10))
        fac = 0.9 * r128 / r8 * portable.ipow(err_old[k], BETA_ROOTS)
        grow[k] = min(6.0, max(1.0 / 3.0, fac))
        err_next[k] = r128 if err[k] >= 1e-4 else ERR_FLOOR_ROOT
        cut[k] = max(1.0 / 3.0, 0.9 / r8)


@lanes
def take_steps(Y, YN, K0, K12, take, L, nf):
    """Lanes with take[k] = -1 adopt their new state YN and its derivative K12, those with 0
    keep theirs: a select of the bits under the lane's mask, which runs as SIMD
    instructions (a store under `if` ran lane by lane, at about twice the cost)."""
    if L == 1:
        if take[0] != 0:
            for i in range(nf):
                Y[i] = YN[i]
                K0[i] = K12[i]
        return
    y, yn, k0, k12 = Y.view(np.int64), YN.view(np.int64), K0.view(np.int64), K12.view(np.int64)
    for i in range(nf):
        # views at each component: see dop853.error_norms
        a, b, c, e = y[i * L:], yn[i * L:], k0[i * L:], k12[i * L:]
        for k in range(L):
            a[k] = (b[k] & take[k]) | (a[k] & ~take[k])
            c[k] = (e[k] & take[k]) | (c[k] & ~take[k])
