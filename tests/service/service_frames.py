"""Frames with known people for the service tests (drawn for the plumbing test double)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from service_doubles import BLOB_WH, INPUT_SIZE

from fisheye import FisheyeCamera, Letterbox


@dataclass(frozen=True)
class PersonFrame:
    """A frame (BGR) with one bright disk where the test double will see a person, and the truth."""

    bgr: NDArray[np.uint8]
    floor_xy_m: tuple[float, float]
    box_cxcywh: NDArray[np.float64]   # (4,) frame px, the box the double should report
    foot_px: NDArray[np.float64]      # (2,) frame px


def person_frame(camera: FisheyeCamera, floor_xy_m: tuple[float, float], frame_wh: tuple[int, int],
                 disk_radius_px: float = 40.0) -> PersonFrame:
    """A black `frame_wh` frame of `camera` with a person standing at `floor_xy_m`.

    The double reports a box of BLOB_WH input px at the disk's centre; scaled to the frame, its foot
    point (the middle of the side nearest the principal point) must be the pixel of `floor_xy_m`.
    """
    cam = camera.scaled_to(frame_wh)
    foot = cam.floor_to_pixels(np.array([floor_xy_m]))[0]
    pp = np.asarray(cam.principal_point)
    radial = (foot - pp) / np.linalg.norm(foot - pp)
    scale = float(np.mean(Letterbox.fit(frame_wh, INPUT_SIZE).scale_xy))
    w, h = BLOB_WH[0] / scale, BLOB_WH[1] / scale
    center = foot + radial * h / 2
    bgr = np.zeros((frame_wh[1], frame_wh[0], 3), dtype=np.uint8)
    shift = 4
    cv2.circle(bgr, (round(center[0] * 16), round(center[1] * 16)), round(disk_radius_px * 16),
               (255, 255, 255), -1, cv2.LINE_AA, shift)
    return PersonFrame(bgr, floor_xy_m, np.array([center[0], center[1], w, h]), foot)


def encode(bgr: NDArray[np.uint8], ext: str = ".jpg") -> bytes:
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if ext == ".jpg" else []
    ok, data = cv2.imencode(ext, bgr, params)
    assert ok
    return bytes(data.tobytes())
