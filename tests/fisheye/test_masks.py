from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye import CalibrationError, camera_from_dict, load_camera
from fisheye.masks import points_in_masks, points_in_polygon, polygon_area_px2, polygon_problem
from models import DEMO_CAMERA_PATH

SQUARE = [[100.0, 100.0], [300.0, 100.0], [300.0, 300.0], [100.0, 300.0]]
# An L shape: the notch (250, 250) is outside.
L_SHAPE = [[100.0, 100.0], [200.0, 100.0], [200.0, 200.0], [300.0, 200.0], [300.0, 300.0], [100.0, 300.0]]


def demo_record(**fields: Any) -> dict[str, Any]:
    return load_camera(DEMO_CAMERA_PATH).model_dump(mode="json", exclude_none=True) | fields


@pytest.mark.parametrize(
    ("points", "polygon", "expected"),
    [
        (np.zeros((0, 2)), SQUARE, []),
        ([[200.0, 200.0], [50.0, 200.0], [350.0, 200.0], [200.0, 50.0]], SQUARE, [True, False, False, False]),
        ([[150.0, 150.0], [250.0, 150.0], [250.0, 250.0], [150.0, 250.0]], L_SHAPE,
         [True, False, True, True]),
        ([[np.nan, 200.0]], SQUARE, [False]),
    ],
)
def test_points_in_polygon_table(points: Any, polygon: Any, expected: list[bool]) -> None:
    assert points_in_polygon(points, polygon).tolist() == expected


def test_points_in_any_of_several_masks() -> None:
    far = [[1000.0, 1000.0], [1100.0, 1000.0], [1050.0, 1100.0]]
    inside = points_in_masks([[200.0, 200.0], [1050.0, 1030.0], [600.0, 600.0]], [SQUARE, far])
    assert inside.tolist() == [True, True, False]
    assert points_in_masks([[200.0, 200.0]], []).tolist() == [False]


@settings(max_examples=100, deadline=None)
@given(u=st.floats(0, 400), v=st.floats(0, 400))
def test_a_convex_polygon_agrees_with_opencv(u: float, v: float) -> None:
    import cv2

    contour = np.array(L_SHAPE, dtype=np.float32).reshape(-1, 1, 2)
    distance = cv2.pointPolygonTest(contour, (u, v), True)
    if abs(distance) > 1e-3:  # on the outline either answer is right
        assert points_in_polygon([[u, v]], L_SHAPE)[0] == (distance > 0)


@pytest.mark.parametrize(
    ("polygon", "message"),
    [
        ([[0.0, 0.0], [10.0, 0.0]], "at least 3 corners"),
        ([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]], "no area"),
        ([[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [0.0, 10.0]], "repeats the corner"),
        ([[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]], "intersects itself"),  # a bow-tie
        ([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0], [10.0, 0.0], [5.0, -5.0]], "intersects itself"),
        ([[0.0, 0.0], [20.0, 0.0], [10.0, 0.0], [10.0, 10.0]], "intersects itself"),  # doubles back
        ([[0.0, 0.0], [np.inf, 0.0], [0.0, 10.0]], "finite"),
        # found by the OpenAPI fuzz test: corners whose products overflow float64
        ([[1.8e136, 7.1e15], [1.2e293, -2e16], [4.4e16, 2e-308], [-1.5e305, -4.7e15]], "within ±1e+06 px"),
    ],
)
def test_bad_polygons_are_named(polygon: list[list[float]], message: str) -> None:
    problem = polygon_problem(np.array(polygon))
    assert problem is not None and message in problem


@pytest.mark.parametrize("polygon", [SQUARE, L_SHAPE, SQUARE[::-1], [[0.0, 0.0], [5.0, 0.0], [10.0, 0.0],
                                                                     [10.0, 10.0]]])
def test_simple_polygons_pass(polygon: list[list[float]]) -> None:
    assert polygon_problem(np.array(polygon)) is None


def test_area_sign_follows_the_corner_order() -> None:
    assert polygon_area_px2(SQUARE) == 40000.0 and polygon_area_px2(SQUARE[::-1]) == -40000.0


def test_camera_masks_validate_and_mask() -> None:
    camera = camera_from_dict(demo_record(masks_px=[SQUARE, L_SHAPE]))
    assert camera.masked([[200.0, 200.0], [900.0, 900.0]]).tolist() == [True, False]
    assert "masks_px" not in load_camera(DEMO_CAMERA_PATH).model_dump(mode="json", exclude_none=True)


@pytest.mark.parametrize(
    ("masks", "message"),
    [
        ([[[0.0, 0.0], [10.0, 10.0], [10.0, 0.0], [0.0, 10.0]]], "mask 1: the polygon intersects itself"),
        ([SQUARE, [[1.0, 1.0], [2.0, 2.0]]], "mask 2: a polygon needs at least 3 corners"),
        ([[[100.0, 100.0], [2100.0, 100.0], [100.0, 300.0]]], "mask 1: corner 2 .* lies outside the image"),
        ([SQUARE] * 65, "at most 64"),
        ([[[0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [2.0, 0.0, 1.0]]], "masks_px"),
    ],
)
def test_bad_masks_are_refused(masks: Any, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        camera_from_dict(demo_record(masks_px=masks))


def test_masks_scale_with_the_frame_like_the_principal_point() -> None:
    camera = camera_from_dict(demo_record(masks_px=[SQUARE]))
    half = camera.scaled_to((1024, 1024))
    assert half.masks_px is not None
    np.testing.assert_allclose((np.array(half.masks_px[0]) + 0.5) * 2 - 0.5, SQUARE)
    assert half.masked([[100.0, 100.0], [200.0, 200.0]]).tolist() == [True, False]
