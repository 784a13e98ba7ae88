import numpy as np

from fisheye import load_camera
from models import DEMO_CAMERA_PATH


def test_demo_camera_floor_round_trip() -> None:
    cam = load_camera(DEMO_CAMERA_PATH)
    xy = np.array([[0.5, -1.0], [10.0, 3.0], [-15.0, 12.0]])
    np.testing.assert_allclose(cam.pixels_to_floor(cam.floor_to_pixels(xy)), xy, atol=1e-6)
