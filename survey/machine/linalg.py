"""Dense linear algebra that gives the same bits on every machine.

LAPACK and BLAS pick blocked, SIMD and FMA kernels by the CPU (OpenBLAS by its core type),
so a product, a least-squares correction, a null vector or a spectrum rounds differently on
another machine. Where an iteration stops at its own noise -- Newton shooting for periodic
orbits, pseudo-arclength continuation, the descent to an equilibrium -- those last bits
decide how many members a family has and the digits of where it bifurcates, and a chaotic
orbit started from the result amplifies them into every digit. Here the small dense
matrices of equilibria, periodic orbits and their families (tens of rows) go through
compiled loops in a fixed order of IEEE operations instead: products summed in order; the
singular value decomposition by one-sided Jacobi rotations (Hestenes; Demmel and Veselic
1992: accurate also for the small singular values a null vector is read from), with the
minimum-norm least squares from it; the nonsymmetric eigenproblem by balancing, Householder
reduction to Hessenberg form and Francis's double-shift QR (EISPACK's balanc, orthes and
hqr), eigenvectors by inverse iteration; the symmetric one by cyclic Jacobi rotations.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from .jit import helper, kernel
from .portable import vatan2, vdot, vnorm

EPS = 2.220446049250313e-16


@kernel
def _matmul(a, b, out):
    """out = a b, each entry summed in order."""
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            s = 0.0
            for k in range(a.shape[1]):
                s += a[i, k] * b[k, j]
            out[i, j] = s


def dot(a, b):
    """a @ b for 1-D and 2-D float arrays (a float for two vectors), summed in order."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim == 1 and b.ndim == 1:
        return float(vdot(a, b))
    A = a[None] if a.ndim == 1 else a
    B = b[:, None] if b.ndim == 1 else b
    if A.ndim != 2 or B.ndim != 2 or A.shape[1] != B.shape[0]:
        raise ValueError(f"shapes {a.shape} and {b.shape} do not multiply")
    out = np.empty((A.shape[0], B.shape[1]))
    _matmul(np.ascontiguousarray(A), np.ascontiguousarray(B), out)
    if a.ndim == 1:
        out = out[0]
    return out[..., 0] if b.ndim == 1 else out


def chain(*factors):
    """The product of the factors, left to right."""
    return functools.reduce(dot, factors)


def norm(x) -> float:
    """The Euclidean norm of a vector, summed in order."""
    return float(vnorm(np.asarray(x, dtype=np.float64)))


@helper
def _rotation(zeta):
    """(c, s) of the Jacobi rotation that zeroes an off-diagonal pair with
    zeta = (a_qq - a_pp) / (2 a_pq): t = tan of the smaller angle."""
    if abs(zeta) > 1e150:
        t = 0.5 / zeta
    else:
        t = 1.0 / (abs(zeta) + math.sqrt(zeta * zeta + 1.0))
        t = -t if zeta < 0.0 else t
    c = 1.0 / math.sqrt(t * t + 1.0)
    return c, c * t


@helper
def _rotate_columns(a, p, q, c, s):
    for i in range(a.shape[0]):
        x, y = a[i, p], a[i, q]
        a[i, p], a[i, q] = c * x - s * y, s * x + c * y


@kernel
def _jacobi(a):
    """One-sided Jacobi rotations of a's columns until they are mutually orthogonal:
    (a V, V) with V orthogonal (n x n, whatever a's shape), so the singular values are the
    norms of a V's columns and V's columns the right singular vectors -- the null space's
    included, as columns of a V that fall to rounding level."""
    m, n = a.shape
    u = a.copy()
    v = np.eye(n)
    tol = EPS * m
    for _ in range(100):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                alpha = beta = gamma = 0.0
                for i in range(m):
                    alpha += u[i, p] * u[i, p]
                    beta += u[i, q] * u[i, q]
                    gamma += u[i, p] * u[i, q]
                if abs(gamma) <= tol * math.sqrt(alpha) * math.sqrt(beta):
                    continue
                rotated = True
                c, s = _rotation((beta - alpha) / (2.0 * gamma))
                _rotate_columns(u, p, q, c, s)
                _rotate_columns(v, p, q, c, s)
        if not rotated:
            break
    return u, v


def svd(a):
    """(s, Vt): a's n singular values, descending, and its right singular vectors as the
    rows of Vt (n x n): np.linalg.svd(a)[1:] except that a wide matrix (m < n) also lists
    the zeros of its null space among s."""
    u, v = _jacobi(np.ascontiguousarray(a, dtype=np.float64))
    s = vnorm(np.ascontiguousarray(u.T))
    order = np.argsort(-s, kind="stable")
    return s[order], np.ascontiguousarray(v[:, order].T)


def norm2(a) -> float:
    """The spectral norm (the largest singular value) of a matrix."""
    return float(svd(a)[0][0])


@kernel
def _min_norm(u, v, b, rcond):
    """sum_j v_j (u_j . b) / |u_j|^2 over the columns with |u_j| > rcond max |u_j|."""
    m, n = u.shape
    size = np.zeros(n)
    for j in range(n):
        for i in range(m):
            size[j] += u[i, j] * u[i, j]
    cut = rcond * rcond * np.max(size)
    x = np.zeros(n)
    for j in range(n):
        if size[j] > cut and size[j] > 0.0:
            c = 0.0
            for i in range(m):
                c += u[i, j] * b[i]
            c /= size[j]
            for i in range(n):
                x[i] += v[i, j] * c
    return x


def lstsq(a, b, rcond: float):
    """The minimum-norm least-squares solution of a x = b, the singular values below
    rcond times the largest cut (np.linalg.lstsq(a, b, rcond)[0])."""
    u, v = _jacobi(np.ascontiguousarray(a, dtype=np.float64))
    return _min_norm(u, v, np.ascontiguousarray(b, dtype=np.float64), rcond)


@kernel
def _balance(a):
    """Scale rows and columns by powers of two (exact) until their norms are comparable
    (EISPACK's balanc): a becomes D^-1 a D, D = diag(the returned scales). The eigenvalues
    and eigenvectors of a badly scaled matrix -- a monodromy matrix with multipliers 1e6
    and 1e-6 -- are then found to the accuracy of its norm."""
    n = a.shape[0]
    d = np.ones(n)
    done = False
    while not done:
        done = True
        for i in range(n):
            c = r = 0.0
            for j in range(n):
                if j != i:
                    c += abs(a[j, i])
                    r += abs(a[i, j])
            if c == 0.0 or r == 0.0:
                continue
            g, f, s = r / 2.0, 1.0, c + r
            while c < g:
                f *= 2.0
                c *= 4.0
            g = r * 2.0
            while c > g:
                f /= 2.0
                c /= 4.0
            if (c + r) / f < 0.95 * s:
                done = False
                d[i] *= f
                for j in range(n):
                    a[i, j] /= f
                for j in range(n):
                    a[j, i] *= f
    return d


@helper
def _reflect(a, ort, m, h, start):
    """Columns j >= start of a times the Householder reflection 1 - u u^T / h from the
    left, u = ort[m:] in rows m and on."""
    n = a.shape[0]
    for j in range(start, a.shape[1]):
        f = 0.0
        for i in range(n - 1, m - 1, -1):
            f += ort[i] * a[i, j]
        f /= h
        for i in range(m, n):
            a[i, j] -= f * ort[i]


@kernel
def _hessenberg(a):
    """Reduce a to upper Hessenberg form in place by Householder reflections (EISPACK's
    orthes): an orthogonal similarity."""
    n = a.shape[0]
    ort = np.zeros(n)
    for m in range(1, n - 1):
        scale = 0.0
        for i in range(m, n):
            scale += abs(a[i, m - 1])
        if scale == 0.0:
            continue
        h = 0.0
        for i in range(n - 1, m - 1, -1):
            ort[i] = a[i, m - 1] / scale
            h += ort[i] * ort[i]
        g = math.sqrt(h)
        g = -g if ort[m] > 0.0 else g
        h -= ort[m] * g
        ort[m] -= g
        _reflect(a, ort, m, h, m)           # from the left
        _reflect(a.T, ort, m, h, 0)         # and from the right
        a[m, m - 1] = scale * g
        for i in range(m + 1, n):
            a[i, m - 1] = 0.0


@kernel
def _hqr(a, wr, wi):
    """The eigenvalues (wr + i wi) of the upper Hessenberg matrix a (overwritten) by
    Francis's double-shift QR iteration with exceptional shifts (EISPACK's hqr, as in
    Numerical Recipes); a complex pair comes out adjacent, exactly conjugate. False if an
    eigenvalue takes more than 60 iterations."""
    n = a.shape[0]
    anorm = 0.0
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            anorm += abs(a[i, j])
    nn = n - 1
    t = 0.0
    p = q = r = x = y = z = w = 0.0
    while nn >= 0:
        its = 0
        while True:
            l = 0
            for ll in range(nn, 0, -1):
                s = abs(a[ll - 1, ll - 1]) + abs(a[ll, ll])
                if s == 0.0:
                    s = anorm
                if abs(a[ll, ll - 1]) + s == s:
                    a[ll, ll - 1] = 0.0
                    l = ll
                    break
            x = a[nn, nn]
            if l == nn:                     # one root
                wr[nn] = x + t
                wi[nn] = 0.0
                nn -= 1
            else:
                y = a[nn - 1, nn - 1]
                w = a[nn, nn - 1] * a[nn - 1, nn]
                if l == nn - 1:             # two roots
                    p = 0.5 * (y - x)
                    q = p * p + w
                    z = math.sqrt(abs(q))
                    x += t
                    if q >= 0.0:
                        z = p + (z if p >= 0.0 else -z)
                        wr[nn - 1] = wr[nn] = x + z
                        if z != 0.0:
                            wr[nn] = x - w / z
                        wi[nn - 1] = wi[nn] = 0.0
                    else:
                        wr[nn - 1] = wr[nn] = x + p
                        wi[nn - 1] = -z
                        wi[nn] = z
                    nn -= 2
                else:
                    if its == 60:
                        return False
                    if its == 10 or its == 20 or its == 40:     # exceptional shift
                        t += x
                        for i in range(nn + 1):
                            a[i, i] -= x
                        s = abs(a[nn, nn - 1]) + abs(a[nn - 1, nn - 2])
                        x = y = 0.75 * s
                        w = -0.4375 * s * s
                    its += 1
                    m = nn - 2
                    while m >= l:           # two small subdiagonal elements in a row
                        z = a[m, m]
                        r = x - z
                        s = y - z
                        p = (r * s - w) / a[m + 1, m] + a[m, m + 1]
                        q = a[m + 1, m + 1] - z - r - s
                        r = a[m + 2, m + 1]
                        s = abs(p) + abs(q) + abs(r)
                        p /= s
                        q /= s
                        r /= s
                        if m == l:
                            break
                        u = abs(a[m, m - 1]) * (abs(q) + abs(r))
                        v = abs(p) * (abs(a[m - 1, m - 1]) + abs(z) + abs(a[m + 1, m + 1]))
                        if u + v == v:
                            break
                        m -= 1
                    for i in range(m + 2, nn + 1):
                        a[i, i - 2] = 0.0
                        if i != m + 2:
                            a[i, i - 3] = 0.0
                    for k in range(m, nn):  # the double QR step on rows l..nn, columns m..nn
                        if k != m:
                            p = a[k, k - 1]
                            q = a[k + 1, k - 1]
                            r = a[k + 2, k - 1] if k != nn - 1 else 0.0
                            x = abs(p) + abs(q) + abs(r)
                            if x != 0.0:
                                p /= x
                                q /= x
                                r /= x
                        s = math.sqrt(p * p + q * q + r * r)
                        s = -s if p < 0.0 else s
                        if s == 0.0:
                            continue
                        if k == m:
                            if l != m:
                                a[k, k - 1] = -a[k, k - 1]
                        else:
                            a[k, k - 1] = -s * x
                        p += s
                        x = p / s
                        y = q / s
                        z = r / s
                        q /= p
                        r /= p
                        for j in range(k, nn + 1):
                            p = a[k, j] + q * a[k + 1, j]
                            if k != nn - 1:
                                p += r * a[k + 2, j]
                                a[k + 2, j] -= p * z
                            a[k + 1, j] -= p * y
                            a[k, j] -= p * x
                        for i in range(l, min(nn, k + 3) + 1):
                            p = x * a[i, k] + y * a[i, k + 1]
                            if k != nn - 1:
                                p += z * a[i, k + 2]
                                a[i, k + 2] -= p * r
                            a[i, k + 1] -= p * q
                            a[i, k] -= p
            if nn < 0 or l >= nn - 1:
                break
    return True


@kernel
def _eigenvalues(a):
    """(wr, wi, converged, D^-1 a D, D's diagonal) of a square matrix: balanced, reduced
    to Hessenberg form, iterated."""
    b = a.copy()
    d = _balance(b)
    h = b.copy()
    _hessenberg(h)
    n = a.shape[0]
    wr, wi = np.zeros(n), np.zeros(n)
    ok = _hqr(h, wr, wi)
    return wr, wi, ok, b, d


@kernel
def _normalise(x):
    """x scaled to unit length, its largest component real and positive."""
    total, top, at = 0.0, -1.0, 0
    for i in range(x.size):
        mag = x[i].real * x[i].real + x[i].imag * x[i].imag
        total += mag
        if mag > top:
            top, at = mag, i
    phase = x[at].conjugate() / math.sqrt(top)
    scale = 1.0 / math.sqrt(total)
    for i in range(x.size):
        x[i] = x[i] * phase * scale
    x[at] = x[at].real


@kernel
def _unbalance(x, d):
    """The eigenvector D x of a from the eigenvector x of D^-1 a D, normalised."""
    out = np.empty(x.size, dtype=np.complex128)
    for i in range(x.size):
        out[i] = x[i] * d[i]
    _normalise(out)
    return out


@helper
def _orthogonalise(x, known, count):
    """x less its projections on the first `count` (orthonormal) columns of known."""
    for c in range(count):
        proj = 0j
        for i in range(x.size):
            proj += known[i, c].conjugate() * x[i]
        for i in range(x.size):
            x[i] -= proj * known[i, c]


@kernel
def _inverse_iteration(a, lam, known, count):
    """The unit eigenvector of a for the eigenvalue lam by inverse iteration from a fixed
    start, kept orthogonal to the first `count` columns of `known` (the vectors already
    found for the same eigenvalue, so a multiple one gets a basis); its largest component
    real and positive."""
    n = a.shape[0]
    size = 0.0
    for i in range(n):
        for j in range(n):
            size = max(size, abs(a[i, j]))
    floor = EPS * max(size, abs(lam.real) + abs(lam.imag), 1e-300)
    lu = np.empty((n, n), dtype=np.complex128)
    for i in range(n):
        for j in range(n):
            lu[i, j] = a[i, j]
        lu[i, i] -= lam
    piv = np.arange(n)
    for k in range(n):                      # LU with partial pivoting
        best, row = -1.0, k
        for i in range(k, n):
            mag = abs(lu[i, k].real) + abs(lu[i, k].imag)
            if mag > best:
                best, row = mag, i
        if row != k:
            for j in range(n):
                lu[k, j], lu[row, j] = lu[row, j], lu[k, j]
            piv[k], piv[row] = piv[row], piv[k]
        if abs(lu[k, k].real) + abs(lu[k, k].imag) < floor:
            lu[k, k] = floor                # singular: lam is an eigenvalue to rounding
        for i in range(k + 1, n):
            f = lu[i, k] / lu[k, k]
            lu[i, k] = f
            for j in range(k + 1, n):
                lu[i, j] -= f * lu[k, j]
    x = np.empty(n, dtype=np.complex128)
    for i in range(n):                      # a start no eigenvector is orthogonal to
        x[i] = ((i * 7919) % 101 + 1) / 102.0
    y = np.empty(n, dtype=np.complex128)
    for _ in range(3):
        _orthogonalise(x, known, count)
        for i in range(n):
            y[i] = x[piv[i]]
        for i in range(n):
            for j in range(i):
                y[i] -= lu[i, j] * y[j]
        for i in range(n - 1, -1, -1):
            for j in range(i + 1, n):
                y[i] -= lu[i, j] * y[j]
            y[i] /= lu[i, i]
        big = 0.0
        for i in range(n):
            big = max(big, abs(y[i].real) + abs(y[i].imag))
        for i in range(n):
            x[i] = y[i] / big
    _orthogonalise(x, known, count)
    _normalise(x)
    return x


def _spectrum(a):
    wr, wi, ok, b, d = _eigenvalues(np.ascontiguousarray(a, dtype=np.float64))
    if not ok:
        raise np.linalg.LinAlgError("the QR iteration for the eigenvalues did not converge")
    return wr + 1j * wi, b, d


def eigvals(a) -> np.ndarray:
    """The eigenvalues of a real square matrix (complex), a conjugate pair adjacent (the
    lower first)."""
    return _spectrum(a)[0]


def eig(a):
    """(eigenvalues, eigenvectors): np.linalg.eig of a real square matrix, in another
    order (a conjugate pair adjacent, the lower first, with conjugate vectors). Each vector
    has unit length, its largest component real and positive; a multiple eigenvalue (equal
    to 1e-10 of the balanced matrix's largest entry) gets independent vectors. By inverse
    iteration on the balanced matrix: accurate in every component of a badly scaled one."""
    lam, b, d = _spectrum(a)
    n = lam.size
    bal = np.zeros((n, n), dtype=np.complex128)        # the vectors of D^-1 a D
    vec = np.zeros((n, n), dtype=np.complex128)
    near = 1e-10 * max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
    for j in range(n):
        if lam[j].imag < 0:                 # hqr's pairs: (x - iy, x + iy) at (j, j + 1)
            continue
        same = [k for k in range(j) if abs(lam[k].real - lam[j].real) <= near
                and abs(lam[k].imag - lam[j].imag) <= near]
        bal[:, j] = _inverse_iteration(b, complex(lam[j]), np.ascontiguousarray(bal[:, same]),
                                       len(same))
        vec[:, j] = _unbalance(bal[:, j], d)
        if j > 0 and lam[j].imag > 0:
            bal[:, j - 1], vec[:, j - 1] = np.conj(bal[:, j]), np.conj(vec[:, j])
    return lam, vec


def modulus(z) -> np.ndarray:
    """|z| elementwise as sqrt(re^2 + im^2) (numpy's complex abs is a SIMD hypot on some
    CPUs)."""
    z = np.asarray(z)
    return np.sqrt(z.real * z.real + z.imag * z.imag)


def argument(z) -> np.ndarray:
    """The angle of z elementwise, in (-pi, pi] (portable atan2)."""
    z = np.asarray(z)
    return vatan2(z.imag, z.real)


@kernel
def symmetric_eigen(A):
    """Eigenvalues (ascending) and orthonormal eigenvectors (columns) of a symmetric
    matrix by cyclic Jacobi rotations (Golub & Van Loan, Alg. 8.5.3): a fixed sequence of
    IEEE operations, so every machine gets the same bits -- LAPACK's eigh does not."""
    n = A.shape[0]
    a = A.copy()
    V = np.eye(n)
    for _ in range(100):
        off, total = 0.0, 0.0
        for p in range(n):
            for q in range(n):
                total += a[p, q] * a[p, q]
                if p != q:
                    off += a[p, q] * a[p, q]
        if not off > 1e-32 * total:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                c, s = _rotation((a[q, q] - a[p, p]) / (2.0 * apq))
                _rotate_columns(a, p, q, c, s)
                for k in range(n):
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k], a[q, k] = c * apk - s * aqk, s * apk + c * aqk
                a[p, q] = a[q, p] = 0.0
                _rotate_columns(V, p, q, c, s)
    w = np.empty(n)
    for i in range(n):
        w[i] = a[i, i]
    order = ascending(w)
    return w[order], V[:, order]


@helper
def ascending(w):
    """np.argsort(w, kind="stable") (NaN last) by insertion: for the few values of a
    spectrum, where numba's merge sort cost a first run 0.8 s of compiling."""
    order = np.empty(w.size, dtype=np.int64)
    for i in range(w.size):
        j = i
        while j > 0 and (w[i] < w[order[j - 1]] or
                         (math.isnan(w[order[j - 1]]) and not math.isnan(w[i]))):
            order[j] = order[j - 1]
            j -= 1
        order[j] = i
    return order


def orthonormal(rows: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the rows' span by modified Gram-Schmidt (sums in order, so
    the same bits on every CPU, unlike LAPACK's QR); a row whose remainder is below 1e-12
    of the largest row adds nothing."""
    basis, floor = [], 1e-12 * float(np.max(vnorm(rows), initial=0.0))
    for v in rows:
        v = v.copy()
        for q in basis:
            v -= float(vdot(v, q)) * q
        size = float(vnorm(v))
        if size > floor:
            basis.append(v / size)
    return np.array(basis).reshape(-1, rows.shape[-1])
