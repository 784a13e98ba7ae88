"""Drawing a result on its frame (`?render=jpeg`): boxes, foot points and floor positions."""

from __future__ import annotations

import math

import cv2
import numpy as np
from numpy.typing import NDArray

from service.frame_decode import decode_frame
from service.result import DetectionResult

_BOX_BGR = (60, 220, 60)
_FOOT_BGR = (40, 40, 255)
_TEXT_BGR = (255, 255, 255)
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_SHIFT = 4  # sub-pixel drawing: coordinates in 1/16 px


def _to_decoded(points_px: NDArray[np.float64], reduction: int) -> NDArray[np.float64]:
    """Frame px -> px of the reduced decode (pixel centres at integers in both)."""
    return (points_px + 0.5) / reduction - 0.5


def _fixed(points: NDArray[np.float64]) -> NDArray[np.int32]:
    return np.round(points * (1 << _SHIFT)).astype(np.int32)


RENDER_SIDE = 1024  # a drawn frame's long side is at least this (or the frame's own size)


def render_jpeg(result: DetectionResult, data: bytes, max_pixels: int, quality: int = 85) -> bytes:
    """The frame `data` with the detections of `result` drawn, as JPEG bytes; large JPEGs are drawn
    at a reduced scale whose long side stays ≥ RENDER_SIDE."""
    frame = decode_frame(data, RENDER_SIDE, max_pixels)
    canvas = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
    detections = result.detections
    scale = max(frame.decoded_wh) / 1000.0
    thickness = max(1, round(2 * scale))
    font_scale = max(0.4, 0.6 * scale)
    for index in range(len(detections)):
        corners = _to_decoded(detections.corners_xy[index], frame.reduction)
        cv2.polylines(canvas, [_fixed(corners)], True, _BOX_BGR, thickness, cv2.LINE_AA, _SHIFT)
        foot = _to_decoded(detections.foot_px[index][None], frame.reduction)[0]
        center = (int(_fixed(foot)[0]), int(_fixed(foot)[1]))
        cv2.circle(canvas, center, max(3, round(4 * scale)) << _SHIFT, _FOOT_BGR, -1, cv2.LINE_AA, _SHIFT)
        x_m, y_m = detections.position_m[index]
        label = f"{detections.scores[index]:.2f}"
        if math.isfinite(x_m) and math.isfinite(y_m):
            label += f" ({x_m:.2f}, {y_m:.2f}) m"
        origin = (int(foot[0]) + 6, int(foot[1]) - 6)
        for color, width in (((0, 0, 0), thickness + 2), (_TEXT_BGR, thickness)):  # outlined text
            cv2.putText(canvas, label, origin, _FONT, font_scale, color, width, cv2.LINE_AA)
    ok, encoded = cv2.imencode(".jpg", canvas, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding of the rendered frame failed")
    return encoded.tobytes()
