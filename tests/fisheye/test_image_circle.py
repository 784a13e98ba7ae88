"""The image-circle fit: synthetic frames with known circles, the renderer's frames, and refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from detector.data.synth import SynthConfig, render_frame
from fisheye import CalibrationError, camera_to_dict, load_camera
from fisheye.camera import FisheyeCamera
from fisheye.image_circle import camera_from_circle, circle_cut, fit_image_circle
from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame

# A frame's circle is found to a fraction of its radius; in px: (centre, radius) tolerance.
FRAMES = {
    "the smallest frame (32 px a side)": (CircleFrame((32, 32), (15.5, 15.5), 13.0), 0.5),
    "centred": (CircleFrame((640, 640), (319.5, 319.5), 300.0), 0.5),
    "off-centre": (CircleFrame((640, 480), (350.2, 228.7), 210.0), 0.5),
    "touching the short side": (CircleFrame((800, 600), (399.5, 299.5), 299.5), 0.5),
    "cut at top and bottom (1312x1080-like)": (CircleFrame((656, 540), (327.5, 274.5), 325.0), 1.0),
    "cut at all four sides": (CircleFrame((540, 540), (270.5, 268.0), 281.0), 1.0),
    "noisy": (CircleFrame((640, 640), (321.0, 318.0), 290.0, noise=12.0, seed=4), 1.0),
    "JPEG quality 30": (CircleFrame((640, 640), (318.0, 322.5), 295.0, jpeg_quality=30, seed=5), 1.0),
    "bright scene up to the rim": (CircleFrame((640, 640), (320.0, 320.0), 280.0, scene_level=235.0), 0.5),
    "dark scene": (CircleFrame((640, 640), (330.0, 310.0), 260.0, scene_level=38.0, border_level=3.0), 1.0),
    "grey border with a timestamp": (
        CircleFrame((656, 540), (328.0, 270.0), 330.0, border_level=14.0, timestamp=True), 1.0),
    "large frame (fit at a reduced scale)": (CircleFrame((2048, 2048), (1030.0, 1019.0), 1010.0), 1.5),
}


@pytest.mark.parametrize("name", list(FRAMES))
def test_the_fitted_circle_is_the_drawn_one(name: str) -> None:
    spec, tolerance_px = FRAMES[name]
    circle = fit_image_circle(draw_circle_frame(spec))
    assert circle.image_wh == spec.wh
    np.testing.assert_allclose(circle.center_px, spec.center_px, atol=tolerance_px)
    assert circle.radius_px == pytest.approx(spec.radius_px, abs=tolerance_px)
    assert circle.inlier_fraction >= 0.8 and circle.rms_px < 1.5


def test_a_wide_circle_is_fitted_from_its_visible_rim_and_says_where_it_is_cut() -> None:
    spec, _ = FRAMES["cut at top and bottom (1312x1080-like)"]
    circle = fit_image_circle(draw_circle_frame(spec))
    assert circle.cut.sides() == ["top", "bottom"]
    assert circle.cut == circle_cut(circle.center_px, circle.radius_px, spec.wh)
    assert 0.4 < circle.cut.visible_rim_fraction < 0.9
    # Every rim point lies in the frame's left or right part: the cut arcs gave none.
    inner = np.abs(circle.rim_points_px[circle.inliers, 0] - spec.center_px[0]) < 0.5 * spec.radius_px
    assert not inner.any()
    assert "circle_cut" in [note.code for note in circle.notes]


def test_a_circle_inside_the_frame_is_not_cut() -> None:
    circle = fit_image_circle(draw_circle_frame(FRAMES["centred"][0]))
    assert circle.cut.sides() == [] and circle.cut.visible_rim_fraction == 1.0
    assert "circle_cut" not in [note.code for note in circle.notes]


@pytest.mark.parametrize(
    ("image", "code"),
    [
        (np.zeros((0, 0, 3), np.uint8), "frame_too_small"),
        (np.zeros((16, 300, 3), np.uint8), "frame_too_small"),
        (np.zeros((480, 640, 3), np.uint8), "no_circle"),
        (np.full((480, 640, 3), 128, np.uint8), "no_circle"),
        (draw_circle_frame(CircleFrame((640, 480), (320.0, 240.0), 420.0)), "no_visible_rim"),
        (draw_circle_frame(CircleFrame((640, 480), (319.5, 239.5), 2000.0)), "no_visible_rim"),
    ],
    ids=["empty", "too small", "all black", "uniform grey", "circle beyond the corners", "no rim at all"],
)
def test_frames_without_a_measurable_circle_are_refused_with_a_reason(image: np.ndarray, code: str) -> None:
    with pytest.raises(CalibrationError) as caught:
        fit_image_circle(image)
    assert caught.value.code == code
    assert str(caught.value)


def test_a_bright_square_is_not_an_image_circle() -> None:
    frame = np.full((480, 640, 3), 5, np.uint8)
    frame[40:440, 120:520] = 160
    with pytest.raises(CalibrationError) as caught:
        fit_image_circle(frame)
    assert caught.value.code == "no_circle"


def test_non_uint8_frames_are_a_programming_error() -> None:
    with pytest.raises(ValueError, match="uint8"):
        fit_image_circle(np.zeros((64, 64), np.float32))


def test_a_grey_frame_fits_as_its_colour_version() -> None:
    rgb = draw_circle_frame(FRAMES["off-centre"][0])
    grey, colour = fit_image_circle(rgb[..., 1]), fit_image_circle(rgb)
    np.testing.assert_allclose(grey.center_px, colour.center_px, atol=0.5)


def _decoded(frame_jpeg: bytes) -> np.ndarray:
    import cv2

    return np.asarray(cv2.imdecode(np.frombuffer(frame_jpeg, np.uint8), cv2.IMREAD_COLOR), np.uint8)


def _wide_camera(size: int) -> FisheyeCamera:
    """A lens whose field reaches past the frame's sides (radius 0.54 of the side)."""
    return FisheyeCamera(id="wide", altitude_m=3.0, image_size=(size, size),
                         principal_point=(size / 2 - 3.0, size / 2 + 2.0),
                         focal_px=(0.54 * size / math.radians(95.0),) * 2, kb=[1.0], max_theta_deg=95.0)


@pytest.mark.parametrize("camera", [None, _wide_camera(288)], ids=["the renderer's camera", "a wide circle"])
def test_the_renderers_frames_give_back_their_cameras_circle(camera: FisheyeCamera | None) -> None:
    """`fishloc synth` draws the circle at the camera's θmax ring: the fit finds that ring."""
    for index in range(2):
        frame = render_frame(7, "seen", index, SynthConfig(size=288, people=(0, 4), camera=camera))
        circle = fit_image_circle(_decoded(frame.jpeg))
        np.testing.assert_allclose(circle.center_px, frame.camera.principal_point, atol=0.6)
        assert circle.radius_px == pytest.approx(frame.camera.image_circle_radius_px(), abs=0.8)
        assert circle.cut.any == (camera is not None)


def test_the_starting_camera_puts_its_90_degree_ring_on_the_circle() -> None:
    spec, _ = FRAMES["cut at top and bottom (1312x1080-like)"]
    circle = fit_image_circle(draw_circle_frame(spec))
    camera = camera_from_circle(circle, "hall-1", altitude_m=3.4)
    assert camera.kb == [1.0] and camera.theta_max_deg == 90.0 and camera.altitude_m == 3.4
    assert camera.image_size == spec.wh and camera.focal_px[0] == camera.focal_px[1]
    horizon = np.array([[math.cos(a), math.sin(a), 0.0] for a in np.linspace(0, 2 * math.pi, 8)])
    uv = camera.rays_to_pixels(horizon)
    distance = np.hypot(uv[:, 0] - circle.center_px[0], uv[:, 1] - circle.center_px[1])
    np.testing.assert_allclose(distance, circle.radius_px, atol=0.01)
    assert load_camera(camera_to_dict(camera)) == camera  # a valid camera file


def test_a_black_floor_below_the_lens_is_not_taken_for_the_border() -> None:
    spec = CircleFrame((640, 640), (322.0, 317.0), 290.0, seed=8)
    frame = draw_circle_frame(spec)
    yy, xx = np.mgrid[:640, :640]
    frame[np.hypot(xx - 320, yy - 320) < 120] = 4  # a black carpet round the nadir
    circle = fit_image_circle(frame)
    np.testing.assert_allclose(circle.center_px, spec.center_px, atol=0.5)
    assert circle.radius_px == pytest.approx(spec.radius_px, abs=0.5)
