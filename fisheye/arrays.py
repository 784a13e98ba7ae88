"""Shape checks shared by the geometry functions."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def as_points(values: ArrayLike, dims: int, name: str) -> NDArray[np.float64]:
    """A new float64 array of shape (N, dims); an empty input gives (0, dims).

    Raises ValueError naming `name` when the input cannot be read as N points of `dims` numbers.
    """
    array = np.array(values, dtype=np.float64)
    if array.size == 0:
        return np.zeros((0, dims))
    if array.ndim != 2 or array.shape[1] != dims:
        raise ValueError(f"{name} must have shape (N, {dims}), got {array.shape}")
    return array


def resolution_scale(from_wh: tuple[int, int], to_wh: tuple[int, int],
                     tolerance_px: float = 1.0) -> tuple[float, float]:
    """(s_u, s_v) taking pixels of a `from_wh` frame to a `to_wh` frame of the same aspect ratio.

    Raises ValueError when a size is not positive or the aspect ratios differ by more than
    `tolerance_px` pixels.
    """
    (from_w, from_h), (to_w, to_h) = from_wh, to_wh
    if min(from_w, from_h, to_w, to_h) < 1:
        raise ValueError(f"frame sizes must be positive, got {from_w}x{from_h} and {to_w}x{to_h}")
    if abs(to_w * from_h - to_h * from_w) > tolerance_px * max(from_w, from_h):
        raise ValueError(f"a {to_w}x{to_h} frame does not have the aspect ratio of {from_w}x{from_h}")
    return to_w / from_w, to_h / from_h


def scale_pixels(uv_px: ArrayLike, scale_uv: tuple[float, float]) -> NDArray[np.float64]:
    """(N, 2) px -> (N, 2) px of a frame resized by `scale_uv`. Pixel centres sit at integers, so a
    coordinate maps as u' = (u + 0.5)·s − 0.5 (as cv2.resize does)."""
    points = as_points(uv_px, 2, "uv_px")
    return (points + 0.5) * np.asarray(scale_uv) - 0.5
