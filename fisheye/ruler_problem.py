"""The least-squares problem of a ruler calibration (used by fisheye.calibration).

A mark at floor distance d and azimuth α is the floor point (d·cos α, d·sin α, 0) seen from the lens
at height Z. Rotated into the lens (the camera's tilt undone, fisheye.tilt) its ray makes an angle θ
with the optical axis at lens azimuth φ, and lands ρ = Σ c_j·θ^(2j−1) px from the principal point
along φ. For fixed nonlinear parameters q = (u0, v0, log fy/fx, tilt a, tilt b (deg), α_1..α_R),
ρ is linear in c: the rows of `RadialProblem.rows`. The nonlinear q is refined by Levenberg–Marquardt
around that linear solve (variable projection).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from fisheye.least_squares import constrained_lstsq
from fisheye.ruler_marks import RulerMarks
from fisheye.tilt import floor_to_lens_rays

FloatArray = NDArray[np.float64]

FIXED_PARAMETERS = 5  # u0, v0, log(fy/fx), tilt a, tilt b; the ruler directions follow
_MONOTONIC_GRID = 513
_LM_ITERATIONS = 100
# Numeric-Jacobian steps: u0 px, v0 px, log(fy/fx), tilt a deg, tilt b deg; ruler directions rad.
_LM_STEPS = np.array([1e-3, 1e-3, 1e-6, 1e-5, 1e-5])
_DIRECTION_STEP_RAD = 1e-7


def theta_powers(theta_rad: FloatArray, n: int) -> FloatArray:
    """(M,) θ -> (M, n) columns θ^(2j−1), j = 1..n (ρ = powers @ c)."""
    return np.stack([theta_rad ** (2 * j + 1) for j in range(n)], axis=1)


def slope_powers(theta_rad: FloatArray, n: int) -> FloatArray:
    """(M,) θ -> (M, n) columns (2j−1)·θ^(2j−2) (dρ/dθ = slope_powers @ c)."""
    return np.stack([(2 * j + 1) * theta_rad ** (2 * j) for j in range(n)], axis=1)


class RadialProblem:
    """The marks as linear least-squares rows in c, for q = (u0, v0, log fy/fx, a, b, α_1..α_R).

    A mark whose azimuth is known (its x, y given, or the direction α_r of its ruler, fitted with the
    principal point or the tilt) gives two rows (u and v offsets, px); any other mark one row (its
    radius, px); a nadir mark of a level camera two rows with A = 0 (its offset from the principal
    point). With `fit_tilt`, every mark's azimuth must be known.
    """

    def __init__(self, marks: RulerMarks, altitude_m: float, n: int, theta_max_rad: float,
                 fit_ruler_directions: bool, fit_tilt: bool = False) -> None:
        self.marks = marks
        self.altitude_m = altitude_m
        self.n = n
        self.fit_tilt = fit_tilt
        self.theta = np.arctan2(marks.distance_m, altitude_m)
        self.powers = theta_powers(self.theta, n)
        grid = np.linspace(0.0, theta_max_rad, _MONOTONIC_GRID)
        self.slope_rows = slope_powers(grid, n)
        nadir, has_xy = marks.is_nadir, marks.has_xy
        self.fixed_azimuth = np.where(
            nadir, 0.0, np.where(has_xy, np.arctan2(marks.xy_m[:, 1], marks.xy_m[:, 0]), np.nan))
        labels = np.asarray(marks.ruler, dtype=object)
        directed = fit_ruler_directions & ~nadir & ~has_xy & (labels != "")
        self.rulers = sorted({str(label) for label in labels[directed]})
        index = [self.rulers.index(str(label)) if use else -1
                 for label, use in zip(labels, directed, strict=True)]
        self.ruler_index = np.array(index, dtype=np.int64)

    @property
    def undirected(self) -> NDArray[np.bool_]:
        """(N,) the marks whose floor azimuth is neither known nor fitted (radius-only rows)."""
        return np.asarray(np.isnan(self.fixed_azimuth) & (self.ruler_index < 0))

    def initial_directions(self, u0: float, v0: float, aspect: float) -> FloatArray:
        """(R,) rad: each ruler's mean floor azimuth as seen from (u0, v0)."""
        du = self.marks.uv_px[:, 0] - u0
        dv = -(self.marks.uv_px[:, 1] - v0) / aspect
        return np.array([math.atan2(dv[self.ruler_index == r].sum(), du[self.ruler_index == r].sum())
                         for r in range(len(self.rulers))])

    def _lens_angles(self, tilt_deg: tuple[float, float], azimuth: FloatArray,
                     distance_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Floor azimuths and distances (K,) -> θ (K,) from the optical axis and lens azimuth φ (K,)."""
        floor = np.stack([distance_m * np.cos(azimuth), distance_m * np.sin(azimuth),
                          np.full(len(azimuth), -self.altitude_m)], axis=1)
        lens = floor_to_lens_rays(floor, tilt_deg)
        return np.arctan2(np.hypot(lens[:, 0], lens[:, 1]), -lens[:, 2]), np.arctan2(lens[:, 1], lens[:, 0])

    def rows(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """A (R, n), b (R,) px for q."""
        u0, v0, aspect = q[0], q[1], math.exp(q[2])
        azimuth = self.fixed_azimuth.copy()
        directed = self.ruler_index >= 0
        azimuth[directed] = q[FIXED_PARAMETERS + self.ruler_index[directed]]
        du = self.marks.uv_px[:, 0] - u0
        dv = self.marks.uv_px[:, 1] - v0
        radial = np.isnan(azimuth)
        known = ~radial
        powers, phi = self.powers[known], azimuth[known]
        if self.fit_tilt:
            theta, phi = self._lens_angles((float(q[3]), float(q[4])), phi, self.marks.distance_m[known])
            powers = theta_powers(theta, self.n)
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

    def jacobian(self, q: FloatArray, free: NDArray[np.bool_], slope_min: float) -> FloatArray:
        """(R, F) central-difference derivatives of the residual vector by the free entries of q."""
        steps = np.concatenate([_LM_STEPS, np.full(len(q) - FIXED_PARAMETERS, _DIRECTION_STEP_RAD)])
        columns = []
        for index in np.flatnonzero(free):
            step = np.zeros(len(q))
            step[index] = steps[index]
            plus = self.solve(q + step, slope_min)[1]
            minus = self.solve(q - step, slope_min)[1]
            columns.append((plus - minus) / (2 * steps[index]))
        return np.stack(columns, axis=1)


def levenberg_marquardt(problem: RadialProblem, q0: FloatArray, free: NDArray[np.bool_],
                        slope_min: float) -> FloatArray:
    """Refine the free entries of q to minimise the variable-projection residual."""
    q = q0.copy()
    residual = problem.solve(q, slope_min)[1]
    cost = float(residual @ residual)
    damping = 1e-3
    for _ in range(_LM_ITERATIONS):
        J = problem.jacobian(q, free, slope_min)
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


def standard_errors(problem: RadialProblem, q: FloatArray, free: NDArray[np.bool_], slope_min: float,
                    noise_px: float) -> FloatArray:
    """(F,) standard errors of the free entries of q for marks clicked with `noise_px` px of noise
    (from the Gauss–Newton covariance noise²·(JᵀJ)⁻¹; inf where JᵀJ is singular)."""
    J = problem.jacobian(q, free, slope_min)
    try:
        covariance = np.linalg.inv(J.T @ J) * noise_px ** 2
    except np.linalg.LinAlgError:
        return np.full(int(free.sum()), np.inf)
    return np.sqrt(np.maximum(np.diag(covariance), 0.0))
