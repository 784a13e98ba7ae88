import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye.boxes import (
    box_centers_distance_px,
    cepdof_to_corners,
    cepdof_to_radius_aligned,
    corners_to_cxcywh,
    cxcywh_to_corners,
    foot_points,
    loaf_to_radius_aligned,
    radial_angles_rad,
    radius_aligned_to_cepdof,
)

PP = np.array([500.0, 400.0])


def _cepdof_reference_corners(box: np.ndarray) -> np.ndarray:
    """Corners of a CEPDOF box as the dataset's own drawing code makes them: the box's local corners
    (±w/2, ±h/2) rotated clockwise on screen by the angle (row vector times [[c, s], [−s, c]])."""
    cx, cy, w, h, angle_deg = box
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    rotation = np.array([[c, s], [-s, c]])
    local = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    return np.array([cx, cy]) + local @ rotation


def _loaf_reference(box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A radius-aligned box as LOAF writes it, `[cx, cy, w, h, angle_deg]`, and that box's corners
    drawn LOAF's way: the angle is the centre's polar angle (counter-clockwise, y up) − 90°, or
    − 270° from 180° on; a corner offset (dx, dy) turns into (dx·c + dy·s, −dx·s + dy·c)."""
    cx, cy, w, h = box
    polar = math.degrees(math.atan2(-(cy - PP[1]), cx - PP[0])) % 360.0
    angle = polar - 90.0 if polar < 180.0 else polar - 270.0
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    local = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    turned = np.stack([local[:, 0] * c + local[:, 1] * s, -local[:, 0] * s + local[:, 1] * c], axis=1)
    return np.array([cx, cy, w, h, angle]), np.array([cx, cy]) + turned


def _same_point_set(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    distances = np.linalg.norm(a[:, None] - b[None], axis=2)
    return bool((distances.min(axis=1) < atol).all() and (distances.min(axis=0) < atol).all())


def _random_boxes(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, 1000, (count, 2)), rng.uniform(1, 120, (count, 2))])


@pytest.mark.parametrize(
    ("cxcywh", "expected"),
    [
        (np.zeros((0, 4)), np.zeros((0, 4, 2))),
        # Right of the principal point: radial axis = +u, tangential = +v.
        (np.array([[600.0, 400.0, 20.0, 40.0]]),
         np.array([[[580.0, 390.0], [580.0, 410.0], [620.0, 410.0], [620.0, 390.0]]])),
        # Below it (v down): radial axis = +v, tangential = −u.
        (np.array([[500.0, 500.0, 20.0, 40.0]]),
         np.array([[[510.0, 480.0], [490.0, 480.0], [490.0, 520.0], [510.0, 520.0]]])),
        # Exactly on it: the angle is atan2(0, 0) = 0, so the radial axis is +u as on the right.
        (np.array([[500.0, 400.0, 20.0, 40.0]]),
         np.array([[[480.0, 390.0], [480.0, 410.0], [520.0, 410.0], [520.0, 390.0]]])),
    ],
)
def test_cxcywh_to_corners_table(cxcywh: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(cxcywh_to_corners(cxcywh, PP), expected, atol=1e-9)


@pytest.mark.parametrize("cxcywh", [np.zeros((0, 4)), _random_boxes(1, 0), _random_boxes(100, 1)])
def test_corners_round_trip(cxcywh: np.ndarray) -> None:
    corners = cxcywh_to_corners(cxcywh, PP)
    assert corners.shape == (len(cxcywh), 4, 2)
    np.testing.assert_allclose(corners_to_cxcywh(corners, PP), cxcywh, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(
    cx=st.floats(-2000, 2000), cy=st.floats(-2000, 2000), w=st.floats(0, 500), h=st.floats(0, 500),
)
def test_corners_property(cx: float, cy: float, w: float, h: float) -> None:
    box = np.array([[cx, cy, w, h]])
    corners = cxcywh_to_corners(box, PP)[0]
    np.testing.assert_allclose(corners_to_cxcywh(corners[None], PP), box, atol=1e-6)
    # The first two corners form the side nearest the principal point.
    near = np.linalg.norm((corners[0] + corners[1]) / 2 - PP)
    far = np.linalg.norm((corners[2] + corners[3]) / 2 - PP)
    assert near <= far + 1e-9


def test_corners_to_cxcywh_refuses_bad_shapes() -> None:
    with pytest.raises(ValueError, match="corners_xy"):
        corners_to_cxcywh(np.zeros((2, 3, 2)), PP)


@pytest.mark.parametrize(
    ("cxcywh", "expected"),
    [
        (np.zeros((0, 4)), np.zeros((0, 2))),
        (np.array([[600.0, 400.0, 20.0, 40.0]]), np.array([[580.0, 400.0]])),
        (np.array([[500.0, 300.0, 20.0, 40.0]]), np.array([[500.0, 320.0]])),
        (np.array([[530.0, 440.0, 10.0, 20.0]]), np.array([[524.0, 432.0]])),
        # The principal point lies within h/2 of the centre: the person stands below the lens.
        (np.array([[510.0, 400.0, 20.0, 40.0]]), PP[None]),
        (np.array([[520.0, 400.0, 20.0, 40.0]]), PP[None]),
        (np.array([[500.0, 400.0, 20.0, 40.0]]), PP[None]),
        (np.array([[500.0, 400.0, 0.0, 0.0]]), PP[None]),
        (np.array([[np.nan, 400.0, 20.0, 40.0]]), np.array([[np.nan, np.nan]])),
    ],
)
def test_foot_points_table(cxcywh: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(foot_points(cxcywh, PP), expected, atol=1e-9)


def test_foot_point_is_the_box_point_nearest_the_principal_point() -> None:
    boxes = _random_boxes(200, 2)
    feet = foot_points(boxes, PP)
    corners = cxcywh_to_corners(boxes, PP)
    # Sample each box densely and compare the nearest sample with the foot point.
    s = np.linspace(0, 1, 201)
    u, v = np.meshgrid(s, s)
    weights = np.stack([(1 - u) * (1 - v), (1 - u) * v, u * v, u * (1 - v)], axis=-1).reshape(-1, 4)
    for box, foot, quad in zip(boxes, feet, corners, strict=True):
        samples = weights @ quad
        nearest = samples[np.argmin(np.linalg.norm(samples - PP, axis=1))]
        step = max(box[2], box[3]) / 200
        assert np.linalg.norm(nearest - foot) <= step + 1e-9


@pytest.mark.parametrize("wh", [(0.0, 0.0), (20.0, 40.0), (40.0, 20.0), (1e-9, 1e-9), (300.0, 600.0)])
def test_foot_point_of_a_box_centred_on_the_principal_point_is_the_principal_point(
    wh: tuple[float, float],
) -> None:
    boxes = np.array([[*PP, *wh], [600.0, 400.0, *wh]])
    feet = foot_points(boxes, PP)
    np.testing.assert_array_equal(feet[0], PP)
    # The box beside it keeps the midpoint of its near side (or the principal point once it holds it).
    np.testing.assert_allclose(feet[1], PP if wh[1] / 2 >= 100 else [600.0 - wh[1] / 2, 400.0])


def test_foot_points_do_not_mutate() -> None:
    boxes = _random_boxes(5, 3)
    copy = boxes.copy()
    foot_points(boxes, PP)
    cxcywh_to_corners(boxes, PP)
    np.testing.assert_array_equal(boxes, copy)


@pytest.mark.parametrize(
    ("centers", "expected_deg"),
    [
        (np.zeros((0, 2)), np.zeros(0)),
        (np.array([[600.0, 400.0], [500.0, 500.0], [400.0, 400.0], [500.0, 300.0]]),
         np.array([0.0, 90.0, 180.0, -90.0])),
    ],
)
def test_radial_angles_table(centers: np.ndarray, expected_deg: np.ndarray) -> None:
    np.testing.assert_allclose(np.degrees(radial_angles_rad(centers, PP)), expected_deg, atol=1e-12)


def test_box_centers_distance() -> None:
    np.testing.assert_allclose(box_centers_distance_px([[503.0, 404.0, 1, 1]], PP), [5.0])
    assert box_centers_distance_px(np.zeros((0, 4)), PP).shape == (0,)


def test_cepdof_corners_follow_the_dataset_convention() -> None:
    rng = np.random.default_rng(4)
    boxes = np.column_stack([_random_boxes(100, 5), rng.uniform(-90, 90, 100)])
    corners = cepdof_to_corners(boxes)
    for box, quad in zip(boxes, corners, strict=True):
        assert _same_point_set(quad, _cepdof_reference_corners(box), atol=1e-9)
    assert cepdof_to_corners(np.zeros((0, 5))).shape == (0, 4, 2)


@pytest.mark.parametrize("cxcywh", [np.zeros((0, 4)), _random_boxes(300, 6)])
def test_radius_aligned_cepdof_round_trip(cxcywh: np.ndarray) -> None:
    cepdof = radius_aligned_to_cepdof(cxcywh, PP)
    assert cepdof.shape == (len(cxcywh), 5)
    assert (cepdof[:, 2] <= cepdof[:, 3]).all()
    assert ((cepdof[:, 4] >= -90) & (cepdof[:, 4] < 90)).all()
    np.testing.assert_allclose(cepdof_to_radius_aligned(cepdof, PP), cxcywh, atol=1e-9)
    # The same rectangle in both conventions.
    for quad, box in zip(cxcywh_to_corners(cxcywh, PP), cepdof, strict=True):
        assert _same_point_set(quad, _cepdof_reference_corners(box), atol=1e-7)


@pytest.mark.parametrize(
    ("cepdof", "expected"),
    [
        (np.zeros((0, 5)), np.zeros((0, 4))),
        # Right of the principal point the ray is horizontal: CEPDOF's long axis at 90° lies on it.
        (np.array([[600.0, 400.0, 20.0, 40.0, 90.0]]), np.array([[600.0, 400.0, 20.0, 40.0]])),
        (np.array([[600.0, 400.0, 20.0, 40.0, -90.0]]), np.array([[600.0, 400.0, 20.0, 40.0]])),
        # Long axis upright while the ray is horizontal: the long side is tangential.
        (np.array([[600.0, 400.0, 20.0, 40.0, 0.0]]), np.array([[600.0, 400.0, 40.0, 20.0]])),
        # Slightly off the ray (annotators are not exact): centre and sides are kept.
        (np.array([[600.0, 400.0, 20.0, 40.0, 80.0]]), np.array([[600.0, 400.0, 20.0, 40.0]])),
        # Above the principal point the ray is vertical: angle 0 is radial.
        (np.array([[500.0, 300.0, 20.0, 40.0, 0.0]]), np.array([[500.0, 300.0, 20.0, 40.0]])),
    ],
)
def test_cepdof_to_radius_aligned_table(cepdof: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(cepdof_to_radius_aligned(cepdof, PP), expected, atol=1e-9)


@pytest.mark.parametrize(
    ("loaf", "expected"),
    [
        (np.zeros((0, 5)), np.zeros((0, 4))),
        # Above the principal point the ray is vertical: angle 0 is radial.
        (np.array([[500.0, 300.0, 20.0, 40.0, 0.0]]), np.array([[500.0, 300.0, 20.0, 40.0]])),
        # Right of it the ray is horizontal: −90 turns h onto it.
        (np.array([[600.0, 400.0, 20.0, 40.0, -90.0]]), np.array([[600.0, 400.0, 20.0, 40.0]])),
        # Up-right, −45 is radial (counter-clockwise); CEPDOF's clockwise −45 would lie across it.
        (np.array([[600.0, 300.0, 20.0, 40.0, -45.0]]), np.array([[600.0, 300.0, 20.0, 40.0]])),
        (np.array([[600.0, 300.0, 20.0, 40.0, 45.0]]), np.array([[600.0, 300.0, 40.0, 20.0]])),
        # Down-right, 45 is radial.
        (np.array([[600.0, 500.0, 20.0, 40.0, 45.0]]), np.array([[600.0, 500.0, 20.0, 40.0]])),
        # On the principal point the ray is +u (angle 0): −90 is radial there.
        (np.array([[500.0, 400.0, 20.0, 40.0, -90.0]]), np.array([[500.0, 400.0, 20.0, 40.0]])),
    ],
)
def test_loaf_to_radius_aligned_table(loaf: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(loaf_to_radius_aligned(loaf, PP), expected, atol=1e-9)


def test_loaf_boxes_of_radius_aligned_boxes_convert_back_and_cover_the_same_rectangle() -> None:
    boxes = _random_boxes(300, 8)
    references = [_loaf_reference(box) for box in boxes]
    loaf = np.array([loaf_box for loaf_box, _ in references])
    assert ((loaf[:, 4] >= -90) & (loaf[:, 4] < 90)).all()
    np.testing.assert_allclose(loaf_to_radius_aligned(loaf, PP), boxes, atol=1e-9)
    for quad, (_, reference) in zip(cxcywh_to_corners(boxes, PP), references, strict=True):
        assert _same_point_set(quad, reference, atol=1e-7)


def test_cepdof_boxes_around_the_principal_point_convert() -> None:
    boxes = np.array([[500.0, 400.0, 30.0, 60.0, 10.0], [501.0, 400.0, 30.0, 60.0, 0.0]])
    radius_aligned = cepdof_to_radius_aligned(boxes, PP)
    assert np.isfinite(radius_aligned).all()
    np.testing.assert_allclose(radius_aligned[:, 2] * radius_aligned[:, 3], boxes[:, 2] * boxes[:, 3])
    np.testing.assert_allclose(foot_points(radius_aligned, PP), [PP, PP])


@pytest.mark.parametrize(
    ("function", "bad"),
    [(cxcywh_to_corners, np.zeros((2, 5))), (foot_points, np.zeros((4,))),
     (cepdof_to_radius_aligned, np.zeros((2, 4))), (loaf_to_radius_aligned, np.zeros((2, 4)))],
)
def test_wrong_box_shapes_are_refused(function: object, bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="must have shape"):
        function(bad, PP)  # type: ignore[operator]
