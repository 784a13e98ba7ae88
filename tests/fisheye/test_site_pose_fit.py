"""Fitting a camera's site pose from floor points with known site positions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fisheye import SitePose, fit_site_pose


@pytest.mark.parametrize("pose", [
    SitePose(x_m=0.0, y_m=0.0, yaw_deg=0.0),
    SitePose(x_m=12.5, y_m=-3.0, yaw_deg=37.0),
    SitePose(x_m=-4.0, y_m=8.0, yaw_deg=-170.0),
])
def test_the_pose_is_recovered_from_exact_points(pose: SitePose) -> None:
    floor = np.array([[1.0, 0.0], [-2.0, 3.0], [4.0, -1.5]])
    fit = fit_site_pose(floor, pose.floor_to_site(floor))
    assert fit.pose.x_m == pytest.approx(pose.x_m, abs=1e-9)
    assert fit.pose.y_m == pytest.approx(pose.y_m, abs=1e-9)
    assert fit.pose.yaw_deg == pytest.approx(pose.yaw_deg, abs=1e-9)
    assert fit.rms_m == pytest.approx(0.0, abs=1e-9)


def test_two_points_are_enough() -> None:
    pose = SitePose(x_m=2.0, y_m=1.0, yaw_deg=90.0)
    floor = np.array([[0.0, 0.0], [5.0, 0.0]])
    fit = fit_site_pose(floor, pose.floor_to_site(floor))
    np.testing.assert_allclose(fit.pose.floor_to_site([[1.0, 1.0]]), pose.floor_to_site([[1.0, 1.0]]))


def test_a_one_degree_yaw_error_is_fourteen_centimetres_at_eight_metres() -> None:
    # Site positions measured with a 1° turn: the best rigid fit leaves the points near the nadir
    # and the far one apart by about 8 m · π/180 = 14 cm between them.
    floor = np.array([[0.0, 0.0], [8.0, 0.0]])
    turned = SitePose(yaw_deg=1.0).floor_to_site(floor)
    site = np.array([floor[0], turned[1]])
    exact = fit_site_pose(floor, site)
    assert exact.pose.yaw_deg == pytest.approx(1.0, abs=1e-9)
    wrong = SitePose(yaw_deg=0.0).floor_to_site(floor)
    assert float(np.hypot(*(wrong[1] - site[1]))) == pytest.approx(8 * math.radians(1.0), abs=1e-3)


def test_residuals_show_a_misplaced_point() -> None:
    floor = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0], [4.0, 4.0]])
    site = floor + np.array([10.0, 0.0])
    site[3] += [0.4, 0.0]
    fit = fit_site_pose(floor, site)
    assert int(np.argmax(fit.residuals_m)) == 3
    assert fit.max_m > 0.2 and fit.rms_m < fit.max_m


@pytest.mark.parametrize(("floor", "site", "message"), [
    ([[0.0, 0.0]], [[1.0, 1.0]], "at least 2"),
    ([[0.0, 0.0], [1.0, 1.0]], [[1.0, 1.0]], "floor points but"),
    ([[1.0, 1.0], [1.0, 1.0]], [[0.0, 0.0], [1.0, 1.0]], "one place"),
    ([[0.0, 0.0], [1.0, np.nan]], [[0.0, 0.0], [1.0, 1.0]], "finite"),
])
def test_unusable_points_are_refused(floor: list[list[float]], site: list[list[float]], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        fit_site_pose(floor, site)
