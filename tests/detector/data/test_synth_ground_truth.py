"""Radius-aligned boxes of silhouettes: they hold every pixel and their h axis lies on the ray."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from detector.data.ground_truth import PersonTruth, people_truth, radius_aligned_box
from fisheye import cxcywh_to_corners

PP = np.array([100.0, 90.0])


def _assert_holds(box: np.ndarray, pixels: np.ndarray, pp: np.ndarray) -> None:
    offset = box[:2] - pp
    radial = offset / np.linalg.norm(offset)
    tangential = np.array([-radial[1], radial[0]])
    r = (pixels - box[:2]) @ radial
    t = (pixels - box[:2]) @ tangential
    assert np.all(np.abs(r) <= box[3] / 2 + 1e-9)
    assert np.all(np.abs(t) <= box[2] / 2 + 1e-9)


@settings(max_examples=60, deadline=None)
@given(
    cx=st.floats(-300, 300), cy=st.floats(-300, 300), angle=st.floats(0, np.pi),
    length=st.floats(2, 60), width=st.floats(1, 25),
)
def test_box_holds_the_silhouette_and_is_radius_aligned(cx, cy, angle, length, width) -> None:
    center = PP + np.array([cx, cy])
    if np.hypot(cx, cy) < 3:
        return
    u, v = np.meshgrid(np.arange(-70, 71), np.arange(-70, 71))
    along = np.cos(angle) * u + np.sin(angle) * v
    across = -np.sin(angle) * u + np.cos(angle) * v
    inside = (np.abs(along) <= length / 2) & (np.abs(across) <= width / 2)
    pixels = np.stack([u[inside], v[inside]], axis=1) + np.round(center)
    if len(pixels) == 0:
        return
    box = radius_aligned_box(pixels.astype(float), PP)
    _assert_holds(box, pixels, PP)
    corners = cxcywh_to_corners(box[None], PP)[0]
    # The near side's and the far side's midpoints lie on the ray through the centre.
    near_mid, far_mid = corners[:2].mean(axis=0), corners[2:].mean(axis=0)
    ray = box[:2] - PP
    for point in (near_mid, far_mid):
        cross = ray[0] * (point - PP)[1] - ray[1] * (point - PP)[0]
        assert abs(cross) <= 1e-6 * np.linalg.norm(ray) * np.linalg.norm(point - PP) + 1e-9


def test_box_of_a_radial_bar_is_tight() -> None:
    # A bar along the ray from the principal point (pixels at v = 90, u in 150..169).
    pixels = np.stack([np.arange(150, 170), np.full(20, 90)], axis=1).astype(float)
    box = radius_aligned_box(pixels, PP)
    np.testing.assert_allclose(box, [159.5, 90.0, 1.0, 20.0], atol=1e-9)


def test_people_truth_from_an_id_image() -> None:
    ids = np.full((50, 60), -1, np.int32)
    ids[10:20, 30:34] = 0
    ids[40:41, 5:6] = 2  # one visible pixel: an ignore region
    truths = people_truth(ids, np.array([40, 7, 10]), np.array([[1.0, 2.0], [0, 0], [3.0, 4.0]]),
                          (25.0, 25.0), min_visible_fraction=0.15, min_visible_px=20)
    assert [t.person for t in truths] == [0, 2]  # person 1 is fully hidden and dropped
    first, last = truths
    assert first.bbox == (29.5, 9.5, 4.0, 10.0)
    assert first.visible_px == 40 and first.visible_fraction == pytest.approx(1.0)
    assert not first.ignore
    assert first.distance_m == pytest.approx(np.hypot(1, 2))
    assert last.visible_fraction == pytest.approx(0.1) and last.ignore


def test_whole_silhouette_boxes_take_in_what_hides_a_person() -> None:
    ids = np.full((50, 60), -1, np.int32)
    ids[10:20, 30:34] = 0  # the visible part of person 0: its lower half hidden behind something
    ids[40:45, 5:9] = 1  # person 1 in the open
    rows, cols = np.mgrid[10:30, 30:34]
    whole = [np.stack([cols.ravel(), rows.ravel()], axis=1).astype(np.float64), np.zeros((0, 2))]
    locations = np.array([[1.0, 2.0], [3.0, 4.0]])
    visible = people_truth(ids, np.array([80, 20]), locations, (25.0, 25.0), 0.15, 10)
    drawn = people_truth(ids, np.array([80, 20]), locations, (25.0, 25.0), 0.15, 10, whole)
    assert visible[0].bbox == (29.5, 9.5, 4.0, 10.0)
    assert drawn[0].bbox == (29.5, 9.5, 4.0, 20.0)  # the hidden half is in the box
    def area(truth: PersonTruth) -> float:
        return truth.rotated_box[2] * truth.rotated_box[3]
    assert area(drawn[0]) > 1.8 * area(visible[0])
    # who counts stays the visible silhouette's decision; a person without whole pixels keeps its box
    assert drawn[0].visible_px == 40 and drawn[0].visible_fraction == pytest.approx(0.5)
    assert drawn[1] == visible[1]
