"""A calibrated overhead fisheye camera: Kannala–Brandt lens, altitude, and the floor below it.

Frames (DESIGN.md): pixels `u` right, `v` down, centres at integers. The floor frame has its origin
at the nadir, `x` towards image right, `y` towards image top, `z` up; rays are unit vectors in that
frame pointing away from the lens (straight down is (0, 0, -1)).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from fisheye.arrays import as_points, resolution_scale, scale_pixels
from fisheye.lens import monotonic_violation, radius_to_theta, theta_to_radius
from fisheye.masks import MAX_MASKS, points_in_masks, polygon_problem
from fisheye.site import SitePose
from fisheye.tilt import MAX_TILT_DEG, floor_to_lens_rays, is_level, lens_to_floor_rays, rays_to_floor

FloatArray = NDArray[np.float64]
Polygons = list[list[tuple[float, float]]]

CAMERA_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$"
_CAMERA_ID_RE = re.compile(CAMERA_ID_PATTERN)
DEFAULT_MAX_THETA_DEG = 90.0
# Frames whose aspect ratio differs from the calibration's by more than one pixel are refused.
_ASPECT_TOLERANCE_PX = 1.0
# Real lenses have |k| well under 10; far larger values only overflow the lens arithmetic.
_MAX_KB_ABS = 1000.0
# The range of a view budget (model-input px): a camera's own, the server's (`service.core.config`).
MIN_VIEW_PIXELS = 64 * 64
MAX_VIEW_PIXELS = 64_000_000
# The most input px a second look may take (`fisheye.view_plan.ViewPlanConfig.second_look_pixels`):
# 64 patches of 256 x 256.
MAX_SECOND_LOOK_PIXELS = 64 * 256 * 256
# The range of a bound on a person's length along the ray, in standing adults
# (`fisheye.view_plan.ViewPlanConfig.longest_person_ratio`); a camera's record may also say 0: none.
MIN_LONGEST_PERSON_RATIO, MAX_LONGEST_PERSON_RATIO = 1.0, 10.0


@dataclass(frozen=True)
class FloorPoints:
    """Floor positions of N pixels: `xy_m` (N, 2) m and `distance_m` (N,) m from the nadir, NaN
    where `valid` (N,) is False (the ray misses the floor or leaves the calibrated field)."""

    xy_m: FloatArray
    distance_m: FloatArray
    valid: NDArray[np.bool_]

    def __post_init__(self) -> None:
        n = len(self.valid)
        if self.xy_m.shape != (n, 2) or self.distance_m.shape != (n,):
            raise ValueError(
                f"FloorPoints arrays disagree: xy_m {self.xy_m.shape}, "
                f"distance_m {self.distance_m.shape}, valid {self.valid.shape}"
            )


class FisheyeCamera(BaseModel):
    """One camera's calibration record (the camera file of DESIGN.md) and its geometry."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    id: str = Field(description="Camera id: letters, digits, '.', '_', '-'; at most 64 characters.")
    altitude_m: float = Field(gt=0, le=1000, description="Lens height above the floor (m).")
    image_size: tuple[int, int] = Field(description="[width, height] the calibration was made at (px).")
    principal_point: tuple[float, float] = Field(description="[u0, v0] (px).")
    focal_px: tuple[float, float] = Field(description="[fx, fy] (px per unit normalised radius).")
    kb: list[float] = Field(min_length=1, max_length=5, description="k1..k5 of r(θ).")
    max_theta_deg: float | None = Field(default=None, gt=0, lt=180)
    tilt_deg: tuple[float, float] | None = Field(
        default=None, description="[a, b]: rotation of the lens about the floor x, then y axis (deg); "
                                  "absent or [0, 0] is a level camera.")
    masks_px: Polygons | None = Field(
        default=None, description="Polygons [[u, v], ...] at image_size where nobody is counted.")
    site: str | None = Field(default=None, pattern=CAMERA_ID_PATTERN,
                             description="The site (floor plan) the camera belongs to.")
    site_pose: SitePose | None = None
    max_view_pixels: int | None = Field(
        default=None, ge=MIN_VIEW_PIXELS, le=MAX_VIEW_PIXELS,
        description="This camera's own budget for a planned view (model-input px, width × height), in "
                    "place of the server's --max-view-pixels and at most its --max-camera-view-pixels.")
    second_look_pixels: int | None = Field(
        default=None, ge=0, le=MAX_SECOND_LOOK_PIXELS,
        description="This camera's own budget for the second look at its frames' small, uncertain "
                    "detections (input px of its one run), in place of the server's --second-look: "
                    "786432 for a crowded scene, 0 for none.")
    longest_person_ratio: float | None = Field(
        default=None, ge=0, le=MAX_LONGEST_PERSON_RATIO,
        description="This camera's own bound on a detection's length along the ray, in standing adults "
                    "where its feet stand (1-10), in place of the server's --longest-person-ratio: 1.8 "
                    "for a calibrated camera, 0 for none.")

    @field_validator("longest_person_ratio")
    @classmethod
    def _check_longest_person_ratio(cls, value: float | None) -> float | None:
        if value is not None and 0 < value < MIN_LONGEST_PERSON_RATIO:
            raise ValueError(f"longest_person_ratio must be 0 (none) or lie in "
                             f"[{MIN_LONGEST_PERSON_RATIO:g}, {MAX_LONGEST_PERSON_RATIO:g}] standing adults")
        return value

    @field_validator("id")
    @classmethod
    def _check_id(cls, value: str) -> str:
        if not _CAMERA_ID_RE.fullmatch(value):  # match() would let a trailing newline through
            raise ValueError(
                "camera id must be 1-64 characters of letters, digits, '.', '_' or '-', "
                "starting with a letter or digit"
            )
        return value

    @field_validator("image_size")
    @classmethod
    def _check_image_size(cls, value: tuple[int, int]) -> tuple[int, int]:
        if min(value) < 2 or max(value) > 20000:
            raise ValueError(f"image_size must be within [2, 20000] px, got {list(value)}")
        return value

    @field_validator("focal_px")
    @classmethod
    def _check_focal(cls, value: tuple[float, float]) -> tuple[float, float]:
        if min(value) <= 0:
            raise ValueError(f"focal_px must be positive, got {list(value)}")
        return value

    @field_validator("tilt_deg")
    @classmethod
    def _check_tilt(cls, value: tuple[float, float] | None) -> tuple[float, float] | None:
        if value is not None and max(abs(value[0]), abs(value[1])) > MAX_TILT_DEG:
            raise ValueError(f"tilt_deg must lie within ±{MAX_TILT_DEG:g}° per axis, got {list(value)}")
        return value

    @field_validator("masks_px")
    @classmethod
    def _check_masks(cls, value: Polygons | None) -> Polygons | None:
        if value is not None and len(value) > MAX_MASKS:
            raise ValueError(f"masks_px may hold at most {MAX_MASKS} polygons, got {len(value)}")
        for index, polygon in enumerate(value or []):
            problem = polygon_problem(np.array(polygon, dtype=np.float64).reshape(-1, 2))
            if problem is not None:
                raise ValueError(f"mask {index + 1}: {problem}")
        return value

    @model_validator(mode="after")
    def _check_geometry(self) -> FisheyeCamera:
        width, height = self.image_size
        u0, v0 = self.principal_point
        if not (0 <= u0 <= width - 1 and 0 <= v0 <= height - 1):
            raise ValueError(
                f"principal_point {list(self.principal_point)} lies outside the image "
                f"{width}x{height}"
            )
        if self.kb[0] <= 0:
            raise ValueError(f"kb[0] (k1) must be positive, got {self.kb[0]}")
        if max(abs(k) for k in self.kb) > _MAX_KB_ABS:
            raise ValueError(f"kb coefficients must lie within ±{_MAX_KB_ABS:g}, got {self.kb}")
        bad_theta = monotonic_violation(self.kb, self.theta_max_rad)
        if bad_theta is not None:
            raise ValueError(
                f"kb {self.kb}: r(θ) is not strictly increasing on [0, {self.theta_max_deg:g}°] "
                f"(it stops at θ = {math.degrees(bad_theta):.2f}°); lower max_theta_deg or fix kb"
            )
        for index, polygon in enumerate(self.masks_px or []):
            corners = np.array(polygon, dtype=np.float64)
            # A corner may sit on the outer edge of the border pixels, half a pixel beyond their centres.
            beyond = (corners < -0.5) | (corners > np.array([width, height]) - 0.5)
            outside = np.flatnonzero(beyond.any(axis=1))
            if outside.size:
                corner = int(outside[0])
                raise ValueError(f"mask {index + 1}: corner {corner + 1} {list(polygon[corner])} lies "
                                 f"outside the image {width}x{height}")
        return self

    # ----- derived values

    @property
    def theta_max_deg(self) -> float:
        return DEFAULT_MAX_THETA_DEG if self.max_theta_deg is None else self.max_theta_deg

    @property
    def theta_max_rad(self) -> float:
        return math.radians(self.theta_max_deg)

    @property
    def resolution_wh(self) -> tuple[int, int]:
        return self.image_size

    @property
    def is_level(self) -> bool:
        """Whether the optical axis points straight down (`tilt_deg` absent or [0, 0])."""
        return is_level(self.tilt_deg)

    @property
    def _tilt(self) -> tuple[float, float] | None:
        """`tilt_deg` of a tilted camera; None for a level one, whose rays need no rotation."""
        return None if is_level(self.tilt_deg) else self.tilt_deg

    def scaled_to(self, resolution_wh: tuple[int, int]) -> FisheyeCamera:
        """This camera for frames of another resolution with the same aspect ratio.

        Pixel centres sit at integers, so a pixel coordinate maps as u' = (u + 0.5)·s − 0.5 (as
        cv2.resize does); focal lengths scale by s.
        """
        width, height = int(resolution_wh[0]), int(resolution_wh[1])
        if (width, height) == tuple(self.image_size):
            return self
        try:
            scale = resolution_scale(self.image_size, (width, height), _ASPECT_TOLERANCE_PX)
        except ValueError as error:
            raise ValueError(f"camera {self.id!r}: {error} (its calibration)") from None
        u0, v0 = self.principal_point
        fx, fy = self.focal_px
        update: dict[str, object] = {
            "image_size": (width, height),
            "principal_point": ((u0 + 0.5) * scale[0] - 0.5, (v0 + 0.5) * scale[1] - 0.5),
            "focal_px": (fx * scale[0], fy * scale[1]),
        }
        if self.masks_px:
            update["masks_px"] = [[(float(u), float(v)) for u, v in scale_pixels(polygon, scale)]
                                  for polygon in self.masks_px]
        return self.model_copy(update=update)

    # ----- pixels <-> rays

    def pixels_to_angles(self, uv_px: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(N, 2) px -> θ (N,) rad from the optical axis and φ (N,) rad, the lens azimuth
        (counter-clockwise from +x; the floor-frame azimuth of a level camera). θ is NaN outside the
        calibrated field (θ > θmax)."""
        uv = as_points(uv_px, 2, "uv_px")
        x_norm = (uv[:, 0] - self.principal_point[0]) / self.focal_px[0]
        y_norm = -(uv[:, 1] - self.principal_point[1]) / self.focal_px[1]
        theta = radius_to_theta(np.hypot(x_norm, y_norm), self.kb, self.theta_max_rad)
        phi = np.arctan2(y_norm, x_norm)
        return theta, phi

    def pixels_to_rays(self, uv_px: ArrayLike) -> FloatArray:
        """(N, 2) px -> (N, 3) unit rays in the floor frame; NaN rows outside the calibrated field."""
        theta, phi = self.pixels_to_angles(uv_px)
        sin_theta = np.sin(theta)
        rays = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), -np.cos(theta)], axis=1)
        tilt = self._tilt
        return rays if tilt is None else lens_to_floor_rays(rays, tilt)

    def rays_to_pixels(self, rays: ArrayLike) -> FloatArray:
        """(N, 3) rays in the floor frame (any length) -> (N, 2) px; NaN rows beyond θmax."""
        directions = as_points(rays, 3, "rays")
        tilt = self._tilt
        if tilt is not None:
            directions = floor_to_lens_rays(directions, tilt)
        horizontal = np.hypot(directions[:, 0], directions[:, 1])
        theta = np.arctan2(horizontal, -directions[:, 2])
        radius = theta_to_radius(theta, self.kb)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos_phi = np.where(horizontal > 0, directions[:, 0] / horizontal, 1.0)
            sin_phi = np.where(horizontal > 0, directions[:, 1] / horizontal, 0.0)
        u = self.principal_point[0] + self.focal_px[0] * radius * cos_phi
        v = self.principal_point[1] - self.focal_px[1] * radius * sin_phi
        uv = np.stack([u, v], axis=1)
        uv[theta > self.theta_max_rad + 1e-12] = np.nan
        return uv

    # ----- pixels <-> floor

    def floor_positions(self, uv_px: ArrayLike) -> FloorPoints:
        """(N, 2) px -> floor positions with distances and a validity mask (see FloorPoints)."""
        if self._tilt is not None:
            xy, valid = rays_to_floor(self.pixels_to_rays(uv_px), self.altitude_m)
            return FloorPoints(xy_m=xy, distance_m=np.hypot(xy[:, 0], xy[:, 1]), valid=valid)
        theta, phi = self.pixels_to_angles(uv_px)
        valid = np.isfinite(theta) & np.isfinite(phi) & (theta < math.pi / 2)
        distance = np.full(theta.shape, np.nan)
        distance[valid] = self.altitude_m * np.tan(theta[valid])
        xy = np.stack([distance * np.cos(phi), distance * np.sin(phi)], axis=1)
        return FloorPoints(xy_m=xy, distance_m=distance, valid=valid)

    def pixels_to_floor(self, uv_px: ArrayLike) -> FloatArray:
        """(N, 2) px -> (N, 2) m on the floor; NaN where there is no floor point."""
        return self.floor_positions(uv_px).xy_m

    def world_to_pixels(self, xyz_m: ArrayLike) -> FloatArray:
        """(N, 3) points in the floor frame (m, z up) -> (N, 2) px; NaN beyond θmax."""
        points = as_points(xyz_m, 3, "xyz_m")
        return self.rays_to_pixels(points - np.array([0.0, 0.0, self.altitude_m]))

    def floor_to_pixels(self, xy_m: ArrayLike) -> FloatArray:
        """(N, 2) m on the floor -> (N, 2) px; NaN beyond θmax."""
        points = as_points(xy_m, 2, "xy_m")
        return self.world_to_pixels(np.concatenate([points, np.zeros((len(points), 1))], axis=1))

    def floor_to_site(self, xy_m: ArrayLike) -> FloatArray | None:
        """(N, 2) floor-frame m -> (N, 2) site-frame m, or None when the camera has no site pose (a
        camera of a site without one stands at the site's origin, unturned)."""
        pose = self.site_pose or (SitePose() if self.site is not None else None)
        return None if pose is None else pose.floor_to_site(xy_m)

    def masked(self, uv_px: ArrayLike) -> NDArray[np.bool_]:
        """(N, 2) px -> (N,) whether each pixel lies inside one of the camera's mask polygons."""
        return points_in_masks(uv_px, self.masks_px or [])

    def image_circle_radius_px(self) -> float:
        """Radius (px, along u) of the calibrated field θ ≤ θmax around the principal point."""
        return float(self.focal_px[0] * theta_to_radius(self.theta_max_rad, self.kb))
