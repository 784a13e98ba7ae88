"""Circles from points: the least-squares circle of an arc, and RANSAC for points with outliers.

`fit_circle_lsq` is the algebraic (Kåsa) fit refined by Gauss–Newton on the geometric distances;
`ransac_circle` samples three-point circles, keeps the one most points lie near and refines it by
least squares with 3σ rejection. Points are (N, 2) px; circles are (u0, v0, R).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def fit_circle_lsq(points_px: FloatArray) -> tuple[float, float, float]:
    """(N, 2) points, N ≥ 3 -> (u0, v0, R) of the circle nearest them: the algebraic (Kåsa) fit,
    then Gauss–Newton on the geometric distances. ValueError for collinear points."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 3:
        raise ValueError(f"a circle needs 3 points, got {len(pts)}")
    mean = pts.mean(axis=0)
    x, y = (pts - mean).T
    A = np.stack([x, y, np.ones_like(x)], axis=1)
    solution, _, rank, _ = np.linalg.lstsq(A, x * x + y * y, rcond=None)
    if rank < 3:
        raise ValueError("the points are collinear")
    cu, cv = solution[0] / 2, solution[1] / 2
    radius_sq = solution[2] + cu * cu + cv * cv
    if not radius_sq > 0:
        raise ValueError("the points fit no circle")
    centre, radius = np.array([cu, cv]), math.sqrt(radius_sq)
    for _ in range(10):
        offset = np.stack([x, y], axis=1) - centre
        distance = np.maximum(np.hypot(offset[:, 0], offset[:, 1]), 1e-12)
        residual = distance - radius
        J = np.concatenate([-offset / distance[:, None], -np.ones((len(x), 1))], axis=1)
        step = np.linalg.lstsq(J, -residual, rcond=None)[0]
        centre, radius = centre + step[:2], radius + float(step[2])
        if np.abs(step).max() < 1e-6:
            break
    if not (np.isfinite(centre).all() and math.isfinite(radius) and radius > 0):
        raise ValueError("the points fit no circle")
    return float(centre[0] + mean[0]), float(centre[1] + mean[1]), abs(radius)


def circle_residuals_px(points_px: FloatArray, circle: tuple[float, float, float]) -> FloatArray:
    """(N, 2) points -> (N,) signed distances from the circle (u0, v0, R); positive outside."""
    u0, v0, radius = circle
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    return np.asarray(np.hypot(pts[:, 0] - u0, pts[:, 1] - v0) - radius)


def _circle_through(p: FloatArray) -> tuple[float, float, float] | None:
    """The circle through three points (3, 2), or None when they are (nearly) collinear."""
    (ax, ay), (bx, by), (cx, cy) = p
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    if abs(d) < 1e-9:
        return None
    a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
    u = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d
    v = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d
    return u, v, math.hypot(ax - u, ay - v)


def ransac_circle(points_px: FloatArray, tolerance_px: float, iterations: int = 400,
                  seed: int = 0) -> tuple[tuple[float, float, float], NDArray[np.bool_]]:
    """(N, 2) points with outliers -> the circle (u0, v0, R) with the most points within
    `tolerance_px`, refined by least squares on them with 3σ rejection, and its inliers (N,).
    Seeded, so the same points give the same circle. ValueError when no circle is found."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    if len(pts) < 3:
        raise ValueError(f"a circle needs 3 points, got {len(pts)}")
    rng = np.random.default_rng(seed)
    best: NDArray[np.bool_] | None = None
    for _ in range(iterations):
        candidate = _circle_through(pts[rng.choice(len(pts), 3, replace=False)])
        if candidate is None:
            continue
        inliers = np.abs(circle_residuals_px(pts, candidate)) <= tolerance_px
        if best is None or inliers.sum() > best.sum():
            best = inliers
    if best is None or best.sum() < 3:
        raise ValueError("no three points fit a circle")
    inliers = best
    circle = fit_circle_lsq(pts[inliers])
    for _ in range(5):
        residual = circle_residuals_px(pts, circle)
        sigma = 1.4826 * float(np.median(np.abs(residual[inliers])))
        kept = np.abs(residual) <= max(3.0 * sigma, 0.5 * tolerance_px)
        if kept.sum() < 3 or np.array_equal(kept, inliers):
            break
        inliers = kept
        circle = fit_circle_lsq(pts[inliers])
    return circle, inliers
