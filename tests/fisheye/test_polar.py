"""The polar unwrap: point maps, box conversions and sampling, against independent constructions."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye import foot_points
from fisheye.polar import PolarGrid, unwrap_with_maps

GRID = PolarGrid(principal_point=(511.5, 500.0), radius_px=480.0, height=96, width=384, overlap=32)


@pytest.mark.parametrize("points", [np.zeros((0, 2)), np.array([[0.0, 0.0], [383.0, 95.0], [100.2, 40.7]])])
def test_strip_frame_round_trip(points: np.ndarray) -> None:
    back = GRID.frame_to_strip(GRID.strip_to_frame(points))
    assert back.shape == points.shape
    np.testing.assert_allclose(back, points, atol=1e-9)


def test_strip_rows_and_columns_by_formula() -> None:
    # Top edge is the outer radius, bottom edge the principal point; column 0's centre is half a
    # column past the start angle, and angles grow clockwise on screen (v down).
    uv = GRID.strip_to_frame(np.array([[-0.5, -0.5], [0.0, 95.5]]))
    np.testing.assert_allclose(uv[0], [511.5 + 480.0, 500.0], atol=1e-9)
    np.testing.assert_allclose(uv[1], GRID.principal_point, atol=1e-9)
    quarter = GRID.strip_to_frame(np.array([[384 / 4 - 0.5, -0.5]]))[0]
    np.testing.assert_allclose(quarter, [511.5, 500.0 + 480.0], atol=1e-9)


def test_overlap_columns_repeat_the_first_ones() -> None:
    first = GRID.strip_to_frame(np.array([[3.0, 10.0]]))
    repeated = GRID.strip_to_frame(np.array([[3.0 + GRID.width, 10.0]]))
    np.testing.assert_allclose(first, repeated, atol=1e-9)
    assert GRID.strip_wh == (416, 96)


@pytest.mark.parametrize("boxes", [np.zeros((0, 4)), np.array([[100.0, 20.0, 130.0, 60.0],
                                                             [10.0, 0.0, 12.0, 95.0],
                                                             [370.0, 50.0, 400.0, 90.0]])])
def test_polar_boxes_round_trip(boxes: np.ndarray) -> None:
    ra = GRID.polar_to_radius_aligned(boxes)
    back = GRID.radius_aligned_to_polar(ra)
    assert back.shape == boxes.shape
    # Columns come back in the first turn: compare angles modulo a turn.
    shift = np.round((boxes[:, 0] - back[:, 0]) / GRID.width) * GRID.width
    np.testing.assert_allclose(back + shift[:, None] * np.array([1, 0, 1, 0]), boxes, atol=1e-7)


@settings(max_examples=200, deadline=None)
@given(x1=st.floats(0, 380), width=st.floats(0.5, 60), y1=st.floats(-0.5, 80), height=st.floats(1, 40))
def test_radius_aligned_box_sits_on_the_segments_middle(x1: float, width: float, y1: float,
                                                       height: float) -> None:
    y2 = min(y1 + height, 95.0)
    box = np.array([[x1, y1, x1 + width, y2]])
    ra = GRID.polar_to_radius_aligned(box)
    # Its centre is the strip box's centre mapped to the frame (middle ray, middle radius), it is
    # as long as the segment and as wide as the segment's arc through its centre.
    centre = GRID.strip_to_frame(np.array([[(box[0, 0] + box[0, 2]) / 2, (y1 + y2) / 2]]))[0]
    np.testing.assert_allclose(ra[0, :2], centre, atol=1e-9)
    middle = np.hypot(*(centre - np.array(GRID.principal_point)))
    assert ra[0, 3] == pytest.approx((y2 - y1) * GRID.radius_px / GRID.height)
    assert ra[0, 2] == pytest.approx(width * 2 * math.pi / GRID.width * middle)
    # The inner corners of the box lie on the segment's inner arc's chord side: the foot point of
    # the box is the middle of the inner arc.
    foot = foot_points(ra, GRID.principal_point)[0]
    expected = GRID.strip_to_frame(np.array([[(box[0, 0] + box[0, 2]) / 2, y2]]))[0]
    np.testing.assert_allclose(foot, expected, atol=1e-6)


def test_a_segment_wider_than_half_a_turn_is_the_square_about_the_principal_point() -> None:
    ra = GRID.polar_to_radius_aligned(np.array([[0.0, 48.0, 250.0, 95.5]]))[0]
    np.testing.assert_allclose(ra[:2], GRID.principal_point, atol=1e-9)
    outer = GRID.row_to_radius_px(48.0)
    np.testing.assert_allclose(ra[2:], [2 * outer, 2 * outer])


def test_box_over_the_principal_point_becomes_the_whole_turn() -> None:
    polar = GRID.radius_aligned_to_polar(np.array([[511.5, 505.0, 40.0, 60.0]]))[0]
    assert polar[0] == -0.5 and polar[2] == GRID.width - 0.5
    assert polar[3] == pytest.approx(GRID.height - 0.5)


def test_unwrap_samples_the_frame_where_the_maps_say() -> None:
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 255, (1000, 1024, 3), dtype=np.uint8)
    frame = cv2.GaussianBlur(frame, (0, 0), 6)  # smooth, so bilinear sampling is near the truth
    strip = GRID.unwrap(frame)
    assert strip.shape == (96, 416, 3)
    for x, y in [(5, 5), (200, 50), (400, 80)]:
        u, v = GRID.strip_to_frame(np.array([[x, y]], dtype=np.float64))[0]
        assert np.abs(strip[y, x].astype(int) - frame[round(v), round(u)].astype(int)).max() <= 6
    # A frame decoded at half scale gives (nearly) the same strip.
    half = cv2.resize(frame, (512, 500), interpolation=cv2.INTER_AREA)
    strip_half = GRID.unwrap(half, scale_xy=(0.5, 0.5))
    assert np.abs(strip_half.astype(int) - strip.astype(int)).mean() < 3


@pytest.mark.parametrize("workers", [2, 3, 7])
@pytest.mark.parametrize("fixed_point", [False, True])
@pytest.mark.parametrize("channels", [1, 3])
def test_a_split_unwrap_is_the_same_pixels_as_one_call(workers: int, fixed_point: bool,
                                                      channels: int) -> None:
    rng = np.random.default_rng(1)
    frame = rng.integers(0, 255, (1000, 1024, channels), dtype=np.uint8).squeeze()
    map_u, map_v = GRID.sampling_maps((1.0, 1.0))
    maps = cv2.convertMaps(map_u, map_v, cv2.CV_16SC2) if fixed_point else (map_u, map_v)
    whole = unwrap_with_maps(frame, *maps, border_value=7)
    split = unwrap_with_maps(frame, *maps, border_value=7, workers=workers)
    assert split.shape == whole.shape == (96, 416, *frame.shape[2:])
    assert split.dtype == np.uint8 and np.array_equal(split, whole)
    assert (whole == 7).any()  # the border value reaches the blocks too (the ring passes the frame)


@pytest.mark.parametrize("workers", [3, 4, 7])
def test_an_unwrap_of_as_many_rows_as_workers_or_fewer(workers: int) -> None:
    # no block is left without rows (OpenCV refuses an empty map)
    frame = np.arange(64 * 64 * 3, dtype=np.uint8).reshape(64, 64, 3)
    map_u, map_v = np.meshgrid(np.arange(8, dtype=np.float32), np.arange(3, dtype=np.float32))
    assert np.array_equal(unwrap_with_maps(frame, map_u, map_v, workers=workers), frame[:3, :8])


def test_each_px_of_a_sampled_unwrap_averages_its_samples_spread_over_its_square() -> None:
    samples_u, samples_v = GRID.sampling_maps((1.0, 1.0), samples=2)
    assert samples_u.shape == (192, 832)
    # each px's 2 x 2 samples sit a quarter px either side of its centre
    quarter = GRID.strip_to_frame(np.array([[10 - 0.25, 40 - 0.25], [10 + 0.25, 40 + 0.25]]))
    np.testing.assert_allclose([samples_u[80, 20], samples_v[80, 20]], quarter[0], atol=1e-3)
    np.testing.assert_allclose([samples_u[81, 21], samples_v[81, 21]], quarter[1], atol=1e-3)
    rng = np.random.default_rng(2)
    frame = rng.integers(0, 255, (1000, 1024, 3), dtype=np.uint8)
    sampled = GRID.unwrap(frame, samples=2)
    assert sampled.shape == (96, 416, 3) and sampled.dtype == np.uint8
    by_hand = unwrap_with_maps(frame, samples_u, samples_v).astype(np.float64)
    mean = by_hand.reshape(96, 2, 416, 2, 3).mean(axis=(1, 3))
    assert np.abs(sampled - mean).max() <= 1  # cv2's area mean rounds
    # at the rim a px spans ~7 frame px across the ray: on noise the one-sample unwrap keeps the
    # frame's spread, the averaged one loses most of it (what a downscale does)
    assert sampled[:10].std() < 0.8 * GRID.unwrap(frame)[:10].std()


@pytest.mark.parametrize("kwargs", [dict(height=0), dict(width=0), dict(overlap=-1),
                                    dict(overlap=500), dict(radius_px=0.0), dict(radius_px=math.nan)])
def test_invalid_grids_are_refused(kwargs: dict[str, float]) -> None:
    base = dict(principal_point=(10.0, 10.0), radius_px=10.0, height=8, width=32, overlap=0)
    with pytest.raises(ValueError):
        PolarGrid(**{**base, **kwargs})  # type: ignore[arg-type]


RING_PIECE = PolarGrid(principal_point=(511.5, 500.0), radius_px=480.0, height=64, width=768, overlap=32,
                       start_rad=math.pi / 2, inner_radius_px=200.0, span=256)


@pytest.mark.parametrize("points", [np.zeros((0, 2)), np.array([[0.0, 0.0], [255.0, 63.0], [100.2, 40.7]])])
def test_ring_piece_round_trip(points: np.ndarray) -> None:
    # A piece of a ring: its columns are the turn's from start_rad, its rows the ring's radii.
    back = RING_PIECE.frame_to_strip(RING_PIECE.strip_to_frame(points))
    assert back.shape == points.shape
    np.testing.assert_allclose(back, points, atol=1e-9)


def test_ring_piece_edges_by_formula() -> None:
    uv = RING_PIECE.strip_to_frame(np.array([[-0.5, -0.5], [-0.5, 63.5]]))
    # Column -0.5 is the start angle (a quarter turn: straight down on screen); the top edge the
    # outer radius, the bottom edge the inner one.
    np.testing.assert_allclose(uv[0], [511.5, 500.0 + 480.0], atol=1e-9)
    np.testing.assert_allclose(uv[1], [511.5, 500.0 + 200.0], atol=1e-9)
    assert RING_PIECE.strip_wh == (256 + 32, 64)
    assert RING_PIECE.px_per_radius_px == pytest.approx(64 / 280.0)


def test_ring_piece_boxes_round_trip() -> None:
    strip = np.array([[10.0, 5.0, 40.0, 50.0], [100.0, 0.0, 130.0, 30.0]])
    frame = RING_PIECE.polar_to_radius_aligned(strip)
    np.testing.assert_allclose(RING_PIECE.radius_aligned_to_polar(frame), strip, atol=1e-6)


@pytest.mark.parametrize(("field", "value"), [("inner_radius_px", 480.0), ("inner_radius_px", -1.0),
                                              ("span", 769), ("span", -1)])
def test_ring_piece_refuses_bad_geometry(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=field):
        PolarGrid(principal_point=(0.0, 0.0), radius_px=480.0, height=64, width=768,
                  **{field: value})  # type: ignore[arg-type]
