"""Circles from points: arcs recovered exactly, outliers left out, degenerate inputs refused."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye.circle_fit import circle_residuals_px, fit_circle_lsq, ransac_circle


def _arc(center: tuple[float, float], radius: float, start_deg: float, span_deg: float, n: int) -> np.ndarray:
    angles = np.radians(start_deg + np.linspace(0.0, span_deg, n))
    return np.stack([center[0] + radius * np.cos(angles), center[1] + radius * np.sin(angles)], axis=1)


@pytest.mark.parametrize("points", [np.zeros((0, 2)), np.zeros((2, 2)), np.array([[0, 0], [1, 1], [2, 2.0]])])
def test_circle_fits_refuse_too_few_or_collinear_points(points: np.ndarray) -> None:
    with pytest.raises(ValueError):
        fit_circle_lsq(points)
    with pytest.raises(ValueError):
        ransac_circle(points, 1.0)


@settings(max_examples=40, deadline=None)
@given(u0=st.floats(-500, 500), v0=st.floats(-500, 500), radius=st.floats(5, 2000),
       start=st.floats(0, 360), span=st.floats(30, 360))
def test_least_squares_recovers_a_circle_from_an_arc(u0: float, v0: float, radius: float, start: float,
                                                      span: float) -> None:
    fitted = fit_circle_lsq(_arc((u0, v0), radius, start, span, 50))
    np.testing.assert_allclose(fitted, (u0, v0, radius), atol=1e-6 * max(radius, 1.0) + 1e-6)


def test_ransac_ignores_outliers_and_says_which() -> None:
    rim = _arc((300.0, 250.0), 200.0, 10.0, 300.0, 200)
    rng = np.random.default_rng(3)
    scattered = rng.uniform(0, 600, (80, 2))
    outliers = scattered[np.abs(circle_residuals_px(scattered, (300.0, 250.0, 200.0))) > 5.0]
    circle, inliers = ransac_circle(np.concatenate([rim, outliers]), 1.0)
    np.testing.assert_allclose(circle, (300.0, 250.0, 200.0), atol=1e-6)
    assert inliers[:200].all() and not inliers[200:].any()
