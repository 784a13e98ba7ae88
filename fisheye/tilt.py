"""Tilt of a camera that does not look straight down (DESIGN.md, `tilt_deg = [a, b]`).

A lens ray is first computed as if the camera were level (optical axis straight down, the formulas of
`fisheye.camera`), then rotated by `a` about the floor frame's x axis and by `b` about its y axis
(right-handed): `floor_ray = R_y(b) · R_x(a) · level_ray`. The lens stays straight above the nadir.
Pure functions on arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.arrays import as_points

FloatArray = NDArray[np.float64]

LEVEL = (0.0, 0.0)
MAX_TILT_DEG = 30.0  # a ceiling camera tilted further is a wall camera; its floor is not below it


def is_level(tilt_deg: tuple[float, float] | None) -> bool:
    """Whether a `tilt_deg` (or its absence) is the level camera."""
    return tilt_deg is None or (tilt_deg[0] == 0.0 and tilt_deg[1] == 0.0)


def tilt_matrix(tilt_deg: tuple[float, float]) -> FloatArray:
    """(3, 3) rotation R_y(b) · R_x(a) taking level-camera rays into the floor frame."""
    a, b = math.radians(tilt_deg[0]), math.radians(tilt_deg[1])
    about_x = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
    about_y = np.array([[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0], [-math.sin(b), 0.0, math.cos(b)]])
    return about_y @ about_x


def lens_to_floor_rays(rays: ArrayLike, tilt_deg: tuple[float, float]) -> FloatArray:
    """(N, 3) rays of the level lens -> (N, 3) the same rays in the floor frame of the tilted camera."""
    return as_points(rays, 3, "rays") @ tilt_matrix(tilt_deg).T


def floor_to_lens_rays(rays: ArrayLike, tilt_deg: tuple[float, float]) -> FloatArray:
    """(N, 3) rays in the floor frame -> (N, 3) the same rays as the level lens sees them."""
    return as_points(rays, 3, "rays") @ tilt_matrix(tilt_deg)


def rays_to_floor(rays: ArrayLike, altitude_m: float) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(N, 3) floor-frame rays from a lens `altitude_m` above the nadir -> (N, 2) m where they meet
    the floor, and (N,) whether they do (a ray level with or above the horizon never does: NaN)."""
    directions = as_points(rays, 3, "rays")
    down = -directions[:, 2]
    meets = np.isfinite(directions).all(axis=1) & (down > 0)
    xy = np.full((len(directions), 2), np.nan)
    xy[meets] = directions[meets, :2] * (altitude_m / down[meets])[:, None]
    return xy, meets
