"""A rendered frame of a known lens looking down at a tiled floor with measuring tapes laid out from
the nadir, for calibrating in the viewer: the truth of every tape mark is known to the pixel."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from fisheye import FisheyeCamera

TILE_M = 0.5
TILED_RADIUS_M = 10.0  # farther out the tiles shrink below a pixel: plain floor there
TAPE_HALF_WIDTH_M = 0.025
TICK_RADIUS_M = 0.04


@dataclass(frozen=True)
class TapeFrame:
    """The frame (BGR), its camera, and the tapes: `azimuths_deg` (R,), `distances_m` (D,), with the
    true pixel of each mark `marks_px` (R, D, 2) and of the nadir `nadir_px` (2,)."""

    bgr: NDArray[np.uint8]
    camera: FisheyeCamera
    azimuths_deg: NDArray[np.float64]
    distances_m: NDArray[np.float64]
    marks_px: NDArray[np.float64]
    nadir_px: NDArray[np.float64]


def tape_frame(camera: FisheyeCamera, azimuths_deg: list[float], distances_m: list[float]) -> TapeFrame:
    """A frame at `camera.image_size`: grey floor tiles, a yellow tape along each azimuth (degrees,
    counter-clockwise from the floor x axis) with a dark tick at each of `distances_m`."""
    width, height = camera.image_size
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    floor = camera.pixels_to_floor(np.stack([u.ravel(), v.ravel()], axis=1)).reshape(height, width, 2)
    x, y = floor[..., 0], floor[..., 1]
    seen = np.isfinite(x)
    tiled = seen & (np.hypot(np.nan_to_num(x), np.nan_to_num(y)) < TILED_RADIUS_M)
    tiles = (np.floor(np.nan_to_num(x) / TILE_M) + np.floor(np.nan_to_num(y) / TILE_M)) % 2 == 0
    bgr = np.zeros((height, width, 3), dtype=np.uint8)
    bgr[seen] = (90, 90, 90)
    bgr[tiled & tiles] = (150, 150, 150)
    bgr[tiled & ~tiles] = (110, 110, 110)
    azimuths = np.asarray(azimuths_deg, dtype=np.float64)
    distances = np.asarray(distances_m, dtype=np.float64)
    reach = float(distances.max()) + 0.3
    for azimuth in np.radians(azimuths):
        along = x * math.cos(azimuth) + y * math.sin(azimuth)
        across = -x * math.sin(azimuth) + y * math.cos(azimuth)
        bgr[seen & (np.abs(across) < TAPE_HALF_WIDTH_M) & (along > 0) & (along < reach)] = (40, 210, 235)
        for distance in distances:
            tick = np.hypot(along - distance, across) < TICK_RADIUS_M
            bgr[seen & tick] = (20, 20, 20)
    units = np.stack([np.cos(np.radians(azimuths)), np.sin(np.radians(azimuths))], axis=1)  # (R, 2)
    points = units[:, None, :] * distances[None, :, None]  # (R, D, 2) m
    marks = camera.floor_to_pixels(points.reshape(-1, 2)).reshape(len(azimuths), len(distances), 2)
    nadir = camera.floor_to_pixels(np.zeros((1, 2)))[0]
    cv2.circle(bgr, (round(nadir[0]), round(nadir[1])), 3, (0, 0, 255), -1)
    return TapeFrame(bgr, camera, azimuths, distances, marks, nadir)
