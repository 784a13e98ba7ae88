"""The camera's sensor and image pipeline: exposure, white balance, vignetting, lens blur, noise,
tone curve, the black outside of the image circle, an on-screen timestamp, JPEG compression."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from detector.data.rays import RayGrid

Image32 = NDArray[np.float32]
ImageU8 = NDArray[np.uint8]


@dataclass(frozen=True)
class SensorSettings:
    """One frame's sensor: mean brightness `exposure` (of the tone-mapped image, 0-1), per-channel
    `white_balance` gains, `vignetting` strength, `blur_px` (Gaussian sigma at 1024 px), shot/read noise
    `noise` (linear units), `jpeg_quality`, `timestamp` text or None and its `timestamp_corner`,
    global `contrast`, `local_contrast` (unsharp masking, as camera HDR processing does) and
    `chromatic_px`: lateral colour shift of red against blue at the rim (at 1024 px)."""

    exposure: float
    white_balance: tuple[float, float, float]
    vignetting: float
    blur_px: float
    noise: float
    jpeg_quality: int
    timestamp: str | None
    timestamp_corner: int
    contrast: float
    local_contrast: float
    chromatic_px: float


def sample_sensor(rng: np.random.Generator, night: bool) -> SensorSettings:
    hour, minute, second = rng.integers(0, 24), rng.integers(0, 60), rng.integers(0, 60)
    style = rng.random()
    if style < 0.45:
        stamp: str | None = f"{hour:02d}:{minute:02d}:{second:02d}{rng.integers(0, 100):02d}"
    elif style < 0.7:
        stamp = (f"20{rng.integers(15, 26)}-{rng.integers(1, 13):02d}-{rng.integers(1, 29):02d} "
                 f"{hour:02d}:{minute:02d}:{second:02d}")
    else:
        stamp = None
    return SensorSettings(
        exposure=float(rng.uniform(0.3, 0.42) if night else rng.uniform(0.4, 0.55)),
        white_balance=(float(rng.normal(1, 0.05)), 1.0, float(rng.normal(1, 0.06))),
        vignetting=float(rng.uniform(0.1, 0.5)),
        blur_px=float(rng.uniform(0.3, 0.9)),
        noise=float(rng.uniform(0.003, 0.01) if night else rng.uniform(0.0002, 0.002)),
        jpeg_quality=int(rng.integers(70, 96)),
        timestamp=stamp,
        timestamp_corner=int(rng.choice([0, 0, 0, 1, 2, 3])),
        contrast=float(rng.uniform(0.0, 0.35)),
        local_contrast=float(rng.uniform(0.0, 0.5)),
        chromatic_px=float(rng.uniform(0.0, 1.5)),
    )


def _luminance(image: Image32) -> Image32:
    return image @ np.array([0.2126, 0.7152, 0.0722], np.float32)


_NOISE_BANK_SIZE = 1 << 22
_noise_bank: list[Image32] = []


def _normal_noise(rng: np.random.Generator, shape: tuple[int, ...]) -> Image32:
    """Standard normal float32 noise of `shape`: a random window of a fixed bank of normals when
    it fits (drawing millions of fresh normals per frame costs more than the rest of the sensor)."""
    count = int(np.prod(shape))
    if count > _NOISE_BANK_SIZE:
        return rng.standard_normal(shape, dtype=np.float32)
    if not _noise_bank:
        _noise_bank.append(np.random.default_rng(2024).standard_normal(_NOISE_BANK_SIZE, dtype=np.float32))
    start = int(rng.integers(0, _NOISE_BANK_SIZE - count + 1))
    return _noise_bank[0][start:start + count].reshape(shape)


_LUT_STEPS = 1024  # tone-curve entries per unit of linear brightness
_LUT_RANGE = 4.0  # linear values above this clip to white


def _tone_curve(contrast: float) -> NDArray[np.uint8]:
    """uint8 output for linear inputs i / _LUT_STEPS: a filmic shoulder, sRGB-like gamma, and an
    S-curve of strength `contrast`."""
    x = np.arange(int(_LUT_RANGE * _LUT_STEPS) + 1, dtype=np.float64) / _LUT_STEPS
    y = np.power(1.25 * x / (1.0 + 0.25 * x), 1 / 2.2)
    y = np.clip(y, 0.0, 1.0)
    y = y + contrast * (y - 0.5) * (1 - np.abs(2 * y - 1))
    return np.clip(y * 255.0 + 0.5, 0, 255).astype(np.uint8)


def develop(linear: Image32, grid: RayGrid, settings: SensorSettings, rng: np.random.Generator) -> ImageU8:
    """(H, W, 3) linear RGB radiance -> (H, W, 3) uint8 RGB as the camera would write it."""
    scale = grid.shape[1] / 1024.0
    theta_max = grid.camera.theta_max_rad
    falloff = 1.0 - settings.vignetting * (grid.theta / theta_max) ** 3
    # Auto exposure: scale the middle grey of the image circle to the target brightness.
    sub = (slice(None, None, 4), slice(None, None, 4))
    lum = _luminance(linear[sub] * falloff[sub][..., None])[grid.valid[sub]]
    reference = float(np.percentile(lum, 60)) if lum.size else 1.0
    gain = settings.exposure ** 2.2 / max(reference, 1e-4)
    # The image circle: dark beyond the lens's field, with a soft rim.
    edge = cv2.GaussianBlur(grid.valid.astype(np.float32), (0, 0), max(0.6, 0.8 * scale))
    pixel_gain = (falloff * edge * np.float32(gain)).astype(np.float32)
    image = linear * pixel_gain[..., None] * np.asarray(settings.white_balance, np.float32)
    # Lens blur grows slower than the frame: high-resolution sensors sit behind sharper lenses.
    sigma = settings.blur_px * np.sqrt(scale)
    if sigma > 0.25:
        image = np.asarray(cv2.GaussianBlur(image, (0, 0), sigma), np.float32)
    if settings.local_contrast > 0:
        # The wide blur is taken at a quarter of the size: it only holds low frequencies.
        height, width = grid.shape
        small = cv2.resize(image, (max(1, width // 4), max(1, height // 4)), interpolation=cv2.INTER_AREA)
        small = cv2.GaussianBlur(small, (0, 0), 3.0 * scale)
        halo = cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)
        image = np.maximum(image + settings.local_contrast * (image - halo), 0.0).astype(np.float32)
    if settings.chromatic_px > 0:
        image = _lateral_colour(image, grid, settings.chromatic_px * scale)
    noise_std = np.sqrt(np.maximum(image, 0.0) * settings.noise + (settings.noise * 0.1) ** 2)
    image += noise_std * _normal_noise(rng, image.shape)
    index = np.clip(image * _LUT_STEPS, 0, _LUT_RANGE * _LUT_STEPS).astype(np.int32)
    out = _tone_curve(settings.contrast)[index]
    if settings.timestamp:
        _stamp(out, settings.timestamp, settings.timestamp_corner)
    return out


def _lateral_colour(image: Image32, grid: RayGrid, shift_px: float) -> Image32:
    """Scale red out and blue in about the principal point so they part by `shift_px` at the
    image circle's rim (lateral chromatic aberration of wide lenses)."""
    u0, v0 = grid.camera.principal_point
    rim = max(grid.camera.image_circle_radius_px(), 1.0)
    height, width = grid.shape
    out = image.copy()
    for channel, sign in ((0, 1.0), (2, -1.0)):
        s = 1.0 + sign * 0.5 * shift_px / rim
        matrix = np.array([[s, 0.0, (1 - s) * u0], [0.0, s, (1 - s) * v0]], np.float32)
        out[..., channel] = cv2.warpAffine(np.ascontiguousarray(image[..., channel]), matrix, (width, height),
                                           flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    return out


def _stamp(image: ImageU8, text: str, corner: int) -> None:
    """Write `text` in white in a corner, as CCTV recorders do (in place)."""
    height, width = image.shape[:2]
    font = cv2.FONT_HERSHEY_SIMPLEX
    scale = width / 900.0
    thickness = max(1, round(width / 700))
    (tw, th), _ = cv2.getTextSize(text, font, scale, thickness)
    margin = int(width * 0.01)
    x = margin if corner in (0, 2) else width - tw - margin
    y = th + margin if corner in (0, 1) else height - margin
    cv2.putText(image, text, (x, y), font, scale, (235, 235, 235), thickness, cv2.LINE_AA)


def encode_jpeg(image_rgb: ImageU8, quality: int) -> bytes:
    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(image_rgb[..., ::-1]),
                            [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return bytes(data.tobytes())
