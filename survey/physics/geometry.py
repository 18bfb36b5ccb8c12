"""Triangle geometry of vertex arrays (NumPy): sides, perimeter, area, inequities, incenter
and orthocenter.

Functions of triangle vertices u, v, w of shape (..., d); sides follow the paper:
a = |w - v|, b = |u - w|, c = |v - u| (side a is opposite u).
"""
from __future__ import annotations

import numpy as np


def cross(a, b):
    """Cross product; the scalar z-component for 2-D vectors."""
    if np.shape(a)[-1] == 2:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return np.cross(a, b)


def sides(u, v, w):
    """Side lengths (a, b, c), shape (..., 3)."""
    return np.stack([np.linalg.norm(w - v, axis=-1), np.linalg.norm(u - w, axis=-1),
                     np.linalg.norm(v - u, axis=-1)], axis=-1)


def perimeter(u, v, w):
    return sides(u, v, w).sum(axis=-1)


def area(u, v, w):
    """Signed area (2-D, positive when u, v, w turn counter-clockwise) or area vector (3-D),
    A = (v - u) x (w - u) / 2."""
    return 0.5 * cross(v - u, w - u)


def area_magnitude(u, v, w):
    A = area(u, v, w)
    return np.abs(A) if A.ndim == np.ndim(u) - 1 else np.linalg.norm(A, axis=-1)


def inequities(u, v, w):
    """(i_a, i_b, i_c) = (b + c - a, c + a - b, a + b - c), all >= 0; zero on collinear
    configurations (paper Appendix B)."""
    a, b, c = np.moveaxis(sides(u, v, w), -1, 0)
    return np.stack([b + c - a, c + a - b, a + b - c], axis=-1)


def incenter(u, v, w):
    """(a u + b v + c w) / P: where the bisector (perimetric) forces meet."""
    s = sides(u, v, w)
    return (s[..., 0:1] * u + s[..., 1:2] * v + s[..., 2:3] * w) / s.sum(axis=-1, keepdims=True)


def orthocenter(u, v, w):
    """Intersection of the altitudes, where the areal forces meet:
    c_o = v + ((v - u).(v - w)) / (2|A|) Ahat x (w - u). The paper's Appendix D prints
    (u - v).(v - w), which puts a right triangle's orthocenter off its right-angle vertex."""
    pad = (lambda x: np.concatenate([x, np.zeros(x.shape[:-1] + (1,))], axis=-1)) \
        if np.shape(u)[-1] == 2 else (lambda x: np.asarray(x, dtype=float))
    U, V, W = pad(u), pad(v), pad(w)
    A = 0.5 * np.cross(V - U, W - U)
    absA = np.linalg.norm(A, axis=-1, keepdims=True)
    co = V + (np.sum((V - U) * (V - W), axis=-1, keepdims=True) / (2 * absA ** 2)) \
        * np.cross(A, W - U)
    return co[..., :np.shape(u)[-1]]
