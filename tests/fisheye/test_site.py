import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from fisheye.site import SitePose


@pytest.mark.parametrize(
    ("pose", "floor_xy", "site_xy"),
    [
        (SitePose(), np.zeros((0, 2)), np.zeros((0, 2))),
        (SitePose(), np.array([[1.0, 2.0]]), np.array([[1.0, 2.0]])),
        (SitePose(x_m=10.0, y_m=-5.0), np.array([[1.0, 2.0]]), np.array([[11.0, -3.0]])),
        # Counter-clockwise yaw: the camera's x axis points along the site's y axis.
        (SitePose(yaw_deg=90.0), np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[0.0, 1.0], [-1.0, 0.0]])),
        (SitePose(x_m=2.0, y_m=3.0, yaw_deg=180.0), np.array([[1.0, 1.0]]), np.array([[1.0, 2.0]])),
        (SitePose(x_m=1.0, yaw_deg=-90.0), np.array([[np.nan, 1.0]]), np.array([[np.nan, np.nan]])),
    ],
)
def test_floor_to_site_table(pose: SitePose, floor_xy: np.ndarray, site_xy: np.ndarray) -> None:
    np.testing.assert_allclose(pose.floor_to_site(floor_xy), site_xy, atol=1e-12)
    if np.isfinite(site_xy).all():
        np.testing.assert_allclose(pose.site_to_floor(site_xy), floor_xy, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(
    x=st.floats(-100, 100), y=st.floats(-100, 100), yaw=st.floats(-360, 360),
    px=st.floats(-50, 50), py=st.floats(-50, 50),
)
def test_site_round_trip_and_distances(x: float, y: float, yaw: float, px: float, py: float) -> None:
    pose = SitePose(x_m=x, y_m=y, yaw_deg=yaw)
    points = np.array([[px, py], [0.0, 0.0]])
    site = pose.floor_to_site(points)
    np.testing.assert_allclose(site[1], [x, y], atol=1e-9)  # the nadir sits at (x_m, y_m)
    np.testing.assert_allclose(pose.site_to_floor(site), points, atol=1e-9)
    assert np.linalg.norm(site[0] - site[1]) == pytest.approx(np.hypot(px, py), abs=1e-9)


@pytest.mark.parametrize(
    ("fields", "name"),
    [({"yaw_deg": 361.0}, "yaw_deg"), ({"x_m": float("nan")}, "x_m"), ({"z_m": 1.0}, "z_m")],
)
def test_site_pose_refusals_name_the_field(fields: dict[str, float], name: str) -> None:
    with pytest.raises(ValidationError, match=name):
        SitePose(**fields)
