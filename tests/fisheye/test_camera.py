import math
import re
from typing import Any

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye import CalibrationError, FisheyeCamera, FloorPoints, camera_from_dict, load_camera
from models import DEMO_CAMERA_PATH

BASE: dict[str, Any] = {
    "id": "lobby-1",
    "altitude_m": 3.2,
    "image_size": [2952, 2952],
    "principal_point": [1476.0, 1470.5],
    "focal_px": [940.0, 936.0],
    "kb": [1.0, -0.02, 0.001],
}
CAMERA = camera_from_dict(BASE)
# OpenCV camera frame (x right, y down, z forward) = floor frame (x, -y, -z).
TO_OPENCV = np.array([1.0, -1.0, -1.0])


def _random_opencv_cameras(count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, FisheyeCamera]]:
    rng = np.random.default_rng(seed)
    cameras = []
    while len(cameras) < count:
        f = rng.uniform(300, 1200)
        u0, v0 = rng.uniform(900, 1100, 2)
        K = np.array([[f, 0, u0], [0, f * rng.uniform(0.95, 1.05), v0], [0, 0, 1.0]])
        D = rng.uniform(-0.05, 0.05, 4) * np.array([1.0, 0.3, 0.1, 0.03])
        try:
            camera = camera_from_dict({
                "id": "cv", "altitude_m": 3.0, "image_size": [2048, 2048],
                "principal_point": [K[0, 2], K[1, 2]], "focal_px": [K[0, 0], K[1, 1]],
                "kb": [1.0, *D.tolist()],
            })
        except CalibrationError:
            continue  # r(θ) turns back before 90°: not a camera FishLoc accepts
        cameras.append((K, D, camera))
    return cameras


def _random_rays(count: int, theta_max_deg: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    theta = rng.uniform(0, math.radians(theta_max_deg), count)
    phi = rng.uniform(-math.pi, math.pi, count)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], axis=1)


def test_rays_to_pixels_agrees_with_opencv_project_points() -> None:
    worst = 0.0
    for K, D, camera in _random_opencv_cameras(20, seed=1):
        rays = _random_rays(500, 89.0, seed=2)
        points = (rays * TO_OPENCV)[:, None, :]
        expected = cv2.fisheye.projectPoints(points, np.zeros(3), np.zeros(3), K, D)[0]
        worst = max(worst, float(np.abs(camera.rays_to_pixels(rays) - expected[:, 0]).max()))
    assert worst < 1e-6


def test_pixels_to_rays_agrees_with_opencv_undistort_points() -> None:
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    worst = 0.0
    for K, D, camera in _random_opencv_cameras(100, seed=11):
        uv = camera.rays_to_pixels(_random_rays(500, 85.0, seed=13))
        # OpenCV clamps the distorted angle at π/2; compare where it does not.
        x_norm = (uv[:, 0] - K[0, 2]) / K[0, 0]
        y_norm = (uv[:, 1] - K[1, 2]) / K[1, 1]
        uv = uv[np.hypot(x_norm, y_norm) < math.pi / 2 - 1e-3]
        undistorted = cv2.fisheye.undistortPoints(uv[:, None, :], K, D, criteria=criteria)[:, 0]
        # OpenCV marks the points its own Newton iteration fails on with -1e6; ours has a fallback.
        solved = (undistorted > -1e5).all(axis=1)
        assert solved.mean() > 0.99
        uv, undistorted = uv[solved], undistorted[solved]
        opencv_rays = np.concatenate([undistorted, np.ones((len(uv), 1))], axis=1) * TO_OPENCV
        ours = camera.pixels_to_rays(uv)
        # Both rays, projected with the same (OpenCV-verified) model, land on the same pixel.
        ours_px, opencv_px = camera.rays_to_pixels(ours), camera.rays_to_pixels(opencv_rays)
        worst = max(worst, float(np.abs(ours_px - opencv_px).max()), float(np.abs(ours_px - uv).max()))
    assert worst < 1e-6


@pytest.mark.parametrize("camera", [CAMERA, load_camera(DEMO_CAMERA_PATH)], ids=["lobby", "demo"])
def test_floor_round_trip_within_a_millimetre_up_to_85_degrees(camera: FisheyeCamera) -> None:
    rng = np.random.default_rng(5)
    distance = camera.altitude_m * np.tan(np.radians(rng.uniform(0, 85, 2000)))
    phi = rng.uniform(-math.pi, math.pi, 2000)
    xy = np.stack([distance * np.cos(phi), distance * np.sin(phi)], axis=1)
    back = camera.floor_positions(camera.floor_to_pixels(xy))
    assert back.valid.all()
    assert np.max(np.hypot(*(back.xy_m - xy).T)) < 1e-3
    np.testing.assert_allclose(back.distance_m, distance, atol=1e-3)


@settings(max_examples=200, deadline=None)
@given(u=st.floats(0, 2951), v=st.floats(0, 2951))
def test_pixels_rays_pixels_property(u: float, v: float) -> None:
    uv = np.array([[u, v]])
    rays = CAMERA.pixels_to_rays(uv)
    if np.isnan(rays).any():  # outside the image circle
        radius = math.hypot((u - 1476.0) / 940.0, (v - 1470.5) / 936.0)
        assert radius > CAMERA.image_circle_radius_px() / 940.0
        return
    assert np.linalg.norm(rays[0]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(CAMERA.rays_to_pixels(rays), uv, atol=1e-6)


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-30, 30), y=st.floats(-30, 30))
def test_floor_pixels_floor_property(x: float, y: float) -> None:
    xy = np.array([[x, y]])
    uv = CAMERA.floor_to_pixels(xy)
    np.testing.assert_allclose(CAMERA.pixels_to_floor(uv), xy, atol=1e-6)
    # The floor frame's y points to the image top: north of the nadir is above the principal point.
    if y > 1e-6:
        assert uv[0, 1] < CAMERA.principal_point[1]
    if x > 1e-6:
        assert uv[0, 0] > CAMERA.principal_point[0]


@pytest.mark.parametrize(
    ("method", "points", "out_shape"),
    [
        ("pixels_to_floor", np.zeros((0, 2)), (0, 2)),
        ("pixels_to_floor", [], (0, 2)),
        ("pixels_to_rays", np.zeros((0, 2)), (0, 3)),
        ("rays_to_pixels", np.zeros((0, 3)), (0, 2)),
        ("floor_to_pixels", np.zeros((0, 2)), (0, 2)),
        ("world_to_pixels", np.zeros((0, 3)), (0, 2)),
        ("pixels_to_floor", [[1476.0, 1470.5]], (1, 2)),
        ("world_to_pixels", [[1.0, 2.0, 0.5]], (1, 2)),
    ],
)
def test_conversion_shapes_table(method: str, points: Any, out_shape: tuple[int, int]) -> None:
    assert getattr(CAMERA, method)(points).shape == out_shape


def test_empty_floor_positions() -> None:
    floor = CAMERA.floor_positions(np.zeros((0, 2)))
    assert floor.xy_m.shape == (0, 2) and floor.distance_m.shape == (0,) and floor.valid.shape == (0,)


@pytest.mark.parametrize("bad", [np.zeros((3,)), np.zeros((2, 3)), np.zeros((1, 2, 2))])
def test_wrong_shapes_are_refused(bad: np.ndarray) -> None:
    with pytest.raises(ValueError, match="uv_px"):
        CAMERA.pixels_to_floor(bad)


def test_nan_input_gives_nan_and_invalid() -> None:
    uv = np.array([[np.nan, 100.0], [1476.0, 1470.5], [np.inf, 3.0]])
    floor = CAMERA.floor_positions(uv)
    assert floor.valid.tolist() == [False, True, False]
    assert np.isnan(floor.xy_m[[0, 2]]).all() and np.isnan(floor.distance_m[[0, 2]]).all()
    np.testing.assert_allclose(floor.xy_m[1], [0.0, 0.0], atol=1e-12)
    assert np.isnan(CAMERA.pixels_to_rays(uv)[0]).all()
    assert np.isnan(CAMERA.floor_to_pixels([[np.nan, 1.0]])).all()
    assert np.isnan(CAMERA.rays_to_pixels([[np.nan, 0.0, -1.0]])).all()


def test_input_is_not_mutated() -> None:
    uv = np.array([[100.0, 200.0], [1500.0, 1500.0]])
    copy = uv.copy()
    CAMERA.pixels_to_floor(uv)
    CAMERA.floor_to_pixels(uv)
    np.testing.assert_array_equal(uv, copy)


def test_points_past_the_horizon_have_no_floor_position() -> None:
    wide = camera_from_dict({**BASE, "max_theta_deg": 100})
    rays = _random_rays(50, 100.0, seed=6)
    theta = np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), -rays[:, 2]))
    floor = wide.floor_positions(wide.rays_to_pixels(rays))
    past = theta >= 90
    assert past.any() and (~past).any()
    assert not floor.valid[past].any() and np.isnan(floor.xy_m[past]).all()
    assert floor.valid[~past].all() and np.isfinite(floor.xy_m[~past]).all()
    # The rays past the horizon are still pixels of the calibrated field.
    assert np.isfinite(wide.pixels_to_rays(wide.rays_to_pixels(rays))).all()


def test_points_past_max_theta_give_nan() -> None:
    narrow = camera_from_dict({**BASE, "max_theta_deg": 60})
    edge = narrow.altitude_m * math.tan(math.radians(60))
    xy = np.array([[edge * 0.99, 0.0], [edge * 1.01, 0.0], [0.0, -edge * 1.5]])
    uv = narrow.floor_to_pixels(xy)
    assert np.isfinite(uv[0]).all() and np.isnan(uv[1:]).all()
    # Pixels beyond the calibrated circle: NaN, invalid.
    radius = narrow.image_circle_radius_px()
    pixels = np.array(narrow.principal_point) + np.array([[radius * 0.999, 0.0], [radius * 1.001, 0.0]])
    floor = narrow.floor_positions(pixels)
    assert floor.valid.tolist() == [True, False]
    assert np.isnan(floor.xy_m[1]).all()
    assert np.isnan(narrow.pixels_to_rays(pixels[1:])).all()
    # The edge of the field itself round-trips (rounding does not push it out).
    rim = narrow.rays_to_pixels([[math.sin(math.radians(60)), 0.0, -math.cos(math.radians(60))]])
    assert np.isfinite(narrow.pixels_to_rays(rim)).all()


def test_world_to_pixels_matches_floor_to_pixels_and_heights() -> None:
    xy = np.array([[1.0, 2.0], [-3.0, 0.5]])
    np.testing.assert_allclose(CAMERA.world_to_pixels(np.c_[xy, np.zeros(2)]), CAMERA.floor_to_pixels(xy))
    # A head 1.7 m up lies further out in the image than the feet (wider angle from the axis).
    head = CAMERA.world_to_pixels(np.c_[xy, np.full(2, 1.7)])
    feet = CAMERA.floor_to_pixels(xy)
    pp = np.array(CAMERA.principal_point)
    assert (np.hypot(*(head - pp).T) > np.hypot(*(feet - pp).T)).all()
    # Above the lens (θ > 90°, past the default field): NaN.
    assert np.isnan(CAMERA.world_to_pixels([[1.0, 0.0, 4.0]])).all()


@pytest.mark.parametrize("resolution_wh", [(1476, 1476), (1024, 1024), (4096, 4096), (2952, 2952)])
def test_scaled_to_another_resolution(resolution_wh: tuple[int, int]) -> None:
    scaled = CAMERA.scaled_to(resolution_wh)
    scale = resolution_wh[0] / 2952
    assert scaled.image_size == resolution_wh
    xy = np.array([[0.0, 0.0], [2.0, -1.0], [-7.5, 4.0]])
    np.testing.assert_allclose(scaled.floor_to_pixels(xy), (CAMERA.floor_to_pixels(xy) + 0.5) * scale - 0.5,
                               atol=1e-9)
    np.testing.assert_allclose(scaled.pixels_to_floor(scaled.floor_to_pixels(xy)), xy, atol=1e-9)
    assert scaled.image_circle_radius_px() == pytest.approx(CAMERA.image_circle_radius_px() * scale)


def test_scaled_to_same_size_is_the_camera_and_other_aspect_is_refused() -> None:
    assert CAMERA.scaled_to((2952, 2952)) is CAMERA
    with pytest.raises(ValueError, match="aspect ratio"):
        CAMERA.scaled_to((1920, 1080))
    with pytest.raises(ValueError, match="positive"):
        CAMERA.scaled_to((0, 0))


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("kb", [1.0, -0.5], "not strictly increasing"),
        ("kb", [1.0, -0.2, 0.0, 0.0, 0.0], "not strictly increasing"),
        ("kb", [-1.0], "k1"),
        ("kb", [], "kb"),
        ("kb", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0], "kb"),
        ("kb", [1.0, float("nan")], "kb.1"),
        ("kb", [1.0, float("inf")], "kb.1"),
        ("kb", [1.0, 2000.0], "kb coefficients must lie within ±1000"),
        ("kb", [1.0, 0.0, -2000.0], "kb coefficients must lie within ±1000"),
        ("altitude_m", 0.0, "altitude_m"),
        ("altitude_m", -3.2, "altitude_m"),
        ("altitude_m", float("nan"), "altitude_m"),
        ("altitude_m", float("inf"), "altitude_m"),
        ("principal_point", [3000.0, 10.0], "principal_point"),
        ("principal_point", [-1.0, 10.0], "principal_point"),
        ("principal_point", [float("nan"), 10.0], "principal_point"),
        ("focal_px", [0.0, 940.0], "focal_px"),
        ("focal_px", [940.0, float("inf")], "focal_px"),
        ("image_size", [1, 2952], "image_size"),
        ("image_size", [2952], "image_size"),
        ("image_size", [30000, 30000], "image_size must be within [2, 20000] px"),
        ("image_size", [20001, 2952], "image_size must be within [2, 20000] px"),
        ("id", "lobby 1", "id"),
        ("id", "", "id"),
        ("id", "-lobby", "id"),
        ("id", "x" * 65, "id"),
        ("max_theta_deg", 0.0, "max_theta_deg"),
        ("max_theta_deg", 180.0, "max_theta_deg"),
        ("site_pose", {"yaw_deg": 400.0}, "site_pose.yaw_deg"),
        ("lens_model", "kb", "lens_model"),
    ],
)
def test_refused_calibrations_name_the_field(field: str, value: Any, message: str) -> None:
    with pytest.raises(CalibrationError, match=re.escape(message)):
        camera_from_dict({**BASE, field: value})


def test_calibrations_at_the_limits_are_accepted() -> None:
    assert camera_from_dict({**BASE, "kb": [1.0, 1000.0]}).kb == [1.0, 1000.0]
    assert camera_from_dict({**BASE, "image_size": [20000, 20000]}).image_size == (20000, 20000)


def test_monotonicity_is_checked_up_to_max_theta_only() -> None:
    kb = [1.0, -0.5]  # r(θ) peaks at 46.8°
    assert camera_from_dict({**BASE, "kb": kb, "max_theta_deg": 45}).theta_max_deg == 45
    with pytest.raises(CalibrationError, match=r"46\.78°"):
        camera_from_dict({**BASE, "kb": kb, "max_theta_deg": 50})


def test_missing_field_is_named() -> None:
    record = dict(BASE)
    del record["altitude_m"]
    with pytest.raises(CalibrationError, match="altitude_m"):
        camera_from_dict(record)


def test_floor_to_site_uses_the_site_pose() -> None:
    assert CAMERA.floor_to_site([[1.0, 0.0]]) is None
    posed = camera_from_dict({**BASE, "site_pose": {"x_m": 10.0, "y_m": -2.0, "yaw_deg": 90.0}})
    site = posed.floor_to_site([[1.0, 0.0]])
    assert site is not None
    np.testing.assert_allclose(site, [[10.0, -1.0]], atol=1e-12)


def test_camera_is_frozen() -> None:
    with pytest.raises(ValueError, match="frozen"):
        CAMERA.altitude_m = 5.0  # type: ignore[misc]


def test_floor_points_checks_shapes() -> None:
    with pytest.raises(ValueError, match="disagree"):
        FloorPoints(np.zeros((2, 2)), np.zeros(3), np.zeros(2, dtype=bool))
