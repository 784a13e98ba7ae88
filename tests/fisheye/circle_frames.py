"""Synthetic fisheye frames with a known image circle: a textured scene inside, a dark border outside."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class CircleFrame:
    """How to draw one frame: size, circle (frame px, pixel centres at integers), scene and border
    grey levels, noise σ, JPEG quality (None: none), a timestamp in the border."""

    wh: tuple[int, int]
    center_px: tuple[float, float]
    radius_px: float
    scene_level: float = 140.0
    border_level: float = 6.0
    noise: float = 2.0
    jpeg_quality: int | None = None
    timestamp: bool = False
    seed: int = 0


def draw_circle_frame(spec: CircleFrame) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB: a blotchy coloured scene of mean `scene_level` inside the circle, with a
    rim darkened a little (vignetting) and anti-aliased over one px, on the border's level."""
    width, height = spec.wh
    rng = np.random.default_rng(spec.seed)
    small = rng.uniform(-1, 1, (max(2, height // 16), max(2, width // 16), 3)).astype(np.float32)
    texture = cv2.resize(small, (width, height), interpolation=cv2.INTER_CUBIC)
    scene = spec.scene_level * (1.0 + 0.35 * texture)
    yy, xx = np.mgrid[:height, :width].astype(np.float64)
    distance = np.hypot(xx - spec.center_px[0], yy - spec.center_px[1])
    coverage = np.clip(spec.radius_px - distance + 0.5, 0.0, 1.0)[..., None]
    vignette = (1.0 - 0.3 * np.clip(distance / spec.radius_px, 0, 1) ** 3)[..., None]
    image = coverage * scene * vignette + (1 - coverage) * spec.border_level
    image = image + rng.normal(0.0, spec.noise, image.shape)
    frame = np.clip(image + 0.5, 0, 255).astype(np.uint8)
    if spec.timestamp:
        cv2.putText(frame, "2026-12-02 13:00:05", (4, max(12, height // 20)), cv2.FONT_HERSHEY_SIMPLEX,
                    width / 900.0, (235, 235, 235), 1, cv2.LINE_AA)
    if spec.jpeg_quality is not None:
        ok, data = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, spec.jpeg_quality])
        assert ok
        frame = np.asarray(cv2.imdecode(data, cv2.IMREAD_UNCHANGED), dtype=np.uint8)
    return frame


def encode_png(rgb: NDArray[np.uint8]) -> bytes:
    ok, data = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return data.tobytes()


def encode_jpeg(rgb: NDArray[np.uint8], quality: int = 90) -> bytes:
    ok, data = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return data.tobytes()
