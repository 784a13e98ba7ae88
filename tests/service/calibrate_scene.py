"""The scene of the Calibrate mode's browser tests: a known lens, the camera the registry holds before
it is calibrated, the tapes laid out, and what the registry and the fit route say about them."""

from __future__ import annotations

from typing import Any

import httpx
import numpy as np
from service_live_server import LiveServer

from fisheye import FisheyeCamera, camera_from_dict, camera_to_dict
from fisheye.ruler_marks import simulate_ruler_marks

TRUE = camera_from_dict({
    "id": "tape", "altitude_m": 3.0, "image_size": [1600, 1200], "principal_point": [806.3, 597.8],
    "focal_px": [420.0, 420.0], "kb": [1.0, -0.03, 0.002],
})
# What the registry has before the calibration: an ideal lens guessed at the frame's centre.
GUESS = dict(camera_to_dict(TRUE), kb=[1.0], focal_px=[400.0, 400.0], principal_point=[799.5, 599.5],
             site_pose={"x_m": 4.0, "y_m": -1.0, "yaw_deg": 30.0}, max_view_pixels=2_000_000,
             second_look_pixels=786_432, longest_person_ratio=1.8)
RULERS = {"east": (10.0, [1, 2, 3, 4, 5, 6, 7, 8]), "north": (100.0, [2, 4, 6, 8]),
          "west": (190.0, [1, 2, 3, 4, 5, 6, 7, 8]), "south": (280.0, [2, 4, 6, 8])}
OPTIONS = {"coefficients": 3, "fit_principal_point": True, "fit_tilt": False}
# The marks a user takes of TRUE along four tapes, a mark every metre out to 8 m.
FOUR_TAPES = simulate_ruler_marks(TRUE, [10.0, 100.0, 190.0, 280.0], np.arange(1.0, 8.001, 1.0))


def registry_camera(server: LiveServer) -> dict[str, Any]:
    response = httpx.get(f"{server.url}/v1/cameras/tape")
    assert response.status_code == 200
    record: dict[str, Any] = response.json()
    return record


def floor_error_at_m(camera: FisheyeCamera, distance_m: float) -> float:
    """Largest floor-position error of `camera` against the true lens on a circle about the nadir."""
    phi = np.radians(np.arange(0.0, 360.0, 5.0))
    xy = distance_m * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return float(np.hypot(*(camera.pixels_to_floor(TRUE.floor_to_pixels(xy)) - xy).T).max())


def fit_body(state: dict[str, Any]) -> dict[str, Any]:
    """The fit request of the page's marks, in pixels of its frame."""
    marks = [{"ruler": m["ruler"], "u": m["u"], "v": m["v"], "distance_m": m["distance_m"],
              **({"x_m": m["x_m"], "y_m": m["y_m"]} if m["x_m"] is not None else {})} for m in state["marks"]]
    frame = state["frame"]
    return {"camera_id": "tape", "altitude_m": TRUE.altitude_m, "image_size": list(TRUE.image_size),
            "frame_size": [frame["width"], frame["height"]], "marks": marks, "options": OPTIONS}


def route_refusal(server: LiveServer, body: dict[str, Any]) -> str:
    response = httpx.post(f"{server.url}/v1/calibrations/fit", json=body)
    assert 400 <= response.status_code < 500, response.text
    message: str = response.json()["error"]["message"]
    return message
