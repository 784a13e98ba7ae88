"""Letterboxing: a frame scaled to fit a square model input, centred and padded.

Shared by training (detector), export parity checks and the service so that all three map pixels
between the frame and the model input the same way. Pixel centres sit at integers, so a coordinate
maps as u_in = (u + 0.5)·s − 0.5 + pad (the convention of cv2.resize).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.arrays import as_points

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Letterbox:
    """How a `frame_wh` frame sits in a `size`×`size` input: resized to `resized_wh`, its top-left
    corner at `offset_xy` (whole input pixels)."""

    frame_wh: tuple[int, int]
    size: int
    resized_wh: tuple[int, int]
    offset_xy: tuple[int, int]

    def __post_init__(self) -> None:
        if min(self.frame_wh) < 1 or self.size < 1:
            raise ValueError(f"letterbox needs positive sizes, got {self.frame_wh} -> {self.size}")

    @classmethod
    def fit(cls, frame_wh: tuple[int, int], size: int) -> Letterbox:
        """The letterbox that fits a frame of `frame_wh` px into a square input of side `size`."""
        width, height = int(frame_wh[0]), int(frame_wh[1])
        scale = size / max(width, height)
        resized = (max(1, round(width * scale)), max(1, round(height * scale)))
        offset = ((size - resized[0]) // 2, (size - resized[1]) // 2)
        return cls((width, height), int(size), resized, offset)

    @property
    def scale_xy(self) -> tuple[float, float]:
        return self.resized_wh[0] / self.frame_wh[0], self.resized_wh[1] / self.frame_wh[1]

    def frame_to_input(self, uv_px: ArrayLike) -> FloatArray:
        """(N, 2) frame px -> (N, 2) input px."""
        uv = as_points(uv_px, 2, "uv_px")
        scale = np.asarray(self.scale_xy)
        return (uv + 0.5) * scale - 0.5 + np.asarray(self.offset_xy, dtype=np.float64)

    def input_to_frame(self, uv_px: ArrayLike) -> FloatArray:
        """(N, 2) input px -> (N, 2) frame px."""
        uv = as_points(uv_px, 2, "uv_px")
        scale = np.asarray(self.scale_xy)
        return (uv - np.asarray(self.offset_xy, dtype=np.float64) + 0.5) / scale - 0.5

    def boxes_input_to_frame(self, cxcywh: ArrayLike) -> FloatArray:
        """(N, 4) boxes in input px -> (N, 4) in frame px (sizes scale by the mean scale)."""
        boxes = as_points(cxcywh, 4, "cxcywh")
        mean_scale = float(np.mean(self.scale_xy))
        return np.concatenate([self.input_to_frame(boxes[:, :2]), boxes[:, 2:] / mean_scale], axis=1)

    def boxes_frame_to_input(self, cxcywh: ArrayLike) -> FloatArray:
        """(N, 4) boxes in frame px -> (N, 4) in input px."""
        boxes = as_points(cxcywh, 4, "cxcywh")
        mean_scale = float(np.mean(self.scale_xy))
        return np.concatenate([self.frame_to_input(boxes[:, :2]), boxes[:, 2:] * mean_scale], axis=1)

    def apply(self, frame_rgb: NDArray[np.uint8], pad_value: int = 0) -> NDArray[np.uint8]:
        """(H, W, 3) uint8 frame -> (size, size, 3) uint8 letterboxed input (area resampling)."""
        import cv2

        height, width = frame_rgb.shape[:2]
        if (width, height) != self.frame_wh:
            raise ValueError(f"frame is {width}x{height}, letterbox expects {self.frame_wh}")
        resized = cv2.resize(frame_rgb, self.resized_wh, interpolation=cv2.INTER_AREA)
        canvas = np.full((self.size, self.size, 3), pad_value, dtype=np.uint8)
        x0, y0 = self.offset_xy
        canvas[y0:y0 + self.resized_wh[1], x0:x0 + self.resized_wh[0]] = resized
        return canvas
