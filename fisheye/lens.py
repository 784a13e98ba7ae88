"""Kannala–Brandt radial lens model: r(θ) = k1·θ + k2·θ³ + k3·θ⁵ + k4·θ⁷ + k5·θ⁹.

Pure functions on arrays. θ is the angle between a ray and the optical axis (rad); r is the
normalised image radius (multiply by the focal length in pixels to get pixels).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

THETA_TOLERANCE_RAD = 1e-12
_NEWTON_ITERATIONS = 30
_BISECTION_ITERATIONS = 80
_MONOTONIC_SAMPLES = 2049
# A radius this close above r(θmax) (rounding in a pixel round trip) still maps to θmax.
_RADIUS_MAX_RELATIVE_SLACK = 1e-12


def theta_to_radius(theta_rad: ArrayLike, kb: ArrayLike) -> FloatArray:
    """r(θ) for any shape of θ (rad) -> same shape, normalised radius."""
    theta = np.asarray(theta_rad, dtype=np.float64)
    coeffs = np.asarray(kb, dtype=np.float64)
    theta_sq = theta * theta
    radius = np.zeros_like(theta)
    # Horner in θ²: r = θ·(k1 + θ²·(k2 + θ²·(...)))
    for k in coeffs[::-1]:
        radius = radius * theta_sq + k
    return radius * theta


def radius_derivative(theta_rad: ArrayLike, kb: ArrayLike) -> FloatArray:
    """dr/dθ for any shape of θ (rad) -> same shape."""
    theta = np.asarray(theta_rad, dtype=np.float64)
    coeffs = np.asarray(kb, dtype=np.float64)
    theta_sq = theta * theta
    derivative = np.zeros_like(theta)
    for i in range(len(coeffs) - 1, -1, -1):
        derivative = derivative * theta_sq + (2 * i + 1) * coeffs[i]
    return derivative


def monotonic_violation(kb: ArrayLike, theta_max_rad: float) -> float | None:
    """The first θ (rad) in [0, θmax] where r(θ) stops strictly increasing, or None if it never does.

    Checks the sign of dr/dθ on a dense grid and at the stationary points of r (real roots of dr/dθ),
    so a short dip between grid points is not missed.
    """
    coeffs = np.asarray(kb, dtype=np.float64)
    if coeffs.size == 0 or coeffs[0] <= 0:
        return 0.0
    candidates = [np.linspace(0.0, theta_max_rad, _MONOTONIC_SAMPLES)]
    # dr/dθ is a polynomial in θ: (2i+1)·k_i·θ^(2i); its real roots are the stationary points.
    derivative_poly = np.zeros(2 * len(coeffs) - 1)
    for i, k in enumerate(coeffs):
        derivative_poly[2 * i] = (2 * i + 1) * k
    if len(derivative_poly) > 1:
        # A negligible leading coefficient (e.g. 1e-300) overflows the companion matrix; the
        # roots it loses lie far outside [0, θmax] and the dense grid still guards the rest.
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            roots = np.roots(derivative_poly[::-1])
        roots = roots[np.isfinite(roots)]
        real = roots[np.abs(roots.imag) < 1e-9].real
        candidates.append(real[(real > 0) & (real <= theta_max_rad)])
    thetas = np.sort(np.concatenate(candidates))
    bad = thetas[radius_derivative(thetas, coeffs) <= 0]
    return float(bad[0]) if bad.size else None


def radius_to_theta(radius: ArrayLike, kb: ArrayLike, theta_max_rad: float) -> FloatArray:
    """θ (rad) with r(θ) = radius, for any shape; NaN where radius is outside [0, r(θmax)] or NaN.

    Newton's method from θ = r/k1, kept inside a bracket [lo, hi] that shrinks every step; any
    element that has not converged after the Newton steps is finished by bisection on its bracket.
    Assumes r(θ) strictly increasing on [0, θmax] (FisheyeCamera refuses lenses where it is not).
    """
    coeffs = np.asarray(kb, dtype=np.float64)
    target = np.asarray(radius, dtype=np.float64)
    shape = target.shape
    target = target.reshape(-1)
    radius_max = float(theta_to_radius(theta_max_rad, coeffs))
    theta = np.full(target.shape, np.nan)
    ok = np.isfinite(target) & (target >= 0) & (target <= radius_max * (1 + _RADIUS_MAX_RELATIVE_SLACK))
    if not ok.any():
        return theta.reshape(shape)
    goal = np.minimum(target[ok], radius_max)
    lo = np.zeros_like(goal)
    hi = np.full_like(goal, theta_max_rad)
    estimate = np.clip(goal / coeffs[0], 0.0, theta_max_rad)
    converged = np.zeros(goal.shape, dtype=bool)
    for _ in range(_NEWTON_ITERATIONS):
        residual = theta_to_radius(estimate, coeffs) - goal
        lo = np.where(residual < 0, estimate, lo)
        hi = np.where(residual > 0, estimate, hi)
        slope = radius_derivative(estimate, coeffs)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(residual == 0, 0.0, residual / slope)
        candidate = estimate - step
        # The root lies in the closed bracket [lo, hi]; a Newton step that leaves it is replaced by
        # the bracket's midpoint.
        outside = ~np.isfinite(candidate) | (candidate < lo) | (candidate > hi)
        candidate = np.where(outside, 0.5 * (lo + hi), candidate)
        converged = (residual == 0) | (np.abs(candidate - estimate) < THETA_TOLERANCE_RAD)
        estimate = candidate
        if converged.all():
            break
    if not converged.all():
        left, right = lo[~converged], hi[~converged]
        goal_left = goal[~converged]
        for _ in range(_BISECTION_ITERATIONS):
            middle = 0.5 * (left + right)
            below = theta_to_radius(middle, coeffs) < goal_left
            left = np.where(below, middle, left)
            right = np.where(below, right, middle)
        estimate[~converged] = 0.5 * (left + right)
    theta[ok] = estimate
    return theta.reshape(shape)
