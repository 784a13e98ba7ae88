import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from opencv_tilt import camera_record, project_floor, ring_m

from fisheye import CalibrationError, camera_from_dict, load_camera
from fisheye.tilt import floor_to_lens_rays, lens_to_floor_rays, rays_to_floor, tilt_matrix
from models import DEMO_CAMERA_PATH

TILTS = [(2.0, -1.5), (3.0, 0.0), (0.0, -3.0), (-3.0, 3.0), (10.0, 5.0)]


@pytest.mark.parametrize("tilt_deg", TILTS)
def test_floor_to_pixels_agrees_with_opencv_project_points(tilt_deg: tuple[float, float]) -> None:
    camera = camera_from_dict(camera_record(tilt_deg))
    floor = np.concatenate([np.zeros((1, 2)), ring_m(1.0), ring_m(4.0), ring_m(8.0)])
    np.testing.assert_allclose(camera.floor_to_pixels(floor), project_floor(floor, tilt_deg), atol=1e-6)


@pytest.mark.parametrize("tilt_deg", TILTS)
def test_pixels_to_floor_inverts_opencv_project_points(tilt_deg: tuple[float, float]) -> None:
    camera = camera_from_dict(camera_record(tilt_deg))
    floor = np.concatenate([np.zeros((1, 2)), ring_m(2.0), ring_m(8.0), ring_m(12.0)])
    np.testing.assert_allclose(camera.pixels_to_floor(project_floor(floor, tilt_deg)), floor, atol=1e-7)
    distance = camera.floor_positions(project_floor(floor, tilt_deg)).distance_m
    np.testing.assert_allclose(distance, np.hypot(*floor.T), atol=1e-7)


def test_the_nadir_stays_below_the_lens() -> None:
    camera = camera_from_dict(camera_record((2.0, -1.5)))
    nadir_px = camera.floor_to_pixels(np.zeros((1, 2)))
    assert np.hypot(*(nadir_px[0] - camera.principal_point)) > 30  # the axis no longer meets the nadir
    np.testing.assert_allclose(camera.pixels_to_floor(nadir_px), np.zeros((1, 2)), atol=1e-12)
    # a = 2° about x turns the axis towards +y (image top): the nadir appears below the centre.
    assert nadir_px[0, 1] > camera.principal_point[1] and nadir_px[0, 0] < camera.principal_point[0]


@pytest.mark.parametrize("tilt_deg", [None, (0.0, 0.0)])
def test_a_level_camera_file_gives_bit_identical_positions(tilt_deg: tuple[float, float] | None) -> None:
    level = load_camera(DEMO_CAMERA_PATH)
    record = level.model_dump(mode="json", exclude_none=True)
    same = camera_from_dict(record if tilt_deg is None else record | {"tilt_deg": list(tilt_deg)})
    uv = np.random.default_rng(3).uniform(0, 2047, size=(500, 2))
    before, after = level.floor_positions(uv), same.floor_positions(uv)
    assert np.array_equal(before.xy_m, after.xy_m, equal_nan=True)
    assert np.array_equal(before.distance_m, after.distance_m, equal_nan=True)
    assert np.array_equal(before.valid, after.valid)
    floor = np.random.default_rng(4).uniform(-9, 9, size=(500, 2))
    assert np.array_equal(level.floor_to_pixels(floor), same.floor_to_pixels(floor), equal_nan=True)
    # The stored record of a camera without a tilt has no tilt field: registries read it as before.
    assert "tilt_deg" not in level.model_dump(mode="json", exclude_none=True)


@pytest.mark.parametrize("rays", [np.zeros((0, 3)), np.array([[0.0, 0.0, -1.0], [0.3, -0.2, -0.9]])])
def test_lens_floor_ray_round_trip(rays: np.ndarray) -> None:
    there = lens_to_floor_rays(rays, (2.0, -1.5))
    assert there.shape == rays.shape
    np.testing.assert_allclose(floor_to_lens_rays(there, (2.0, -1.5)), rays, atol=1e-15)


def test_tilt_matrix_is_a_rotation_about_x_then_y() -> None:
    matrix = tilt_matrix((90.0, 0.0))
    np.testing.assert_allclose(matrix @ [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], atol=1e-15)  # down turns to +y
    matrix = tilt_matrix((0.0, 90.0))
    np.testing.assert_allclose(matrix @ [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], atol=1e-15)  # down turns to −x
    np.testing.assert_allclose(tilt_matrix((20.0, -7.0)) @ tilt_matrix((20.0, -7.0)).T, np.eye(3), atol=1e-15)


def test_rays_at_or_above_the_horizon_miss_the_floor() -> None:
    xy, meets = rays_to_floor(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.1], [0.0, 0.0, -1.0],
                                        [np.nan, 0.0, -1.0]]), 3.0)
    assert meets.tolist() == [False, False, True, False]
    assert np.isnan(xy[[0, 1, 3]]).all() and xy[2].tolist() == [0.0, 0.0]


def test_a_tilted_camera_has_no_floor_point_past_its_horizon() -> None:
    camera = camera_from_dict(camera_record((20.0, 0.0)) | {"max_theta_deg": 100.0, "kb": [1.0]})
    # θ = 80° of the lens towards image top (+y) is 100° from straight down: above the horizon;
    # 80° towards image bottom is 60° from straight down, on the floor.
    up_px = camera.principal_point[0], camera.principal_point[1] - 940.0 * math.radians(80)
    down_px = camera.principal_point[0], camera.principal_point[1] + 940.0 * math.radians(80)
    positions = camera.floor_positions(np.array([up_px, down_px]))
    assert positions.valid.tolist() == [False, True] and np.isnan(positions.xy_m[0]).all()
    assert positions.distance_m[1] == pytest.approx(3.2 * math.tan(math.radians(60)))


@settings(max_examples=100, deadline=None)
@given(a=st.floats(-5, 5), b=st.floats(-5, 5), x=st.floats(-15, 15), y=st.floats(-15, 15))
def test_floor_pixels_floor_property(a: float, b: float, x: float, y: float) -> None:
    camera = camera_from_dict(camera_record((a, b)))
    uv = camera.floor_to_pixels(np.array([[x, y]]))
    np.testing.assert_allclose(camera.pixels_to_floor(uv), [[x, y]], atol=1e-6)


@pytest.mark.parametrize(("tilt", "message"), [([31.0, 0.0], "tilt_deg"), ([0.0], "tilt_deg"),
                                               ([float("nan"), 0.0], "tilt_deg")])
def test_bad_tilts_are_refused(tilt: list[float], message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        camera_from_dict(camera_record(None) | {"tilt_deg": tilt})


def test_scaling_keeps_the_tilt() -> None:
    camera = camera_from_dict(camera_record((2.0, -1.5)))
    half = camera.scaled_to((1476, 1476))
    assert half.tilt_deg == (2.0, -1.5)
    floor = ring_m(6.0)
    np.testing.assert_allclose((half.floor_to_pixels(floor) + 0.5) * 2 - 0.5, camera.floor_to_pixels(floor),
                               atol=1e-9)
