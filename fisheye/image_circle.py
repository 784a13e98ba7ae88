"""The image circle of a fisheye frame: the bright disk the lens draws on the sensor's dark border.

`fit_image_circle(image)` finds its centre (the principal point of a lens whose axis meets the
sensor there) and radius from the frame alone:

1. a grey level (the brightest channel, median-filtered against JPEG ringing) at a working scale;
2. a threshold from the frame's own statistics: the border's level (a low percentile) and the
   scene's (the median of the middle), or a refusal when the two do not differ;
3. rays from a centre guess out to the frame's edge; walking each inward from the edge, the rim is
   the first crossing into a run of bright samples, placed at half height between the border's and
   the rim's local levels; a ray that is bright at the frame's edge ends inside the circle (the frame
   cuts it there) and gives no point, so a circle wider than the frame is fitted from the parts of
   its rim that show;
4. RANSAC over three-point circles, then least squares on the inliers with outlier rejection
   (`fisheye.circle_fit`; twice, the second time with rays cast from the first circle's centre);
5. checks that refuse what is not an image circle: too little visible rim, a border that is not dark
   outside the fitted circle, a centre outside the frame.

`camera_from_circle` turns a circle into a starting camera: an ideal equidistant 180° lens whose 90°
ring is the circle (`kb = [1]`, `fx = fy = R / (π/2)`); `camera_of_uncalibrated_frame` is the camera
assumed for a frame nobody calibrated: its circle's, or the shorter side's where none shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from fisheye.calibration import FitNote
from fisheye.camera import DEFAULT_MAX_THETA_DEG, FisheyeCamera
from fisheye.camera_file import (
    ASSUMED_ALTITUDE_M,
    ASSUMED_CAMERA_ID,
    CalibrationError,
    assumed_camera,
    camera_from_dict,
)
from fisheye.circle_fit import circle_residuals_px, ransac_circle

FloatArray = NDArray[np.float64]

MIN_SIDE_PX = 32
WORK_SIDE_PX = 1024  # the fit runs at most this long a side; the rim is placed to a fraction of a px
_RAYS = 720
_MIN_CONTRAST = 20.0  # grey levels between the border and the scene
_MIN_RIM_POINTS = 24
_MIN_RIM_ARC_DEG = 40.0  # the rim must show over at least this much of its angle
_MIN_INLIER_FRACTION = 0.4
_MAX_BRIGHT_OUTSIDE = 0.1  # fraction of the frame outside the circle that may be bright


@dataclass(frozen=True)
class CircleCut:
    """Where the frame cuts the circle (each side the circle passes beyond) and the fraction of the
    rim's length that lies inside the frame."""

    top: bool
    bottom: bool
    left: bool
    right: bool
    visible_rim_fraction: float

    @property
    def any(self) -> bool:
        return self.top or self.bottom or self.left or self.right

    def sides(self) -> list[str]:
        return [name for name in ("top", "bottom", "left", "right") if getattr(self, name)]


@dataclass(frozen=True)
class ImageCircle:
    """A fitted image circle: `center_px` (u0, v0) and `radius_px` R in frame px of a frame of
    `image_wh`; `rim_points_px` (N, 2) the rim points found and `inliers` (N,) those the circle fits;
    `rms_px` the inliers' RMS distance from the circle (frame px); `cut` where the frame cuts it."""

    center_px: tuple[float, float]
    radius_px: float
    image_wh: tuple[int, int]
    rim_points_px: FloatArray
    inliers: NDArray[np.bool_]
    rms_px: float
    cut: CircleCut
    rays: int
    notes: tuple[FitNote, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.rim_points_px.shape != (len(self.inliers), 2):
            raise ValueError(f"rim_points_px {self.rim_points_px.shape} and inliers "
                             f"{self.inliers.shape} disagree")
        if not (math.isfinite(self.radius_px) and self.radius_px > 0):
            raise ValueError(f"radius_px must be positive, got {self.radius_px}")

    @property
    def inlier_fraction(self) -> float:
        """Inliers among the rim points found (0 when none were)."""
        return float(self.inliers.mean()) if len(self.inliers) else 0.0


# ----- rim points along rays


@dataclass(frozen=True)
class _Levels:
    border: float
    scene: float
    threshold: float


def grey_levels(image: NDArray[np.uint8]) -> NDArray[np.float32]:
    """(H, W) or (H, W, C) uint8 -> (H, W) float32: the brightest channel (a coloured scene is
    bright in one channel at least), median-filtered against JPEG ringing and noise."""
    if image.ndim == 3:
        image = np.ascontiguousarray(image.max(axis=2))
    return np.asarray(cv2.medianBlur(np.ascontiguousarray(image, dtype=np.uint8), 3), dtype=np.float32)


def _levels(grey: NDArray[np.float32]) -> _Levels:
    height, width = grey.shape
    border = float(np.percentile(grey, 1.0))
    yy, xx = np.ogrid[:height, :width]
    # The scene's level over most of the middle, so a dark floor below the lens does not pass for it.
    middle = np.hypot(xx - (width - 1) / 2, yy - (height - 1) / 2) <= 0.4 * min(width, height)
    scene = float(np.median(grey[middle]))
    if scene - border < _MIN_CONTRAST:
        raise CalibrationError(
            f"no image circle: the middle of the frame (grey {scene:.0f}) is not brighter than its "
            f"darkest part (grey {border:.0f}); a fisheye frame shows a bright disk on a dark border",
            code="no_circle")
    return _Levels(border, scene, border + max(8.0, 0.25 * (scene - border)))


def _ray_ends(centre: tuple[float, float], angles: FloatArray, wh: tuple[int, int]) -> FloatArray:
    """(A,) ray angles from `centre` -> (A,) distances to the frame's edge (pixel centres inset)."""
    width, height = wh
    u0, v0 = centre
    cos, sin = np.cos(angles), np.sin(angles)
    with np.errstate(divide="ignore", invalid="ignore"):
        tu = np.where(cos > 1e-12, (width - 1 - u0) / cos, np.where(cos < -1e-12, -u0 / cos, np.inf))
        tv = np.where(sin > 1e-12, (height - 1 - v0) / sin, np.where(sin < -1e-12, -v0 / sin, np.inf))
    return np.asarray(np.maximum(np.minimum(tu, tv), 0.0))


def rim_points(grey: NDArray[np.float32], centre: tuple[float, float], threshold: float,
               rays: int = _RAYS) -> tuple[FloatArray, int]:
    """(H, W) grey levels -> (N, 2) rim points (px of `grey`) along `rays` rays from `centre`, and
    how many rays end bright at the frame's edge (inside the circle: the frame cuts it there)."""
    height, width = grey.shape
    angles = np.arange(rays, dtype=np.float64) * (2 * math.pi / rays)
    ends = _ray_ends(centre, angles, (width, height))
    length = math.ceil(ends.max()) + 1
    steps = np.arange(length, dtype=np.float64)  # one sample per px from the centre outward
    map_u = (centre[0] + np.cos(angles)[:, None] * steps).astype(np.float32)
    map_v = (centre[1] + np.sin(angles)[:, None] * steps).astype(np.float32)
    profiles = np.asarray(cv2.remap(grey, map_u, map_v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE),
                          dtype=np.float32)
    run = max(3, round(0.01 * max(width, height)))
    points, cut = [], 0
    for index in range(rays):
        last = math.floor(ends[index])
        if last < 2 * run:
            continue
        profile = profiles[index, :last + 1]
        bright = profile >= threshold
        if bright[-run:].mean() > 0.5:
            cut += 1
            continue
        # The outermost sample that starts `run` bright samples inward: skips thin bright marks
        # (timestamps, dust) in the border.
        kernel = np.convolve(bright.astype(np.int32), np.ones(run, dtype=np.int32), "valid")
        starts = np.flatnonzero(kernel == run)
        if starts.size == 0:
            continue
        k = int(starts[-1]) + run - 1  # the run's outer end
        radius = _half_height(profile, k, run)
        if radius is not None:
            points.append((centre[0] + math.cos(angles[index]) * radius,
                           centre[1] + math.sin(angles[index]) * radius))
    return np.asarray(points, dtype=np.float64).reshape(-1, 2), cut


def _half_height(profile: NDArray[np.float32], k: int, run: int) -> float | None:
    """The rim's radius along one ray: where the profile falls through half way between the rim's
    level just inside sample `k` and the border's just outside it, to a fraction of a sample."""
    inside = float(np.median(profile[max(0, k - 3 * run):k + 1]))
    outside = float(np.median(profile[k + 1:k + 1 + 2 * run])) if k + 1 < len(profile) else inside
    if inside - outside < 4.0:
        return None
    half = 0.5 * (inside + outside)
    lo, hi = max(0, k - 2 * run), min(len(profile) - 1, k + 2 * run)
    window = profile[lo:hi + 1]
    above = np.flatnonzero(window >= half)
    if above.size == 0:
        return None
    i = lo + int(above[-1])  # the last sample at or above half height
    if i + 1 >= len(profile):
        return float(i)
    a, b = float(profile[i]), float(profile[i + 1])
    return i + (a - half) / (a - b) if a > b else float(i)


# ----- the fit


def _bright_mask_centre(grey: NDArray[np.float32], threshold: float) -> tuple[float, float]:
    v, u = np.nonzero(grey >= threshold)
    return float(u.mean()), float(v.mean())


def circle_cut(center_px: tuple[float, float], radius_px: float, image_wh: tuple[int, int]) -> CircleCut:
    """Which sides of a frame of `image_wh` cut the circle, and the fraction of its rim inside."""
    width, height = image_wh
    u0, v0 = center_px
    angles = np.linspace(0.0, 2 * math.pi, 3600, endpoint=False)
    u, v = u0 + radius_px * np.cos(angles), v0 + radius_px * np.sin(angles)
    inside = (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)
    return CircleCut(top=v0 - radius_px < -0.5, bottom=v0 + radius_px > height - 0.5,
                     left=u0 - radius_px < -0.5, right=u0 + radius_px > width - 0.5,
                     visible_rim_fraction=float(inside.mean()))


def _arc_span_deg(points: FloatArray, centre: tuple[float, float]) -> float:
    """Degrees of angle about `centre` the points cover, counting 10° bins that hold any."""
    angles = np.degrees(np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0])) % 360.0
    return 10.0 * len(np.unique((angles // 10).astype(int)))


def _bright_outside(grey: NDArray[np.float32], circle: tuple[float, float, float], threshold: float,
                    margin: float) -> float | None:
    """Fraction of the frame beyond the circle (by `margin` px) that is bright; None when none is."""
    height, width = grey.shape
    yy, xx = np.ogrid[:height, :width]
    outside = np.hypot(xx - circle[0], yy - circle[1]) > circle[2] + margin
    if not outside.any():
        return None
    return float((grey[outside] >= threshold).mean())


def fit_image_circle(image: NDArray[np.uint8], frame_wh: tuple[int, int] | None = None,
                     rays: int = _RAYS) -> ImageCircle:
    """(H, W) or (H, W, 3) uint8 frame -> its fitted image circle in frame px. `frame_wh` is the
    size of the frame when `image` is a reduced copy of it (same aspect ratio; e.g. a JPEG decoded
    at 1/2 scale): the circle comes back in the frame's px.

    CalibrationError codes: `frame_too_small`, `no_circle` (no bright disk on a dark border, or
    what was found is not one), `no_visible_rim` (the circle covers the frame: no rim shows, so it
    cannot be measured; use an assumed or measured camera instead).
    """
    if image.ndim not in (2, 3) or image.dtype != np.uint8:
        raise ValueError(f"image must be (H, W) or (H, W, C) uint8, got {image.shape} {image.dtype}")
    height, width = image.shape[:2]
    frame_w, frame_h = (width, height) if frame_wh is None else frame_wh
    if min(width, height, frame_w, frame_h) < MIN_SIDE_PX:
        raise CalibrationError(f"the frame is {frame_w}x{frame_h}; fitting an image circle needs at least "
                               f"{MIN_SIDE_PX} px a side", code="frame_too_small")
    scale = min(1.0, WORK_SIDE_PX / max(width, height))
    grey = grey_levels(image)
    if scale < 1.0:
        size = (max(1, round(width * scale)), max(1, round(height * scale)))
        grey = np.asarray(cv2.resize(grey, size, interpolation=cv2.INTER_AREA), dtype=np.float32)
    # Work px -> frame px: centres of pixels at integers on both (as cv2.resize maps them).
    sx, sy = frame_w / grey.shape[1], frame_h / grey.shape[0]
    levels = _levels(grey)
    centre = _bright_mask_centre(grey, levels.threshold)
    points = np.zeros((0, 2))
    circle: tuple[float, float, float] | None = None
    inliers = np.zeros(0, dtype=bool)
    for _ in range(2):
        points, cut_rays = rim_points(grey, centre, levels.threshold, rays)
        if cut_rays >= 0.9 * rays:
            raise _refused("almost no ray from the middle meets a dark border", cut_rays, rays)
        if len(points) < _MIN_RIM_POINTS:
            break
        tolerance = max(1.5, 0.005 * max(grey.shape))
        try:
            circle, inliers = ransac_circle(points, tolerance)
        except ValueError:
            circle = None
            break
        centre = (circle[0], circle[1])
    if circle is None or inliers.sum() < _MIN_RIM_POINTS:
        raise _refused(f"{len(points)} rim points found along {rays} rays ({int(inliers.sum())} on one "
                       f"circle), {_MIN_RIM_POINTS} are needed", cut_rays, rays)
    return _checked(grey, circle, points, inliers, levels, (frame_w, frame_h), (sx, sy), (rays, cut_rays))


def _refused(reason: str, cut_rays: int, rays: int) -> CalibrationError:
    """The refusal for `reason`: `no_visible_rim` when most rays from the middle stay bright up to the
    frame's edge (the circle seems to cover the frame), else `no_circle`."""
    if cut_rays >= 0.5 * rays:
        return CalibrationError(
            f"no visible rim: {cut_rays} of {rays} rays from the frame's middle stay bright up to the "
            f"frame's edge, so the image circle seems to cover the frame ({reason}); its centre and "
            "radius cannot be measured: give the camera's principal point and focal, or use the "
            "assumed camera", code="no_visible_rim")
    return CalibrationError(f"no image circle: {reason}", code="no_circle")


def _checked(grey: NDArray[np.float32], circle: tuple[float, float, float], points: FloatArray,
             inliers: NDArray[np.bool_], levels: _Levels, image_wh: tuple[int, int],
             scale_xy: tuple[float, float], ray_counts: tuple[int, int]) -> ImageCircle:
    """The fitted circle in frame px after the checks that refuse what is not an image circle;
    `ray_counts` are the rays cast and those that ended bright at the frame's edge."""
    width, height = image_wh
    rays, cut_rays = ray_counts
    sx, sy = scale_xy
    span = _arc_span_deg(points[inliers], (circle[0], circle[1]))
    if span < _MIN_RIM_ARC_DEG:
        raise CalibrationError(
            f"no visible rim: the rim points found cover only {span:.0f}° of the circle (at least "
            f"{_MIN_RIM_ARC_DEG:.0f}° are needed to measure it)", code="no_visible_rim")
    fraction = float(inliers.mean())
    if fraction < _MIN_INLIER_FRACTION:
        raise _refused(f"only {fraction:.0%} of the {len(points)} rim points lie on one circle",
                       cut_rays, rays)
    bright = _bright_outside(grey, circle, levels.threshold, margin=max(3.0, 0.01 * circle[2]))
    if bright is not None and bright > _MAX_BRIGHT_OUTSIDE:
        raise _refused(f"{bright:.0%} of the frame outside the best circle is bright; the border around "
                       "a fisheye's image circle is dark", cut_rays, rays)
    center = ((circle[0] + 0.5) * sx - 0.5, (circle[1] + 0.5) * sy - 0.5)
    radius = circle[2] * math.sqrt(sx * sy)
    if not (0 <= center[0] <= width - 1 and 0 <= center[1] <= height - 1):
        raise CalibrationError(
            f"no image circle: the fitted centre ({center[0]:.1f}, {center[1]:.1f}) lies outside the "
            f"{width}x{height} frame", code="no_circle")
    frame_points = (points + 0.5) * np.array([sx, sy]) - 0.5
    residual = circle_residuals_px(frame_points[inliers], (*center, radius))
    cut = circle_cut(center, radius, image_wh)
    notes = [FitNote("image_circle", f"image circle: centre ({center[0]:.1f}, {center[1]:.1f}) px, "
                                     f"radius {radius:.1f} px, from {int(inliers.sum())} rim points "
                                     f"along {rays} rays")]
    if cut.any:
        notes.append(FitNote(
            "circle_cut", f"the frame cuts the circle at its {', '.join(cut.sides())}: "
                          f"{cut.visible_rim_fraction:.0%} of the rim shows, and only that part was fitted"))
    if fraction < 0.7:
        notes.append(FitNote("rim_outliers", f"{1 - fraction:.0%} of the rim points found lie off the "
                                             "circle (dark scene at the rim, marks in the border)",
                             "warning"))
    return ImageCircle(center_px=(float(center[0]), float(center[1])), radius_px=float(radius),
                       image_wh=image_wh, rim_points_px=frame_points, inliers=inliers,
                       rms_px=float(np.sqrt(np.mean(residual ** 2))), cut=cut, rays=rays,
                       notes=tuple(notes))


def camera_from_circle(circle: ImageCircle, camera_id: str = "camera",
                       altitude_m: float = ASSUMED_ALTITUDE_M) -> FisheyeCamera:
    """A starting camera from an image circle: an ideal equidistant 180° lens (`kb = [1]`) whose
    90° ring is the circle (`fx = fy = R / (π/2)`), its principal point the circle's centre,
    `altitude_m` up (a guess until measured), `max_theta_deg` 90."""
    focal = circle.radius_px / (math.pi / 2)
    return camera_from_dict({
        "id": camera_id,
        "altitude_m": altitude_m,
        "image_size": list(circle.image_wh),
        "principal_point": [round(circle.center_px[0], 2), round(circle.center_px[1], 2)],
        "focal_px": [round(focal, 3), round(focal, 3)],
        "kb": [1.0],
        "max_theta_deg": DEFAULT_MAX_THETA_DEG,
    })


def starting_camera_notes(circle: ImageCircle, camera: FisheyeCamera) -> tuple[FitNote, ...]:
    """The circle's notes and one on what the starting camera from it is (and is not)."""
    return (*circle.notes, FitNote(
        "starting_camera",
        f"starting camera: an ideal equidistant 180° lens (kb [1], focal {camera.focal_px[0]:.1f} px = "
        f"R / (π/2)) {camera.altitude_m:g} m up; floor positions are estimates until the altitude is "
        "measured and the lens fitted from ruler marks"))


def camera_of_uncalibrated_frame(image: NDArray[np.uint8], frame_wh: tuple[int, int] | None = None,
                                 camera_id: str = ASSUMED_CAMERA_ID) -> tuple[FisheyeCamera, FitNote]:
    """The camera assumed for a frame nobody calibrated, from the frame itself: the starting camera
    of its image circle (also one wider than the frame), or, where no circle can be measured, the
    camera whose circle fills the frame's shorter side (`assumed_camera`); the note says which and
    why."""
    height, width = image.shape[:2]
    wh = (width, height) if frame_wh is None else frame_wh
    try:
        circle = fit_image_circle(image, wh)
    except CalibrationError as error:
        fallback = assumed_camera(*wh).model_copy(update={"id": camera_id})
        return fallback, FitNote("assumed_short_side", f"no image circle ({error}); assumed the circle "
                                                       "that fills the frame's shorter side", "warning")
    camera = camera_from_circle(circle, camera_id)
    return camera, FitNote("assumed_image_circle", f"assumed the camera of the frame's image circle: "
                                                   f"centre ({circle.center_px[0]:.1f}, "
                                                   f"{circle.center_px[1]:.1f}) px, radius "
                                                   f"{circle.radius_px:.1f} px")
