"""Site pose: the rigid transform from a camera's floor frame into a shared site frame."""

from __future__ import annotations

import math

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
