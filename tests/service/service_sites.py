"""A two-camera site for the service tests: cameras of the demo calibration, 4 m apart on one map,
and frames of people at known site positions drawn for the test double."""

from __future__ import annotations

from typing import Any

import httpx
import numpy as np
from service_frames import encode, person_frame

from fisheye import FisheyeCamera, camera_to_dict

SITE = "hall"
FRAME_WH = (512, 512)
MIN_SCORE = 0.85  # the double's blob (0.9) only, not its constant boxes
T0 = 1_764_612_000.0
# Camera nadirs on the map; cam-b is turned by 90° to exercise the pose.
POSES = {"cam-a": {"x_m": -2.0, "y_m": 0.0, "yaw_deg": 0.0},
         "cam-b": {"x_m": 2.0, "y_m": 0.0, "yaw_deg": 90.0}}


def site_camera_record(demo: FisheyeCamera, camera_id: str, site: str = SITE) -> dict[str, Any]:
    return {**camera_to_dict(demo), "id": camera_id, "site": site, "site_pose": POSES[camera_id]}


def put_site_cameras(client: httpx.Client, demo: FisheyeCamera, site: str = SITE) -> None:
    for camera_id in POSES:
        answer = client.put(f"/v1/cameras/{camera_id}", json=site_camera_record(demo, camera_id, site))
        assert answer.status_code in (200, 201), answer.text


def frame_of(demo: FisheyeCamera, camera_id: str, site_xy_m: tuple[float, float]) -> bytes:
    """A JPEG frame of `camera_id` with one person at `site_xy_m` on the map."""
    pose = POSES[camera_id]
    yaw = np.radians(pose["yaw_deg"])
    offset = np.array(site_xy_m) - [pose["x_m"], pose["y_m"]]
    floor = np.array([[np.cos(yaw), np.sin(yaw)], [-np.sin(yaw), np.cos(yaw)]]) @ offset
    return encode(person_frame(demo, (float(floor[0]), float(floor[1])), FRAME_WH).bgr)


def detect(client: httpx.Client, camera_id: str, frame: bytes, capture_time: float | str,
           **params: Any) -> httpx.Response:
    query = {"min_score": MIN_SCORE, "capture_time": capture_time, **params}
    return client.post(f"/v1/cameras/{camera_id}/detect", params=query, content=frame,
                       headers={"Content-Type": "image/jpeg"})


def walk(client: httpx.Client, demo: FisheyeCamera, start: tuple[float, float],
         velocity: tuple[float, float], steps: int, t0: float = T0, fps: float = 5.0,
         cameras: tuple[str, ...] = ("cam-a", "cam-b")) -> list[str | None]:
    """One person walking; each camera sends its frame of each step. The track ids answered."""
    ids = []
    for k in range(steps):
        t = k / fps
        where = (start[0] + velocity[0] * t, start[1] + velocity[1] * t)
        for camera_id in cameras:
            answer = detect(client, camera_id, frame_of(demo, camera_id, where), t0 + t)
            assert answer.status_code == 200, answer.text
            detections = answer.json()["detections"]
            assert len(detections) == 1
            ids.append(detections[0]["track_id"])
    return ids
