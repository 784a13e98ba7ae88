"""Per-pixel rays of a fisheye camera, cached, and the image regions that 3D shapes project to.

The renderer casts one ray per frame pixel straight through the camera model
(`FisheyeCamera.pixels_to_rays`), so synthetic geometry matches the service's geometry exactly.
Computing the rays inverts the lens polynomial for every pixel, so grids are cached per camera.
"""

from __future__ import annotations

import json
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fisheye import FisheyeCamera, camera_to_dict
from fisheye.lens import theta_to_radius

FloatArray = NDArray[np.float64]
_CACHE_SIZE = 3
_cache: OrderedDict[str, RayGrid] = OrderedDict()


@dataclass(frozen=True)
class RayGrid:
    """Rays of every pixel of a frame: `directions` (H, W, 3) float32 unit vectors in the world
    frame (zeros outside the calibrated field), `valid` (H, W) bool, `theta` (H, W) float32 rad,
    `pixel_angle_rad` (H, W) float32: the angle one pixel spans (for texture filtering).

    The world frame is the camera's floor frame unless the grid is posed (`posed_grid`): then the
    camera's nadir stands at `nadir_m` of the world and its floor frame is turned by `yaw_rad`
    (counter-clockwise), so several cameras can look at one world."""

    camera: FisheyeCamera
    directions: NDArray[np.float32]
    valid: NDArray[np.bool_]
    theta: NDArray[np.float32]
    pixel_angle_rad: NDArray[np.float32]
    nadir_m: tuple[float, float] = (0.0, 0.0)
    yaw_rad: float = 0.0

    @property
    def shape(self) -> tuple[int, int]:
        return self.valid.shape[0], self.valid.shape[1]

    @property
    def origin(self) -> FloatArray:
        return np.array([self.nadir_m[0], self.nadir_m[1], self.camera.altitude_m])

    def world_to_camera(self, xyz_m: FloatArray) -> FloatArray:
        """(..., 3) world points -> (..., 3) the same points in the camera's floor frame."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        dx = xyz_m[..., 0] - self.nadir_m[0]
        dy = xyz_m[..., 1] - self.nadir_m[1]
        return np.stack([c * dx + s * dy, -s * dx + c * dy, xyz_m[..., 2]], axis=-1)

    def region_rays(self, rect: tuple[int, int, int, int]) -> FloatArray:
        """(K, 3) float64 rays of the pixels of `rect` = (x0, y0, x1, y1), row-major."""
        x0, y0, x1, y1 = rect
        return self.directions[y0:y1, x0:x1].reshape(-1, 3).astype(np.float64)


def ray_grid(camera: FisheyeCamera) -> RayGrid:
    """The RayGrid of `camera` at its calibration size (`camera.scaled_to` first for another size)."""
    key = json.dumps(camera_to_dict(camera), sort_keys=True)
    grid = _cache.get(key)
    if grid is not None:
        _cache.move_to_end(key)
        return grid
    width, height = camera.image_size
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    theta, _ = camera.pixels_to_angles(uv)
    rays = camera.pixels_to_rays(uv)
    valid = np.isfinite(rays).all(axis=1)
    rays[~valid] = 0.0
    theta = np.where(valid, theta, 0.0).reshape(height, width)
    # One pixel spans about 1 / (f · dr/dθ) radians radially.
    kb = np.asarray(camera.kb)
    slope = sum((2 * i + 1) * k * theta ** (2 * i) for i, k in enumerate(kb))
    pixel_angle = 1.0 / (camera.focal_px[0] * np.maximum(slope, 1e-3))
    grid = RayGrid(
        camera=camera,
        directions=rays.reshape(height, width, 3).astype(np.float32),
        valid=valid.reshape(height, width),
        theta=theta.astype(np.float32),
        pixel_angle_rad=pixel_angle.astype(np.float32),
    )
    _cache[key] = grid
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)
    return grid


def posed_grid(grid: RayGrid, nadir_m: tuple[float, float], yaw_rad: float) -> RayGrid:
    """`grid` with its camera's nadir at `nadir_m` (x, y) of the world and its floor frame turned
    by `yaw_rad` counter-clockwise: the rays are rotated into the world frame."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)
    return replace(grid, directions=np.ascontiguousarray(grid.directions @ rotation.T),
                   nadir_m=(float(nadir_m[0]), float(nadir_m[1])), yaw_rad=float(yaw_rad))


def project_points(camera: FisheyeCamera, xyz_m: FloatArray) -> FloatArray:
    """(N, 3) floor-frame points -> (N, 2) px through the lens polynomial, also past θmax (so a
    shape partly outside the field still gets its full region)."""
    rel = xyz_m - np.array([0.0, 0.0, camera.altitude_m])
    horizontal = np.hypot(rel[:, 0], rel[:, 1])
    theta = np.arctan2(horizontal, -rel[:, 2])
    radius = theta_to_radius(theta, camera.kb)
    safe = np.maximum(horizontal, 1e-12)
    u = camera.principal_point[0] + camera.focal_px[0] * radius * rel[:, 0] / safe
    v = camera.principal_point[1] - camera.focal_px[1] * radius * rel[:, 1] / safe
    return np.stack([u, v], axis=1)


def _sphere_samples() -> FloatArray:
    """(26, 3) directions: the faces, edges and corners of a cube, normalised."""
    grid = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)
                     if (x, y, z) != (0, 0, 0)], dtype=np.float64)
    return grid / np.linalg.norm(grid, axis=1, keepdims=True)


_SPHERE = _sphere_samples()


def capsule_region(camera: FisheyeCamera, a: FloatArray, b: FloatArray, radius_m: float,
                   margin_px: float = 2.0) -> tuple[int, int, int, int] | None:
    """Pixel rect (x0, y0, x1, y1), end-exclusive and clipped to the frame, that holds the image of
    every point within `radius_m` of the segment a-b (3,) each; None when it is off the frame."""
    width, height = camera.image_size
    origin = np.array([0.0, 0.0, camera.altitude_m])
    ab = b - a
    along = np.clip(((origin - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    if np.linalg.norm(a + along * ab - origin) <= radius_m * 1.05:
        return 0, 0, width, height  # the lens is inside the shape
    steps = np.linspace(0.0, 1.0, 5)[:, None]
    centres = a + steps * ab  # (5, 3)
    # The cube samples lie inside the sphere; scale them out so their hull covers it.
    points = (centres[:, None, :] + 1.3 * radius_m * _SPHERE[None]).reshape(-1, 3)
    uv = project_points(camera, points)
    span = uv.max(axis=0) - uv.min(axis=0)
    margin = margin_px + 0.08 * span
    x0 = int(np.floor(uv[:, 0].min() - margin[0]))
    y0 = int(np.floor(uv[:, 1].min() - margin[1]))
    x1 = int(np.ceil(uv[:, 0].max() + margin[0])) + 1
    y1 = int(np.ceil(uv[:, 1].max() + margin[1])) + 1
    # A shape that reaches round the nadir projects round the principal point.
    u0, v0 = camera.principal_point
    horizontal = np.hypot(centres[:, 0], centres[:, 1]).min()
    if horizontal <= radius_m * 1.75:
        x0, y0 = min(x0, int(u0) - 1), min(y0, int(v0) - 1)
        x1, y1 = max(x1, int(u0) + 2), max(y1, int(v0) + 2)
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)
    if x0 >= x1 or y0 >= y1:
        return None
    return x0, y0, x1, y1
