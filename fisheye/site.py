"""Site pose: the rigid transform from a camera's floor frame into a shared site frame, and its fit
from floor points whose site positions are known."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field

from fisheye.arrays import as_points


class SitePose(BaseModel):
    """Where a camera's floor frame sits in the site frame: its nadir at (x_m, y_m), its x axis
    turned counter-clockwise by yaw_deg."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_deg: float = Field(default=0.0, ge=-360.0, le=360.0)

    def _rotation(self) -> NDArray[np.float64]:
        yaw = math.radians(self.yaw_deg)
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        return np.array([[cos_yaw, -sin_yaw], [sin_yaw, cos_yaw]])

    def floor_to_site(self, xy_m: ArrayLike) -> NDArray[np.float64]:
        """Camera floor frame (N, 2) m -> site frame (N, 2) m; NaN rows stay NaN."""
        points = as_points(xy_m, 2, "xy_m")
        return points @ self._rotation().T + np.array([self.x_m, self.y_m])

    def site_to_floor(self, xy_m: ArrayLike) -> NDArray[np.float64]:
        """Site frame (N, 2) m -> camera floor frame (N, 2) m."""
        points = as_points(xy_m, 2, "xy_m")
        return (points - np.array([self.x_m, self.y_m])) @ self._rotation()


@dataclass(frozen=True)
class SitePoseFit:
    """A fitted pose and how well it places the points: `residuals_m` (N,) distance between each
    point's known site position and where the pose puts it, their RMS and maximum."""

    pose: SitePose
    residuals_m: NDArray[np.float64]

    @property
    def rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_m**2)))

    @property
    def max_m(self) -> float:
        return float(self.residuals_m.max())


def fit_site_pose(floor_xy_m: ArrayLike, site_xy_m: ArrayLike) -> SitePoseFit:
    """The rigid pose (no scale) that best maps floor points (N, 2) m of a camera onto their known
    site positions (N, 2) m, in least squares (Kabsch); N ≥ 2 points, not all at one place.

    A yaw error of 1° moves a point 8 m from the nadir by 14 cm: points far apart fix the yaw best.
    """
    floor = as_points(floor_xy_m, 2, "floor_xy_m")
    site = as_points(site_xy_m, 2, "site_xy_m")
    if len(floor) != len(site):
        raise ValueError(f"{len(floor)} floor points but {len(site)} site points")
    if len(floor) < 2:
        raise ValueError(f"a site pose needs at least 2 points, got {len(floor)}")
    if not (np.isfinite(floor).all() and np.isfinite(site).all()):
        raise ValueError("the points must be finite numbers")
    floor_mean, site_mean = floor.mean(axis=0), site.mean(axis=0)
    floor_centred, site_centred = floor - floor_mean, site - site_mean
    if np.hypot(*floor_centred.T).max() < 1e-3:
        raise ValueError("the floor points must not all lie at one place")
    # 2-D Kabsch: the angle that best turns the centred floor points onto the centred site points.
    cross = float(np.sum(floor_centred[:, 0] * site_centred[:, 1] - floor_centred[:, 1] * site_centred[:, 0]))
    dot = float(np.sum(floor_centred * site_centred))
    yaw = math.atan2(cross, dot)
    rotation = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    offset = site_mean - rotation @ floor_mean
    yaw_deg = (math.degrees(yaw) + 180.0) % 360.0 - 180.0
    pose = SitePose(x_m=float(offset[0]), y_m=float(offset[1]), yaw_deg=yaw_deg)
    residuals = np.hypot(*(pose.floor_to_site(floor) - site).T)
    return SitePoseFit(pose, residuals)
