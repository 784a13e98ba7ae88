"""Tilted fisheye cameras as OpenCV sees them: an independent projection for the tilt tests.

OpenCV's camera frame has x right, y down (image), z along the optical axis. A level FishLoc camera
looks down (floor −z) with image right = floor +x and image up = floor +y, so a level-lens ray d maps
to OpenCV coordinates diag(1, −1, −1)·d. The tilt rotates lens rays into the floor frame by
R_y(b)·R_x(a) (built here with cv2.Rodrigues), so a floor point P seen from the lens at C = (0, 0, Z)
is at diag(1, −1, −1)·(R_y(b)·R_x(a))ᵀ·(P − C) in OpenCV's camera frame.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from fisheye.ruler_marks import RulerMarks

FloatArray = NDArray[np.float64]

ALTITUDE_M = 3.2
IMAGE_SIZE = (2952, 2952)
K = np.array([[940.0, 0.0, 1480.3], [0.0, 940.0, 1469.8], [0.0, 0.0, 1.0]])
D = np.array([-0.02, 0.001, 0.0, 0.0])  # kb = [1, -0.02, 0.001]
FOUR_TAPES_DEG = (0.0, 90.0, 180.0, 270.0)
EVERY_QUARTER_METRE = np.arange(0.25, 10.001, 0.25)


def opencv_rotation(tilt_deg: tuple[float, float]) -> FloatArray:
    """(3, 3) floor frame -> OpenCV camera frame of a lens tilted by `tilt_deg`."""
    about_x = cv2.Rodrigues(np.array([math.radians(tilt_deg[0]), 0.0, 0.0]))[0]
    about_y = cv2.Rodrigues(np.array([0.0, math.radians(tilt_deg[1]), 0.0]))[0]
    return np.asarray(np.diag([1.0, -1.0, -1.0]) @ (about_y @ about_x).T)


def project_floor(xy_m: FloatArray, tilt_deg: tuple[float, float], altitude_m: float = ALTITUDE_M,
                  K: FloatArray = K, D: FloatArray = D) -> FloatArray:
    """(N, 2) floor points (m) -> (N, 2) px by cv2.fisheye.projectPoints."""
    rotation = opencv_rotation(tilt_deg)
    translation = -rotation @ np.array([0.0, 0.0, altitude_m])
    points = np.concatenate([xy_m, np.zeros((len(xy_m), 1))], axis=1).reshape(-1, 1, 3)
    uv = cv2.fisheye.projectPoints(points, cv2.Rodrigues(rotation)[0], translation, K, D)[0]
    return np.asarray(uv.reshape(-1, 2), dtype=np.float64)


def tape_marks(tilt_deg: tuple[float, float], directions_deg: tuple[float, ...] = FOUR_TAPES_DEG,
               distances_m: FloatArray = EVERY_QUARTER_METRE, noise_px: float = 0.0,
               seed: int = 0) -> RulerMarks:
    """The marks of tapes laid from the nadir in `directions_deg` (a mark every `distances_m`) plus the
    nadir, as OpenCV projects them, each click off by Gaussian `noise_px` per axis."""
    xy, distance, labels = [np.zeros((1, 2))], [np.zeros(1)], ["nadir"]
    for direction in directions_deg:
        unit = np.array([math.cos(math.radians(direction)), math.sin(math.radians(direction))])
        xy.append(distances_m[:, None] * unit)
        distance.append(distances_m)
        labels += [f"tape{direction:g}"] * len(distances_m)
    uv = project_floor(np.concatenate(xy), tilt_deg)
    if noise_px > 0:
        uv = uv + np.random.default_rng(seed).normal(0.0, noise_px, uv.shape)
    return RulerMarks.from_arrays(uv, np.concatenate(distance), None, labels)


def camera_record(tilt_deg: tuple[float, float] | None) -> dict[str, Any]:
    """The FishLoc camera file of the OpenCV camera above."""
    record: dict[str, Any] = {
        "id": "tilted", "altitude_m": ALTITUDE_M, "image_size": list(IMAGE_SIZE),
        "principal_point": [K[0, 2], K[1, 2]], "focal_px": [K[0, 0], K[1, 1]], "kb": [1.0, *D[:2]],
    }
    return record if tilt_deg is None else record | {"tilt_deg": list(tilt_deg)}


def ring_m(distance_m: float, step_deg: float = 5.0) -> FloatArray:
    """(M, 2) floor points on a circle of `distance_m` around the nadir."""
    phi = np.radians(np.arange(0.0, 360.0, step_deg))
    return np.asarray(distance_m * np.stack([np.cos(phi), np.sin(phi)], axis=1))
