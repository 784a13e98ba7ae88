"""A camera whose image circle is wider than its frame, end to end on a real server: the circle
fitted from a frame, its starting camera saved, a person beyond the frame's shorter side detected
and placed on the floor; and the polar view made from such a camera reaches the circle's rim."""

from __future__ import annotations

import math

import cv2
import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer

from contract.views import polar_radius_px
from fisheye import assumed_camera, load_camera
from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame, encode_png

# Cut at top and bottom; a scene dim enough that only the drawn person is what the test double sees.
WIDE = CircleFrame((1312, 1080), (652.0, 549.0), 656.0, scene_level=70.0, seed=9)


def test_a_person_beyond_the_shorter_side_is_placed_by_the_fitted_camera(live_server: LiveServer) -> None:
    rgb = draw_circle_frame(WIDE)
    fitted = httpx.post(f"{live_server.url}/v1/calibrations/image-circle", content=encode_png(rgb),
                        params={"camera_id": "wide-1"}, headers={"content-type": "image/png"}, timeout=60)
    assert fitted.status_code == 200, fitted.text
    record = fitted.json()["camera"]
    assert httpx.put(f"{live_server.url}/v1/cameras/wide-1", json=record).status_code == 201
    camera = load_camera(record)
    # A person standing where the lens sees 560 px from the centre, beyond the shorter side's circle.
    theta = 560.0 / camera.focal_px[0]
    floor_xy = (camera.altitude_m * math.tan(theta), 0.0)
    person = person_frame(camera, floor_xy, WIDE.wh, disk_radius_px=20.0)
    frame = np.where(person.bgr > 0, person.bgr, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    answer = httpx.post(f"{live_server.url}/v1/cameras/wide-1/detect", content=encode(frame),
                        headers={"content-type": "image/jpeg"}, timeout=60)
    assert answer.status_code == 200, answer.text
    best = max(answer.json()["detections"], key=lambda d: d["score"])
    assert best["foot_px"][0] > WIDE.center_px[0] + WIDE.wh[1] / 2  # beyond the shorter side's circle
    # Near the horizon (θ 77°) a pixel is decimetres of floor: the foot is checked in px, the
    # position against the camera's own projection of it.
    np.testing.assert_allclose(best["foot_px"], person.foot_px, atol=2.0)
    expected = camera.pixels_to_floor(np.array([best["foot_px"]]))[0]
    assert best["position_m"] == pytest.approx(expected, abs=1e-3)
    assert best["position_m"] == pytest.approx(floor_xy, abs=0.05 * floor_xy[0])
    # The camera that assumes the circle fills the shorter side has no floor point there.
    assert np.isnan(assumed_camera(*WIDE.wh).pixels_to_floor(np.array([best["foot_px"]]))).all()


@pytest.mark.parametrize(("radius_px", "reach"), [(656.0, "ring"), (900.0, "corner")])
def test_the_polar_view_of_a_wide_circle_reaches_its_rim_or_the_frames_corners(radius_px: float,
                                                                                reach: str) -> None:
    camera = load_camera({"id": "wide", "altitude_m": 3.0, "image_size": [1312, 1080],
                          "principal_point": [652.0, 549.0], "focal_px": [radius_px / (math.pi / 2)] * 2,
                          "kb": [1.0], "max_theta_deg": 90})
    corner = math.hypot(1311.5 - 652.0, 549.5)  # to the farthest corner (top right), pixel edges
    expected = radius_px if reach == "ring" else corner
    assert polar_radius_px(camera, 90.0) == pytest.approx(expected)
    assert polar_radius_px(assumed_camera(1312, 1080), 90.0) == pytest.approx(540.0)
