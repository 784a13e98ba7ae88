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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fisheye.camera import DEFAULT_MAX_THETA_DEG, FisheyeCamera
from fisheye.camera_file import CalibrationError, camera_from_dict
from fisheye.least_squares import constrained_lstsq
from fisheye.ruler_marks import RulerMarks

FloatArray = NDArray[np.float64]

MAX_COEFFICIENTS = 5
_MONOTONIC_GRID = 513
_MONOTONIC_SLOPE_FRACTION = 1e-3  # ε as a fraction of the marks' mean slope ρ/θ
_MIN_DIRECTION_SPREAD = 0.05  # smallest eigenvalue of the marks' direction scatter for a fitted centre
_LM_ITERATIONS = 100
_LM_STEPS = np.array([1e-3, 1e-3, 1e-6])  # numeric-Jacobian steps: u0 px, v0 px, log(fy/fx)


@dataclass(frozen=True)
class RulerFitConfig:
    """What to fit. `coefficients`: number of kb terms (1..5). `focal_px`: keep this fx (k1 fitted);
    None fits fx with k1 = 1. `aspect_ratio`: fy/fx (kept unless `fit_aspect_ratio`).
    `principal_point`: [u0, v0] px; None takes the nadir mark. `fit_principal_point`: refine it from
    all marks. `max_theta_deg`: the camera's θmax (r(θ) is kept increasing up to it; None: 90°)."""

    coefficients: int = 3
    focal_px: float | None = None
    aspect_ratio: float = 1.0
    fit_aspect_ratio: bool = False
    principal_point: tuple[float, float] | None = None
    fit_principal_point: bool = False
    max_theta_deg: float | None = None

    def __post_init__(self) -> None:
        if not 1 <= self.coefficients <= MAX_COEFFICIENTS:
            raise CalibrationError(f"coefficients must be 1 to {MAX_COEFFICIENTS}, got {self.coefficients}")
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise CalibrationError(f"focal_px must be a finite number > 0, got {self.focal_px}")
        if not (math.isfinite(self.aspect_ratio) and self.aspect_ratio > 0):
            raise CalibrationError(f"aspect_ratio must be a finite number > 0, got {self.aspect_ratio}")
        if self.principal_point is not None and not all(math.isfinite(p) for p in self.principal_point):
            raise CalibrationError(f"principal_point must be finite, got {self.principal_point}")
        if self.max_theta_deg is not None and not 0 < self.max_theta_deg < 180:
            raise CalibrationError(f"max_theta_deg must lie in (0, 180), got {self.max_theta_deg}")

    @property
    def theta_max_deg(self) -> float:
        return DEFAULT_MAX_THETA_DEG if self.max_theta_deg is None else self.max_theta_deg


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
    notes: tuple[str, ...] = field(default=())

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


def _theta_powers(theta_rad: FloatArray, n: int) -> FloatArray:
    """(M,) θ -> (M, n) columns θ^(2j−1), j = 1..n (ρ = powers @ c)."""
    return np.stack([theta_rad ** (2 * j + 1) for j in range(n)], axis=1)


def _slope_powers(theta_rad: FloatArray, n: int) -> FloatArray:
    """(M,) θ -> (M, n) columns (2j−1)·θ^(2j−2) (dρ/dθ = slope_powers @ c)."""
    return np.stack([(2 * j + 1) * theta_rad ** (2 * j) for j in range(n)], axis=1)


class _RadialProblem:
    """The marks as linear least-squares rows in c, for q = (u0, v0, log fy/fx, α_1..α_R).

    A mark whose azimuth is known (its x, y given, or the direction α_r of its ruler, fitted with the
    principal point) gives two rows (u and v offsets, px); any other mark one row (its radius,
    px); a nadir mark two rows with A = 0 (its offset from the principal point).
    """

    def __init__(self, marks: RulerMarks, altitude_m: float, n: int, theta_max_rad: float,
                 fit_ruler_directions: bool) -> None:
        self.marks = marks
        self.n = n
        self.theta = np.arctan2(marks.distance_m, altitude_m)
        self.powers = _theta_powers(self.theta, n)
        grid = np.linspace(0.0, theta_max_rad, _MONOTONIC_GRID)
        self.slope_rows = _slope_powers(grid, n)
        nadir, has_xy = marks.is_nadir, marks.has_xy
        self.fixed_azimuth = np.where(
            nadir, 0.0, np.where(has_xy, np.arctan2(marks.xy_m[:, 1], marks.xy_m[:, 0]), np.nan))
        labels = np.asarray(marks.ruler, dtype=object)
        directed = fit_ruler_directions & ~nadir & ~has_xy & (labels != "")
        self.rulers = sorted({str(label) for label in labels[directed]})
        index = [self.rulers.index(str(label)) if use else -1
                 for label, use in zip(labels, directed, strict=True)]
        self.ruler_index = np.array(index, dtype=np.int64)

    def initial_directions(self, u0: float, v0: float, aspect: float) -> FloatArray:
        """(R,) rad: each ruler's mean floor azimuth as seen from (u0, v0)."""
        du = self.marks.uv_px[:, 0] - u0
        dv = -(self.marks.uv_px[:, 1] - v0) / aspect
        return np.array([math.atan2(dv[self.ruler_index == r].sum(), du[self.ruler_index == r].sum())
                         for r in range(len(self.rulers))])

    def rows(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """A (R, n), b (R,) px for q."""
        u0, v0, aspect = q[0], q[1], math.exp(q[2])
        azimuth = self.fixed_azimuth.copy()
        directed = self.ruler_index >= 0
        azimuth[directed] = q[3 + self.ruler_index[directed]]
        du = self.marks.uv_px[:, 0] - u0
        dv = self.marks.uv_px[:, 1] - v0
        radial = np.isnan(azimuth)
        known = ~radial
        powers, phi = self.powers[known], azimuth[known]
        A = [self.powers[radial], np.cos(phi)[:, None] * powers, -aspect * np.sin(phi)[:, None] * powers]
        b = [np.hypot(du[radial], dv[radial] / aspect), du[known], dv[known]]
        return np.concatenate(A), np.concatenate(b)

    def solve(self, q: FloatArray, slope_min: float) -> tuple[FloatArray, FloatArray]:
        """c (n,) under dρ/dθ ≥ slope_min on the grid, and the residual vector A c − b px."""
        A, b = self.rows(q)
        c = constrained_lstsq(A, b, self.slope_rows, np.full(len(self.slope_rows), slope_min))
        return c, A @ c - b

    def mean_slope(self, q: FloatArray) -> float:
        """Median ρ/θ (px/rad) of the marks away from the nadir: the scale of dρ/dθ."""
        radius = np.hypot(self.marks.uv_px[:, 0] - q[0], (self.marks.uv_px[:, 1] - q[1]) / math.exp(q[2]))
        away = self.theta > 0
        return float(np.median(radius[away] / self.theta[away]))


def _levenberg_marquardt(problem: _RadialProblem, q0: FloatArray, free: NDArray[np.bool_],
                         slope_min: float) -> FloatArray:
    """Refine the free entries of q to minimise the variable-projection residual."""
    q = q0.copy()
    steps = np.concatenate([_LM_STEPS, np.full(len(q) - 3, 1e-7)])
    residual = problem.solve(q, slope_min)[1]
    cost = float(residual @ residual)
    damping = 1e-3
    for _ in range(_LM_ITERATIONS):
        columns = []
        for index in np.flatnonzero(free):
            step = np.zeros(len(q))
            step[index] = steps[index]
            plus = problem.solve(q + step, slope_min)[1]
            minus = problem.solve(q - step, slope_min)[1]
            columns.append((plus - minus) / (2 * steps[index]))
        J = np.stack(columns, axis=1)
        gradient, normal = J.T @ residual, J.T @ J
        improved = converged = False
        while damping < 1e12:
            lhs = normal + damping * np.diag(np.diag(normal) + 1e-12)
            delta = np.linalg.solve(lhs, -gradient)
            trial = q.copy()
            trial[free] += delta
            trial_residual = problem.solve(trial, slope_min)[1]
            trial_cost = float(trial_residual @ trial_residual)
            if trial_cost <= cost:
                converged = bool(cost - trial_cost <= 1e-15 * max(cost, 1.0) or np.all(
                    np.abs(delta) <= 1e-10 * (1 + np.abs(q[free]))))
                q, residual, cost, improved = trial, trial_residual, trial_cost, True
                damping = max(damping / 3, 1e-12)
                break
            damping *= 4
        if not improved or converged:
            break
    return q


def _initial_principal_point(marks: RulerMarks, config: RulerFitConfig,
                             image_size: tuple[int, int]) -> tuple[tuple[float, float], str]:
    if config.principal_point is not None:
        return config.principal_point, "given"
    nadir = marks.is_nadir
    if nadir.any():
        u0, v0 = marks.uv_px[nadir].mean(axis=0)
        return (float(u0), float(v0)), "the nadir mark" if nadir.sum() == 1 else "the mean of the nadir marks"
    if config.fit_principal_point:
        width, height = image_size
        return ((width - 1) / 2, (height - 1) / 2), "the image centre"
    raise CalibrationError(
        "principal_point: the marks have no nadir row (distance_m = 0); add one, give the "
        "principal point, or fit it"
    )


def _direction_spread(marks: RulerMarks, principal_point: tuple[float, float]) -> float:
    """Smallest eigenvalue of the scatter of the marks' unit directions from the centre: 0 when all
    marks lie on one line through it, 0.5 for rulers evenly spread."""
    away = ~marks.is_nadir
    offset = np.where(marks.has_xy[away, None], marks.xy_m[away] * [1.0, -1.0],
                      marks.uv_px[away] - np.asarray(principal_point))
    length = np.hypot(offset[:, 0], offset[:, 1])
    unit = offset[length > 0] / length[length > 0, None]
    return float(np.linalg.eigvalsh(unit.T @ unit / len(unit))[0]) if len(unit) else 0.0


def _residuals(camera: FisheyeCamera, marks: RulerMarks) -> MarkResiduals:
    fitted = camera.floor_positions(marks.uv_px)
    _, phi = camera.pixels_to_angles(marks.uv_px)
    along_azimuth = marks.distance_m[:, None] * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    floor_xy = np.where(marks.has_xy[:, None], marks.xy_m, along_azimuth)
    predicted = camera.floor_to_pixels(floor_xy)
    return MarkResiduals(
        fitted_distance_m=fitted.distance_m,
        distance_error_m=fitted.distance_m - marks.distance_m,
        position_error_m=np.hypot(*(fitted.xy_m - marks.xy_m).T),
        pixel_error_px=np.hypot(*(predicted - marks.uv_px).T),
    )


def fit_ruler_calibration(
    marks: RulerMarks,
    altitude_m: float,
    image_size: tuple[int, int],
    camera_id: str = "camera",
    config: RulerFitConfig | None = None,
) -> RulerFit:
    """Fit a camera from ruler marks and the lens altitude; CalibrationError says what is wrong."""
    config = config or RulerFitConfig()
    if not (isinstance(altitude_m, int | float) and math.isfinite(altitude_m) and altitude_m > 0):
        raise CalibrationError(f"altitude_m must be a finite number of metres > 0, got {altitude_m}")
    n = config.coefficients
    theta_max_rad = math.radians(config.theta_max_deg)
    fit_centre = config.fit_principal_point or config.fit_aspect_ratio
    problem = _RadialProblem(marks, float(altitude_m), n, theta_max_rad, fit_centre)
    theta_marked = float(problem.theta.max(initial=0.0))
    if theta_marked >= theta_max_rad:
        raise CalibrationError(
            f"max_theta_deg: the marks reach θ = {math.degrees(theta_marked):.1f}°, beyond "
            f"max_theta_deg = {config.theta_max_deg:g}°"
        )
    distinct = len(np.unique(np.round(problem.theta[problem.theta > 0], 12)))
    if distinct < n:
        raise CalibrationError(
            f"coefficients: {n} coefficients need marks at {n} or more different non-zero distances; "
            f"the marks have {distinct}"
        )
    principal_point, pp_source = _initial_principal_point(marks, config, image_size)
    width, height = image_size
    if not (0 <= principal_point[0] <= width - 1 and 0 <= principal_point[1] <= height - 1):
        raise CalibrationError(
            f"principal_point {list(principal_point)} ({pp_source}) lies outside the image {width}x{height}"
        )
    spread = _direction_spread(marks, principal_point)
    if fit_centre and spread < _MIN_DIRECTION_SPREAD:
        raise CalibrationError(
            "principal_point: fitting the principal point or the aspect ratio needs rulers in at least "
            "two directions that are not on one line"
        )
    directions = problem.initial_directions(principal_point[0], principal_point[1], config.aspect_ratio)
    q = np.concatenate([[principal_point[0], principal_point[1], math.log(config.aspect_ratio)], directions])
    slope_min = _MONOTONIC_SLOPE_FRACTION * problem.mean_slope(q)
    free = np.concatenate([[config.fit_principal_point, config.fit_principal_point, config.fit_aspect_ratio],
                           np.ones(len(directions), dtype=bool)])
    if free.any():
        q = _levenberg_marquardt(problem, q, free, slope_min)
    c, _ = problem.solve(q, slope_min)
    A, b = problem.rows(q)
    unconstrained = np.linalg.lstsq(A, b, rcond=None)[0]
    constrained = bool((problem.slope_rows @ unconstrained < slope_min).any())
    fx = float(c[0]) if config.focal_px is None else config.focal_px
    aspect = math.exp(q[2])
    camera = camera_from_dict({
        "id": camera_id,
        "altitude_m": float(altitude_m),
        "image_size": [int(width), int(height)],
        "principal_point": [float(q[0]), float(q[1])],
        "focal_px": [fx, fx * aspect],
        "kb": (c / fx).tolist(),
        **({} if config.max_theta_deg is None else {"max_theta_deg": config.max_theta_deg}),
    })
    notes = [f"principal point from {pp_source}" + (", then fitted" if config.fit_principal_point else "")]
    notes.append(
        f"marks reach {marks.distance_m.max():.2f} m (θ = {math.degrees(theta_marked):.1f}°); floor "
        "positions farther out are extrapolated"
    )
    if not config.fit_principal_point and spread >= _MIN_DIRECTION_SPREAD:
        notes.append(
            "the rulers point in several directions: fitting the principal point from all marks "
            "(--fit-principal-point) averages out the error of the single nadir click"
        )
    if constrained:
        notes.append(
            f"r(θ) was held strictly increasing up to {config.theta_max_deg:g}° by the monotonicity "
            "constraint (the unconstrained fit turns back); consider fewer coefficients or more marks "
            "far out"
        )
    return RulerFit(camera, marks, _residuals(camera, marks), math.degrees(theta_marked), constrained,
                    tuple(notes))

