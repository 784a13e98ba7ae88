"""Fit a camera's lens from ruler marks on the floor (the LOAF paper's protocol, fisheye.ruler_marks).

A mark at floor distance d from the nadir is seen at θ = atan(d / Z) from the optical axis (Z the
altitude) and at ρ = fx·r(θ) = Σ c_j·θ^(2j−1) px from the principal point, with c_j = fx·k_j. For a
fixed principal point and aspect ratio fy/fx, ρ is linear in c, so c comes from a linear least-squares
fit in pixels; the principal point and the aspect ratio, when they are fitted, are found by
Levenberg–Marquardt around that linear solve (variable projection).

The marks determine only the products fx·k_j. With `focal_px` unset, fx is fitted and k1 = 1
(OpenCV's normalisation, so the lens exports as K, D); with `focal_px` given, fx stays and k1 takes
the scale. Both describe the same lens.

r(θ) must increase strictly on [0, θmax] (FisheyeCamera refuses other lenses). The linear fit is
therefore solved under dρ/dθ ≥ ε on a dense grid of θ (an inequality-constrained least squares);
the result says when a constraint was active, i.e. when the unconstrained fit would have turned back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from fisheye.calibration_checks import (
    MIN_DIRECTION_SPREAD,
    MIN_TILT_DIRECTIONS,
    check_marks_in_image,
    check_nadir_marks,
    check_ruler_order,
    check_tilt_marks,
    count_directions,
    direction_spread,
)
from fisheye.camera import DEFAULT_MAX_THETA_DEG, FisheyeCamera
from fisheye.camera_file import CalibrationError, camera_from_dict
from fisheye.ruler_marks import RulerMarks
from fisheye.ruler_problem import RadialProblem, levenberg_marquardt, standard_errors

FloatArray = NDArray[np.float64]

MAX_COEFFICIENTS = 5
MAX_FITTED_RULERS = 32  # each fitted ruler direction is a parameter: the fit's work grows with its square
_MONOTONIC_SLOPE_FRACTION = 1e-3  # ε as a fraction of the marks' mean slope ρ/θ
_CLICK_NOISE_PX = 0.5  # the least noise a hand-clicked mark has, for the tilt's uncertainty
_MAX_TILT_SIGMA_DEG = 0.1  # a tilt known less well than this moves positions far out by centimetres
_SHORT_REACH_DEG = 60.0  # marks nearer the centre than this leave most of the floor extrapolated


@dataclass(frozen=True)
class RulerFitConfig:
    """What to fit. `coefficients`: number of kb terms (1..5). `focal_px`: keep this fx (k1 fitted);
    None fits fx with k1 = 1. `aspect_ratio`: fy/fx (kept unless `fit_aspect_ratio`).
    `principal_point`: [u0, v0] px; None takes the nadir mark. `fit_principal_point`: refine it from
    all marks. `max_theta_deg`: the camera's θmax (r(θ) is kept increasing up to it; None: 90°).
    `fit_tilt`: fit `tilt_deg` too (needs rulers in 3+ directions; fits the principal point unless
    it is given)."""

    coefficients: int = 3
    focal_px: float | None = None
    aspect_ratio: float = 1.0
    fit_aspect_ratio: bool = False
    principal_point: tuple[float, float] | None = None
    fit_principal_point: bool = False
    max_theta_deg: float | None = None
    fit_tilt: bool = False

    def __post_init__(self) -> None:
        if not 1 <= self.coefficients <= MAX_COEFFICIENTS:
            raise _options_error(f"coefficients must be 1 to {MAX_COEFFICIENTS}, got {self.coefficients}")
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise _options_error(f"focal_px must be a finite number > 0, got {self.focal_px}")
        if not (math.isfinite(self.aspect_ratio) and self.aspect_ratio > 0):
            raise _options_error(f"aspect_ratio must be a finite number > 0, got {self.aspect_ratio}")
        if self.principal_point is not None and not all(math.isfinite(p) for p in self.principal_point):
            raise _options_error(f"principal_point must be finite, got {self.principal_point}")
        if self.max_theta_deg is not None and not 0 < self.max_theta_deg < 180:
            raise _options_error(f"max_theta_deg must lie in (0, 180), got {self.max_theta_deg}")

    @property
    def theta_max_deg(self) -> float:
        return DEFAULT_MAX_THETA_DEG if self.max_theta_deg is None else self.max_theta_deg


def _options_error(message: str) -> CalibrationError:
    return CalibrationError(message, code="invalid_options")


@dataclass(frozen=True)
class FitNote:
    """A remark on a fit: a stable `code` (e.g. `tilt_undetermined`), `level` "info" or "warning",
    and the sentence for the user."""

    code: str
    message: str
    level: str = "info"

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class MarkResiduals:
    """Per mark (N,): the fitted camera's floor distance of the marked pixel, its error against the
    ruler (m, signed: positive when the camera puts the mark too far out), the floor position error
    (m, NaN for marks without x, y) and the pixel error (px, marked pixel to where the camera
    projects the mark's floor point; without x, y that point lies on the marked pixel's azimuth)."""

    fitted_distance_m: FloatArray
    distance_error_m: FloatArray
    position_error_m: FloatArray
    pixel_error_px: FloatArray

    def __post_init__(self) -> None:
        n = len(self.fitted_distance_m)
        shapes = {a.shape for a in (self.distance_error_m, self.position_error_m, self.pixel_error_px)}
        if shapes != {(n,)}:
            raise ValueError(f"MarkResiduals arrays disagree in shape: {shapes} vs ({n},)")


@dataclass(frozen=True)
class RulerFit:
    """A fitted camera, its residual on every mark, and notes for the user."""

    camera: FisheyeCamera
    marks: RulerMarks
    residuals: MarkResiduals
    theta_max_marked_deg: float
    monotonic_constrained: bool
    notes: tuple[FitNote, ...] = field(default=())

    @property
    def rms_m(self) -> float:
        """RMS floor-distance error over the marks (m)."""
        return float(np.sqrt(np.nanmean(self.residuals.distance_error_m ** 2)))

    @property
    def rms_px(self) -> float:
        """RMS pixel error over the marks (px)."""
        return float(np.sqrt(np.nanmean(self.residuals.pixel_error_px ** 2)))

    @property
    def max_abs_m(self) -> float:
        """Largest floor-distance error (m)."""
        return float(np.nanmax(np.abs(self.residuals.distance_error_m)))


def _initial_principal_point(marks: RulerMarks, config: RulerFitConfig, image_size: tuple[int, int],
                             fit_principal_point: bool) -> tuple[tuple[float, float], str]:
    if config.principal_point is not None:
        return config.principal_point, "given"
    nadir = marks.is_nadir
    if nadir.any():
        u0, v0 = marks.uv_px[nadir].mean(axis=0)
        return (float(u0), float(v0)), "the nadir mark" if nadir.sum() == 1 else "the mean of the nadir marks"
    if fit_principal_point:
        width, height = image_size
        return ((width - 1) / 2, (height - 1) / 2), "the image centre"
    raise CalibrationError(
        "principal_point: the marks have no nadir row (distance_m = 0); add one, give the "
        "principal point, or fit it", code="invalid_marks"
    )


def _residuals(camera: FisheyeCamera, marks: RulerMarks) -> MarkResiduals:
    fitted = camera.floor_positions(marks.uv_px)
    _, phi = camera.pixels_to_angles(marks.uv_px)
    if not camera.is_level:  # the lens azimuth is not the floor azimuth: take the fitted point's
        phi = np.where(fitted.valid, np.arctan2(fitted.xy_m[:, 1], fitted.xy_m[:, 0]), phi)
    along_azimuth = marks.distance_m[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    floor_xy = np.where(marks.has_xy[:, None], marks.xy_m, along_azimuth)
    predicted = camera.floor_to_pixels(floor_xy)
    return MarkResiduals(
        fitted_distance_m=fitted.distance_m,
        distance_error_m=fitted.distance_m - marks.distance_m,
        position_error_m=np.hypot(*(fitted.xy_m - marks.xy_m).T),
        pixel_error_px=np.hypot(*(predicted - marks.uv_px).T),
    )



def _fitted_camera(record: dict[str, object]) -> FisheyeCamera:
    try:
        return camera_from_dict(record)
    except CalibrationError as error:
        monotonic = "strictly increasing" in str(error)
        raise CalibrationError(
            f"the fitted lens cannot be used: {error}" + (
                "; the marks ask for an r(θ) that turns back: check far marks, use fewer coefficients "
                "or a smaller max_theta_deg" if monotonic else ""),
            code="not_monotonic" if monotonic else "invalid_camera") from None


def _tilt_notes(tilt_deg: tuple[float, float], sigma_deg: tuple[float, float]) -> list[FitNote]:
    worst = max(sigma_deg) if all(math.isfinite(s) for s in sigma_deg) else math.inf
    fitted = (f"tilt fitted: [{tilt_deg[0]:.3f}°, {tilt_deg[1]:.3f}°] "
              f"(± {sigma_deg[0]:.3f}°, ± {sigma_deg[1]:.3f}° for clicks good to {_CLICK_NOISE_PX:g} px)")
    if not worst <= _MAX_TILT_SIGMA_DEG:  # also NaN or inf: the tilt is not determined at all
        return [FitNote(
            "tilt_undetermined",
            f"{fitted}: the marks cannot pin the tilt down to {_MAX_TILT_SIGMA_DEG:g}°; add rulers in "
            "more directions and marks farther out", "warning")]
    return [FitNote("tilt", fitted)]


def _check_marks(marks: RulerMarks, problem: RadialProblem, config: RulerFitConfig,
                 principal_point: tuple[float, float], fit_centre: bool) -> None:
    """Refuse marks that cannot give the asked fit (CalibrationError with a code)."""
    nadir = marks.is_nadir
    centre_uv = marks.uv_px[nadir].mean(axis=0) if nadir.any() else principal_point
    centre = (float(centre_uv[0]), float(centre_uv[1]))
    check_ruler_order(marks, centre)
    if config.fit_tilt:
        check_tilt_marks(marks, centre, int(problem.undirected.sum()))
    if count_directions(marks, centre) < 2:
        raise CalibrationError(
            "marks: every mark lies on one radius from the nadir (one ruler); the lens is not known "
            "around the image from it: lay the ruler in two or more directions", code="one_direction")
    if fit_centre and direction_spread(marks, principal_point) < MIN_DIRECTION_SPREAD:
        raise CalibrationError(
            "principal_point: fitting the principal point or the aspect ratio needs rulers in at least "
            "two directions that are not on one line", code="one_direction"
        )


def _fit_notes(fit: RulerFit, config: RulerFitConfig, pp_source: str, fit_pp: bool,
               tilt_sigma_deg: tuple[float, float] | None) -> tuple[FitNote, ...]:
    """What the user should know about a fit: where the centre came from, how far the marks reach,
    what else the marks allow fitting, how well the tilt is known, and whether the constraint acted."""
    marks, camera = fit.marks, fit.camera
    notes = [FitNote("principal_point", f"principal point from {pp_source}" + (
        ", then fitted" + (" with the tilt" if config.fit_tilt and not config.fit_principal_point else "")
        if fit_pp else ""))]
    reach = (f"marks reach {marks.distance_m.max():.2f} m (θ = {fit.theta_max_marked_deg:.1f}°); floor "
             "positions farther out are extrapolated")
    if fit.theta_max_marked_deg < _SHORT_REACH_DEG:
        notes.append(FitNote("marks_short", f"{reach}: add marks farther out (θ ≥ {_SHORT_REACH_DEG:g}°) "
                                            "before trusting positions there", "warning"))
    else:
        notes.append(FitNote("marks_reach", reach))
    if not fit_pp and direction_spread(marks, camera.principal_point) >= MIN_DIRECTION_SPREAD:
        notes.append(FitNote(
            "principal_point_fittable",
            "the rulers point in several directions: fitting the principal point from all marks "
            "(--fit-principal-point) averages out the error of the single nadir click"))
    if tilt_sigma_deg is not None and camera.tilt_deg is not None:
        notes += _tilt_notes(camera.tilt_deg, tilt_sigma_deg)
    directed = marks.is_nadir | marks.has_xy | (np.asarray(marks.ruler, dtype=object) != "")
    if not config.fit_tilt and directed.all() and \
            count_directions(marks, camera.principal_point) >= MIN_TILT_DIRECTIONS:
        notes.append(FitNote(
            "tilt_fittable", "the camera is taken to be level; with rulers in three or more directions "
                             "the tilt can be fitted (--fit-tilt) and positions far out get better"))
    if fit.monotonic_constrained:
        notes.append(FitNote(
            "monotonic_constraint",
            f"r(θ) was held strictly increasing up to {config.theta_max_deg:g}° by the monotonicity "
            "constraint (the unconstrained fit turns back); consider fewer coefficients or more marks "
            "far out", "warning"))
    return tuple(notes)


def fit_ruler_calibration(
    marks: RulerMarks,
    altitude_m: float,
    image_size: tuple[int, int],
    camera_id: str = "camera",
    config: RulerFitConfig | None = None,
) -> RulerFit:
    """Fit a camera from ruler marks and the lens altitude; CalibrationError says what is wrong
    (its `code` says why in one word)."""
    config = config or RulerFitConfig()
    if not (isinstance(altitude_m, int | float) and math.isfinite(altitude_m) and altitude_m > 0):
        raise _options_error(f"altitude_m must be a finite number of metres > 0, got {altitude_m}")
    n = config.coefficients
    theta_max_rad = math.radians(config.theta_max_deg)
    check_marks_in_image(marks, image_size)
    check_nadir_marks(marks)
    fit_tilt = config.fit_tilt
    fit_pp = config.fit_principal_point or (fit_tilt and config.principal_point is None)
    fit_centre = fit_pp or config.fit_aspect_ratio
    problem = RadialProblem(marks, float(altitude_m), n, theta_max_rad, fit_centre or fit_tilt, fit_tilt)
    if len(problem.rulers) > MAX_FITTED_RULERS:
        raise CalibrationError(
            f"ruler: the marks name {len(problem.rulers)} rulers, and each one's direction is fitted; "
            f"at most {MAX_FITTED_RULERS} can be (give marks of one tape the same label)",
            code="invalid_marks")
    theta_marked = float(problem.theta.max(initial=0.0))
    if theta_marked >= theta_max_rad:
        raise CalibrationError(
            f"max_theta_deg: the marks reach θ = {math.degrees(theta_marked):.1f}°, beyond "
            f"max_theta_deg = {config.theta_max_deg:g}°", code="invalid_options"
        )
    distinct = len(np.unique(np.round(problem.theta[problem.theta > 0], 12)))
    if distinct < n:
        raise CalibrationError(
            f"coefficients: {n} coefficients need marks at {n} or more different non-zero distances; "
            f"the marks have {distinct}", code="too_few_marks"
        )
    principal_point, pp_source = _initial_principal_point(marks, config, image_size, fit_pp)
    width, height = image_size
    if not (0 <= principal_point[0] <= width - 1 and 0 <= principal_point[1] <= height - 1):
        raise _options_error(
            f"principal_point {list(principal_point)} ({pp_source}) lies outside the image {width}x{height}"
        )
    _check_marks(marks, problem, config, principal_point, fit_centre)

    # q = (u0, v0, log fy/fx, tilt a, tilt b, ruler directions): the nonlinear part (ruler_problem).
    directions = problem.initial_directions(principal_point[0], principal_point[1], config.aspect_ratio)
    q = np.concatenate([[principal_point[0], principal_point[1], math.log(config.aspect_ratio), 0.0, 0.0],
                        directions])
    free = np.concatenate([[fit_pp, fit_pp, config.fit_aspect_ratio, fit_tilt, fit_tilt],
                           np.ones(len(directions), dtype=bool)])
    try:
        slope_min = _MONOTONIC_SLOPE_FRACTION * problem.mean_slope(q)
        if free.any():
            q = levenberg_marquardt(problem, q, free, slope_min)
        c, residual = problem.solve(q, slope_min)
        A, b = problem.rows(q)
        unconstrained = np.linalg.lstsq(A, b, rcond=None)[0]
    except (ValueError, np.linalg.LinAlgError) as error:  # rank-deficient rows, infeasible constraints
        raise CalibrationError(f"the marks do not determine a lens ({error}); check the marks, the "
                               "altitude and the options", code="fit_failed") from None
    constrained = bool((problem.slope_rows @ unconstrained < slope_min).any())
    fx = float(c[0]) if config.focal_px is None else config.focal_px
    aspect = math.exp(q[2])
    camera = _fitted_camera({
        "id": camera_id,
        "altitude_m": float(altitude_m),
        "image_size": [int(width), int(height)],
        "principal_point": [float(q[0]), float(q[1])],
        "focal_px": [fx, fx * aspect],
        "kb": (c / fx).tolist(),
        **({} if config.max_theta_deg is None else {"max_theta_deg": config.max_theta_deg}),
        **({"tilt_deg": [float(q[3]), float(q[4])]} if fit_tilt else {}),
    })
    tilt_sigma_deg = None
    if fit_tilt:
        free_index = np.cumsum(free) - 1
        dof = max(len(residual) - int(free.sum()) - n, 1)
        noise_px = max(float(np.sqrt(residual @ residual / dof)), _CLICK_NOISE_PX)
        sigma = standard_errors(problem, q, free, slope_min, noise_px)
        tilt_sigma_deg = (float(sigma[free_index[3]]), float(sigma[free_index[4]]))
    fit = RulerFit(camera, marks, _residuals(camera, marks), math.degrees(theta_marked), constrained)
    return replace(fit, notes=_fit_notes(fit, config, pp_source, fit_pp, tilt_sigma_deg))
