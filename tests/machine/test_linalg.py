"""The portable linear algebra against closed forms: products summed in order, singular
values and null vectors of matrices built from chosen ones, minimum-norm least squares by
its defining conditions, spectra of matrices similar to known ones (badly scaled, with
complex pairs, multiple eigenvalues and reciprocal pairs of a symplectic map). That every
CPU gets the same bits is checked where it matters, on the periodic families
(tests/pipeline/test_portable_archives.py)."""
import functools

import numpy as np
import pytest

from survey.machine import linalg as L


def orthogonal(n, seed):
    return np.linalg.qr(np.random.default_rng(seed).normal(size=(n, n)))[0]


def test_products_are_summed_in_order():
    rng = np.random.default_rng(1)
    a, b, v = rng.normal(size=(4, 7)), rng.normal(size=(7, 3)), rng.normal(size=7)
    in_order = lambda x, y: functools.reduce(lambda s, k: s + x[k] * y[k], range(x.size), 0.0)
    got = L.dot(a, b)
    assert all(got[i, j] == in_order(a[i], b[:, j]) for i in range(4) for j in range(3))
    assert L.dot(v, v) == in_order(v, v) and L.norm(v) == np.sqrt(in_order(v, v))
    assert L.dot(a, v).shape == (4,) and L.dot(v, b).shape == (3,)
    np.testing.assert_array_equal(L.chain(a.T, a, v), L.dot(L.dot(a.T, a), v))
    with pytest.raises(ValueError, match="do not multiply"):
        L.dot(a, a)


@pytest.mark.parametrize("m, n", [(6, 6), (9, 5), (4, 7), (1, 3), (12, 13)])
def test_svd_finds_the_chosen_singular_values_and_the_null_space(m, n):
    """A = U diag(s) V^T with s spanning 12 decades, the last of min(m, n) > 1 of them
    zero: the singular values come back to 1e-15 of the largest, V is orthogonal, and the
    rows of Vt past the rank are a null space of A (as a continuation's tangent is)."""
    k = min(m, n)
    s = np.logspace(0, -12, k)
    rank = max(k - 1, 1)
    s[rank:] = 0.0
    A = orthogonal(m, m)[:, :k] @ np.diag(s) @ orthogonal(n, n + 100)[:, :k].T
    got, Vt = L.svd(A)
    assert got.shape == (n,) and Vt.shape == (n, n)
    assert np.all(np.diff(got) <= 0)
    np.testing.assert_allclose(got[:k], s, rtol=0, atol=2e-15)
    np.testing.assert_allclose(got[k:], 0.0, atol=2e-15)
    np.testing.assert_allclose(Vt @ Vt.T, np.eye(n), atol=1e-14)
    assert np.max(np.abs(A @ Vt[rank:].T)) <= 2e-15
    assert L.norm2(A) == pytest.approx(1.0, abs=1e-15)


def test_least_squares_is_the_minimum_norm_solution():
    """Rank-deficient and overdetermined: the residual is orthogonal to A's columns (the
    normal equations) and the solution to A's null space (minimum norm); a consistent
    full-rank system is solved to rounding."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 6))
    A[:, 5] = A[:, 0] - 2 * A[:, 3]                  # rank 5
    b = rng.normal(size=9)
    x = L.lstsq(A, b, 1e-14)
    assert np.max(np.abs(A.T @ (A @ x - b))) <= 1e-13
    null = np.array([1.0, 0, 0, -2.0, 0, -1.0]) / np.sqrt(6.0)
    assert abs(null @ x) <= 1e-14
    B = rng.normal(size=(7, 7))
    x0 = rng.normal(size=7)
    np.testing.assert_allclose(L.lstsq(B, B @ x0, 1e-14), x0, rtol=0, atol=1e-12)


def similar(blocks, scales, seed):
    """A matrix similar to the block diagonal `blocks` by a badly scaled transform."""
    n = sum(b.shape[0] for b in blocks)
    D = np.zeros((n, n))
    i = 0
    for b in blocks:
        D[i:i + b.shape[0], i:i + b.shape[0]] = b
        i += b.shape[0]
    S = np.diag(scales) @ orthogonal(n, seed)
    return S @ D @ np.linalg.inv(S)


def test_eigenvalues_and_vectors_of_a_badly_scaled_matrix_with_complex_pairs():
    """Blocks [[a, -b], [b, a]] (eigenvalues a +- ib) and real ones, conjugated by a
    transform whose rows are scaled over 8 decades: every eigenvalue to 1e-12 of its
    size, a conjugate pair adjacent and exactly conjugate, each vector of unit length with
    A v = lambda v to rounding in every component (balancing)."""
    blocks = [np.array([[0.3, -2.0], [2.0, 0.3]]), np.array([[-1.5]]),
              np.array([[1e-3, -5.0], [5.0, 1e-3]]), np.array([[7.0]]), np.array([[0.0]])]
    want = np.array([0.3 + 2j, 0.3 - 2j, -1.5, 1e-3 + 5j, 1e-3 - 5j, 7.0, 0.0])
    A = similar(blocks, 10.0 ** np.linspace(-4, 4, 7), 5)
    lam, V = L.eig(A)
    for z in want:
        assert np.min(np.abs(lam - z)) <= 1e-12 * max(abs(z), 1.0), (z, lam)
    for j in np.flatnonzero(lam.imag < 0):
        assert lam[j + 1] == np.conj(lam[j])
        np.testing.assert_array_equal(V[:, j + 1], np.conj(V[:, j]))
    np.testing.assert_allclose(np.linalg.norm(V, axis=0), 1.0, rtol=1e-14)
    scale = np.abs(A) @ np.abs(V) + np.abs(V) * np.abs(lam)      # componentwise
    assert np.max(np.abs(A @ V - V * lam) / scale) <= 1e-12
    np.testing.assert_array_equal(L.eigvals(A), lam)


def test_a_symplectic_maps_multipliers_come_in_reciprocal_pairs():
    """A monodromy-like symplectic matrix -- a hyperbolic pair e^(+-3), a pair on the unit
    circle, an inverse-hyperbolic pair -- conjugated by a shear: the multipliers to 1e-12
    of their size, the small ones of each pair included."""
    r, w = 3.0, 0.7
    hyper = np.array([[np.cosh(r), np.sinh(r)], [np.sinh(r), np.cosh(r)]])
    ellip = np.array([[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]])
    inverse = -np.array([[np.cosh(0.2), np.sinh(0.2)], [np.sinh(0.2), np.cosh(0.2)]])
    M = np.zeros((6, 6))
    for k, b in enumerate((hyper, ellip, inverse)):
        M[2 * k:2 * k + 2, 2 * k:2 * k + 2] = b
    shear = np.eye(6)
    shear[1, 2] = shear[3, 0] = 0.8
    shear[1, 0] = shear[5, 4] = -1.3
    mu = L.eigvals(np.linalg.inv(shear) @ M @ shear)
    want = [np.exp(r), np.exp(-r), np.exp(1j * w), np.exp(-1j * w), -np.exp(0.2),
            -np.exp(-0.2)]
    for z in want:
        assert np.min(np.abs(mu - z)) <= 1e-12 * abs(z), (z, mu)


def test_a_multiple_eigenvalue_gets_independent_vectors():
    """The infinitesimal rotation of three planar vectors (+-2.5i, each three times) and a
    symmetric matrix with a double and a triple eigenvalue: a basis of eigenvectors."""
    R = np.kron(np.eye(3), np.array([[0.0, -2.5], [2.5, 0.0]]))
    Q = orthogonal(5, 9)
    S = Q @ np.diag([2.0, 2.0, 3.0, 3.0, 3.0]) @ Q.T
    for A in (R, S):
        lam, V = L.eig(A)
        assert np.linalg.matrix_rank(V, tol=1e-8) == A.shape[0]
        assert np.max(np.abs(A @ V - V * lam)) <= 1e-14 * np.abs(A).max() * A.shape[0]


@pytest.mark.parametrize("n", [1, 2, 3, 14, 30])
def test_symmetric_eigen_gives_the_closed_form_spectrum_and_an_orthonormal_basis(n):
    """The second-difference matrix (2 on the diagonal, -1 beside it) has eigenvalues
    2 - 2 cos(k pi / (n + 1)); conjugated by a random orthogonal matrix it is a full
    symmetric matrix with the same spectrum. Its eigenvectors are orthonormal and rebuild
    it."""
    T = 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    Q = orthogonal(n, n)
    A = Q @ T @ Q.T
    A = 0.5 * (A + A.T)
    w, V = L.symmetric_eigen(A)
    exact = 2 - 2 * np.cos(np.arange(1, n + 1) * np.pi / (n + 1))
    np.testing.assert_allclose(w, exact, rtol=0, atol=1e-13 * n)
    np.testing.assert_allclose(V.T @ V, np.eye(n), atol=1e-14 * n)
    np.testing.assert_allclose(V @ np.diag(w) @ V.T, A, atol=1e-14 * n)


def test_ascending_orders_as_numpys_stable_sort_with_ties_and_nans():
    """symmetric_eigen's order of its eigenvalues: numpy's stable argsort, NaNs last."""
    from numba import njit
    order = njit(L.ascending.py_func)
    rng = np.random.default_rng(5)
    for n in (0, 1, 2, 7, 30):
        for _ in range(50):
            w = rng.integers(-3, 4, n).astype(float)       # many ties
            w[rng.random(n) < 0.2] = np.nan
            w[rng.random(n) < 0.1] = -0.0
            assert np.array_equal(order(w), np.argsort(w, kind="stable")), w
