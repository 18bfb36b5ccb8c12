"""Observables against the paper's triangle identities (Appendices A-D)."""
import numpy as np
import pytest

from survey.physics.families import initial_state, triangle_from_sides
from survey.physics.geometry import (
    area,
    area_magnitude,
    incenter,
    inequities,
    orthocenter,
    perimeter,
    sides,
)
from survey.physics.system import System


@pytest.fixture(params=[2, 3])
def triangles(request):
    rng = np.random.default_rng(request.param)
    return rng.normal(size=(3, 50, request.param))


def test_inequities_give_perimeter_and_heron_area(triangles):
    u, v, w = triangles
    i = inequities(u, v, w)
    P = perimeter(u, v, w)
    assert np.all(i >= 0)
    np.testing.assert_allclose(i.sum(axis=-1), P, rtol=1e-14)
    np.testing.assert_allclose(area_magnitude(u, v, w), 0.25 * np.sqrt(P * i.prod(axis=-1)),
                               rtol=1e-10)
    a, b, c = np.moveaxis(sides(u, v, w), -1, 0)
    np.testing.assert_allclose(a, 0.5 * (i[:, 1] + i[:, 2]), rtol=1e-13)


def test_incenter_is_equidistant_from_the_sides_at_the_inradius(triangles):
    u, v, w = triangles
    ci = incenter(u, v, w)
    r = 2 * area_magnitude(u, v, w) / perimeter(u, v, w)
    for p, q in ((u, v), (v, w), (w, u)):
        e = (q - p) / np.linalg.norm(q - p, axis=-1, keepdims=True)
        x = ci - p
        dist = np.linalg.norm(x - np.sum(x * e, axis=-1, keepdims=True) * e, axis=-1)
        np.testing.assert_allclose(dist, r, rtol=1e-10)


def test_orthocenter_lies_on_all_three_altitudes(triangles):
    u, v, w = triangles
    co = orthocenter(u, v, w)
    scale = np.linalg.norm(co, axis=-1) + 1
    for p, q, r in ((u, v, w), (v, w, u), (w, u, v)):
        np.testing.assert_allclose(np.sum((co - p) * (r - q), axis=-1) / scale ** 2, 0,
                                   atol=1e-10)
    # right triangle: the orthocenter is the right-angle vertex
    np.testing.assert_allclose(orthocenter(np.zeros(2), np.array([1.0, 0]), np.array([0, 1.0])),
                               [0, 0], atol=1e-15)


def test_moment_of_inertia_from_sides_with_unequal_masses():
    m = np.array([1.0, 2.5, 0.7])
    system = System.create(masses=m)
    q = triangle_from_sides(2.9, 2.0, 1.8, m) + np.array([0.3, -1.1])
    y = system.state(q, np.zeros((3, 2)))
    a, b, c = sides(*system.triangle(y))
    expected = (m[1] * m[2] * a ** 2 + m[0] * m[2] * b ** 2 + m[0] * m[1] * c ** 2) / m.sum()
    assert system.moment_of_inertia(y) == pytest.approx(expected, rel=1e-13)
    np.testing.assert_allclose(triangle_from_sides(2.9, 2.0, 1.8, m).T @ m, 0, atol=1e-14)


def test_area_orientation_and_3d_embedding():
    u, v, w = np.array([0.0, 0]), np.array([1.0, 0]), np.array([0.0, 1])
    assert area(u, v, w) == 0.5 and area(u, w, v) == -0.5
    s2, s3 = System.create(), System.create(dim=3)
    y2 = initial_state(s2, "equilateral", delta=3.0)
    y3 = initial_state(s3, "equilateral", delta=3.0)
    np.testing.assert_allclose(s3.angular_momentum(y3), [0, 0, s2.angular_momentum(y2)])
    np.testing.assert_allclose(area(*s3.triangle(y3)), [0, 0, area(*s2.triangle(y2))])
    assert s3.energy(y3) == s2.energy(y2)


def test_degenerate_sides_are_rejected():
    with pytest.raises(ValueError, match="non-degenerate"):
        triangle_from_sides(3.0, 1.0, 2.0)
