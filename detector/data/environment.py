"""The static surroundings of a scene: floor, walls (room walls or building façades), ceiling, sky.

The enclosure is an axis-aligned rectangle around the camera's nadir (of a posed grid: around
any point of the world the camera sees); a ray leaves it through a wall
unless it meets the floor first. `trace_environment` gives every pixel its distance, albedo and
normal; a scene computes it once and reuses it for all its frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from detector.data.rays import RayGrid
from detector.data.textures import Texture

FloatArray = NDArray[np.float64]
Image32 = NDArray[np.float32]

FLOOR, WALL, CEILING, SKY = 1, 2, 3, 4


@dataclass(frozen=True)
class Environment:
    """Enclosure `room_m` (x0, y0, x1, y1) around the nadir with walls `wall_height_m` high; above
    them a ceiling (indoor) or sky. The floor mixes `floor` and `floor_second` by the overlay's 5th
    channel, is tinted by its RGB and blended towards that colour by its 4th (markings, rugs).
    `walls` is a texture in (s, z) metres where s runs round the enclosure from (x0, y0)
    counter-clockwise."""

    indoor: bool
    room_m: tuple[float, float, float, float]
    wall_height_m: float
    floor: Texture
    floor_second: Texture
    floor_overlay: Texture
    walls: Texture
    ceiling_color: tuple[float, float, float]
    sky_colors: tuple[tuple[float, float, float], tuple[float, float, float]]


@dataclass(frozen=True)
class Background:
    """Per pixel (H, W): distance `t` along the ray (inf where none), surface `kind`, `albedo`
    (H, W, 3) and `normal` (H, W, 3)."""

    t: Image32
    kind: NDArray[np.uint8]
    albedo: Image32
    normal: Image32


def _wall_coordinate(env: Environment, x: FloatArray, y: FloatArray, axis: NDArray[np.int64],
                     positive: NDArray[np.bool_]) -> FloatArray:
    """Distance s (m) round the enclosure of wall points, counter-clockwise from (x0, y0)."""
    x0, y0, x1, y1 = env.room_m
    width, depth = x1 - x0, y1 - y0
    s = np.where(axis == 1,
                 np.where(positive, width + depth + (x1 - x), x - x0),  # y = y1 or y = y0
                 np.where(positive, width + (y - y0), 2 * width + depth + (y1 - y)))  # x = x1 / x0
    return s


def trace_environment(env: Environment, grid: RayGrid) -> Background:
    """Distance, albedo and normal of the surroundings for every pixel of `grid`."""
    height, width = grid.shape
    altitude = grid.camera.altitude_m
    valid = grid.valid.ravel()
    d = grid.directions.reshape(-1, 3)[valid].astype(np.float64)
    pix_angle = grid.pixel_angle_rad.ravel()[valid].astype(np.float64)
    n = len(d)
    ox, oy = grid.nadir_m
    x0, y0, x1, y1 = env.room_m
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(d[:, 2] < -1e-9, altitude / -d[:, 2], np.inf)
        tx = np.where(d[:, 0] > 1e-12, (x1 - ox) / d[:, 0],
                      np.where(d[:, 0] < -1e-12, (x0 - ox) / d[:, 0], np.inf))
        ty = np.where(d[:, 1] > 1e-12, (y1 - oy) / d[:, 1],
                      np.where(d[:, 1] < -1e-12, (y0 - oy) / d[:, 1], np.inf))
    t_wall = np.minimum(tx, ty)
    wall_axis = np.where(tx <= ty, 0, 1)
    z_wall = altitude + t_wall * d[:, 2]
    kind = np.full(n, SKY, np.uint8)
    t = np.full(n, np.inf)
    on_floor = t_floor <= t_wall
    on_wall = ~on_floor & (z_wall <= env.wall_height_m) & np.isfinite(t_wall)
    kind[on_floor] = FLOOR
    t[on_floor] = t_floor[on_floor]
    kind[on_wall] = WALL
    t[on_wall] = t_wall[on_wall]
    above = ~on_floor & ~on_wall
    if env.indoor:
        with np.errstate(divide="ignore"):
            t_ceiling = np.where(d[:, 2] > 1e-9, (env.wall_height_m - altitude) / d[:, 2], np.inf)
        ceiling = above & np.isfinite(t_ceiling)
        kind[ceiling] = CEILING
        t[ceiling] = t_ceiling[ceiling]
    albedo = np.zeros((n, 3), np.float32)
    normal = np.zeros((n, 3), np.float32)
    # floor
    idx = np.flatnonzero(on_floor)
    if idx.size:
        tf = t[idx]
        fx, fy = ox + tf * d[idx, 0], oy + tf * d[idx, 1]
        # The floor seen at incidence θ stretches a pixel by 1 / cos θ radially.
        footprint = tf * pix_angle[idx] / np.maximum(-d[idx, 2], 0.02)
        over = env.floor_overlay.sample(fx, fy, footprint)
        base = env.floor.sample(fx, fy, footprint)
        second = over[:, 4:5]
        mixed = np.flatnonzero(second[:, 0] > 0.01)
        if mixed.size:
            other = env.floor_second.sample(fx[mixed], fy[mixed], footprint[mixed])
            base[mixed] = base[mixed] * (1 - second[mixed]) + other * second[mixed]
        alpha = over[:, 3:4]
        albedo[idx] = base * (1 - alpha) * over[:, :3] + alpha * over[:, :3]
        normal[idx] = (0.0, 0.0, 1.0)
    # walls
    idx = np.flatnonzero(on_wall)
    if idx.size:
        tw = t[idx]
        wx, wy, wz = ox + tw * d[idx, 0], oy + tw * d[idx, 1], altitude + tw * d[idx, 2]
        axis = wall_axis[idx]
        positive = np.where(axis == 0, d[idx, 0] > 0, d[idx, 1] > 0)
        s = _wall_coordinate(env, wx, wy, axis, positive)
        grazing = np.abs(np.where(axis == 0, d[idx, 0], d[idx, 1]))
        footprint = tw * pix_angle[idx] / np.maximum(grazing, 0.05)
        albedo[idx] = env.walls.sample(s, wz, footprint)[:, :3]
        nrm = np.zeros((idx.size, 3), np.float32)
        nrm[np.arange(idx.size), axis] = np.where(positive, -1.0, 1.0)
        normal[idx] = nrm
    ceiling_idx = np.flatnonzero(kind == CEILING)
    albedo[ceiling_idx] = env.ceiling_color
    normal[ceiling_idx] = (0.0, 0.0, -1.0)
    sky_idx = np.flatnonzero(kind == SKY)
    if sky_idx.size:
        elevation = np.clip(d[sky_idx, 2], 0.0, 1.0)[:, None]
        horizon, zenith = np.array(env.sky_colors[0]), np.array(env.sky_colors[1])
        albedo[sky_idx] = horizon * (1 - elevation) + zenith * elevation
    full_t = np.full(height * width, np.inf, np.float32)
    full_t[valid] = t
    full_kind = np.zeros(height * width, np.uint8)
    full_kind[valid] = kind
    full_albedo = np.zeros((height * width, 3), np.float32)
    full_albedo[valid] = albedo
    full_normal = np.zeros((height * width, 3), np.float32)
    full_normal[valid] = normal
    return Background(
        t=full_t.reshape(height, width),
        kind=full_kind.reshape(height, width),
        albedo=full_albedo.reshape(height, width, 3),
        normal=full_normal.reshape(height, width, 3),
    )
