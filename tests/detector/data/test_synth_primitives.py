"""Ray intersections of the renderer's primitives against closed-form answers."""

import numpy as np
import pytest

from detector.data.primitives import (
    Material,
    make_box,
    make_capsule,
    make_cylinder,
    make_ellipsoid,
)

GREY = Material((0.5, 0.5, 0.5))
DOWN = np.array([[0.0, 0.0, -1.0]])
ORIGIN = np.array([0.0, 0.0, 3.0])


def test_empty_ray_set_gives_empty_answers() -> None:
    box = make_box(np.array([0, 0, 0.5]), np.array([0.5, 0.5, 0.5]), 0.0, GREY)
    t, n = box.intersect(ORIGIN, np.zeros((0, 3)))
    assert t.shape == (0,) and n.shape == (0, 3)


@pytest.mark.parametrize(
    ("prim", "top_z"),
    [
        (make_box(np.array([0, 0, 0.5]), np.array([0.3, 0.2, 0.5]), 0.7, GREY), 1.0),
        (make_ellipsoid(np.array([0, 0, 1.0]), np.array([0.2, 0.3, 0.4]), np.eye(3), GREY), 1.4),
        (make_capsule(np.array([0, 0, 0.2]), np.array([0, 0, 1.2]), 0.1, GREY), 1.3),
        (make_capsule(np.array([-0.5, 0, 1.0]), np.array([0.5, 0, 1.0]), 0.1, GREY), 1.1),
        (make_cylinder(np.array([0, 0, 0.0]), np.array([0, 0, 0.9]), 0.25, GREY), 0.9),
        (make_cylinder(np.array([0, -0.5, 0.3]), np.array([0, 0.5, 0.3]), 0.3, GREY), 0.6),
    ],
)
def test_ray_straight_down_hits_the_top(prim, top_z: float) -> None:
    t, n = prim.intersect(ORIGIN, DOWN)
    assert t[0] == pytest.approx(3.0 - top_z, abs=1e-9)
    np.testing.assert_allclose(n[0], [0, 0, 1], atol=1e-9)


def test_oblique_rays_hit_a_sphere_where_geometry_says() -> None:
    center, radius = np.array([2.0, 1.0, 1.0]), 0.5
    sphere = make_ellipsoid(center, np.full(3, radius), np.eye(3), GREY)
    rng = np.random.default_rng(0)
    targets = center + rng.normal(size=(200, 3)) * 0.4
    rays = targets - ORIGIN
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    t, n = sphere.intersect(ORIGIN, rays)
    # Closed form: |o + t d - c|^2 = r^2.
    oc = ORIGIN - center
    b = rays @ oc
    disc = b * b - (oc @ oc - radius ** 2)
    expected = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    np.testing.assert_allclose(t, expected, atol=1e-9)
    hit = np.isfinite(t)
    points = ORIGIN + t[hit, None] * rays[hit]
    np.testing.assert_allclose(n[hit], (points - center) / radius, atol=1e-9)


def test_misses_are_infinite() -> None:
    sideways = np.array([[1.0, 0.0, 0.0]])
    for prim in (
        make_box(np.array([0, 0, 0.5]), np.array([0.3, 0.2, 0.5]), 0.0, GREY),
        make_capsule(np.array([0, 0, 0.2]), np.array([0, 0, 1.2]), 0.1, GREY),
        make_cylinder(np.array([0, 0, 0.0]), np.array([0, 0, 0.9]), 0.25, GREY),
    ):
        t, _ = prim.intersect(ORIGIN, sideways)
        assert np.isinf(t[0])


def test_shadow_rays_from_many_origins() -> None:
    box = make_box(np.array([0, 0, 1.0]), np.array([0.5, 0.5, 0.1]), 0.0, GREY)
    origins = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.2, -0.3, 0.5]])
    t, _ = box.intersect(origins, np.tile([0.0, 0.0, 1.0], (3, 1)))
    np.testing.assert_allclose(t, [0.9, np.inf, 0.4])
