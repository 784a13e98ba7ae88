import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fisheye import lens
from fisheye.lens import monotonic_violation, radius_derivative, radius_to_theta, theta_to_radius

HALF_PI = math.pi / 2
# Lenses with r(θ) strictly increasing on [0, 90°]: equidistant, the demo camera's, OpenCV-like.
LENSES = [
    [1.0],
    [1.0, -0.032, 0.0021],
    [0.98, -0.05, 0.004, -0.0001],
    [1.0, 0.01, -0.004, 0.0005, -0.00002],
]


def _flat_lens(slope_min: float) -> list[float]:
    """r(θ) = θ − aθ³ + bθ⁵ whose slope dips to `slope_min` at θ ≈ 66° (Newton's nemesis)."""
    a = 0.5
    b = 9 * a * a / (20 * (1 - slope_min))
    return [1.0, -a, b]


def _flattest_theta(kb: list[float]) -> float:
    return math.sqrt(3 * -kb[1] / (10 * kb[2]))


@pytest.mark.parametrize(
    ("theta", "kb", "expected"),
    [
        (np.zeros(0), [1.0], np.zeros(0)),
        (np.array([0.0, 0.5, 1.0]), [1.0], np.array([0.0, 0.5, 1.0])),
        (np.array([0.5]), [1.0, -0.1], np.array([0.5 - 0.1 * 0.125])),
        (np.array([1.0]), [2.0, 0.1, 0.01, 0.001, 0.0001], np.array([2.1111])),
        (np.array([[0.0, 2.0]]), [1.0, 0.0, 1.0], np.array([[0.0, 34.0]])),
    ],
)
def test_theta_to_radius_table(theta: np.ndarray, kb: list[float], expected: np.ndarray) -> None:
    np.testing.assert_allclose(theta_to_radius(theta, kb), expected, rtol=1e-12)


@pytest.mark.parametrize("kb", LENSES)
def test_radius_derivative_matches_finite_differences(kb: list[float]) -> None:
    theta = np.linspace(0.01, 1.5, 50)
    step = 1e-6
    numeric = (theta_to_radius(theta + step, kb) - theta_to_radius(theta - step, kb)) / (2 * step)
    np.testing.assert_allclose(radius_derivative(theta, kb), numeric, rtol=1e-7)


@pytest.mark.parametrize(
    ("radius", "expected_shape"),
    [(np.zeros(0), (0,)), (np.zeros((2, 3)), (2, 3)), (np.float64(0.3), ())],
)
def test_radius_to_theta_keeps_shape(radius: np.ndarray, expected_shape: tuple[int, ...]) -> None:
    assert radius_to_theta(radius, [1.0], HALF_PI).shape == expected_shape


@pytest.mark.parametrize("kb", LENSES)
def test_radius_to_theta_inverts_theta_to_radius(kb: list[float]) -> None:
    theta = np.concatenate([[0.0, 1e-12, HALF_PI], np.linspace(0, HALF_PI, 1001)])
    recovered = radius_to_theta(theta_to_radius(theta, kb), kb, HALF_PI)
    assert np.max(np.abs(recovered - theta)) < 1e-9
    assert recovered[0] == 0.0


@settings(max_examples=200, deadline=None)
@given(
    theta=st.floats(0.0, HALF_PI, allow_nan=False),
    kb=st.sampled_from([*LENSES, _flat_lens(1e-4), _flat_lens(1e-7)]),
)
def test_radius_to_theta_round_trip_property(theta: float, kb: list[float]) -> None:
    recovered = float(radius_to_theta(theta_to_radius(theta, kb), kb, HALF_PI))
    assert abs(recovered - theta) < 1e-9


def _plain_newton(goal: float, kb: list[float], iterations: int = 30) -> float:
    theta = goal / kb[0]
    for _ in range(iterations):
        theta -= float((theta_to_radius(theta, kb) - goal) / radius_derivative(theta, kb))
    return theta


def test_bracketing_fallback_where_newton_misbehaves() -> None:
    kb = _flat_lens(1e-6)
    assert monotonic_violation(kb, HALF_PI) is None
    theta = np.concatenate([np.linspace(0.0, HALF_PI, 200), _flattest_theta(kb) + np.array([-1e-4, 0, 1e-5])])
    goal = theta_to_radius(theta, kb)
    # Unguarded Newton from θ = r/k1 lands on the flat stretch for some radii, is thrown far out
    # and has not come back after 30 steps.
    with np.errstate(all="ignore"):
        plain = np.array([_plain_newton(float(g), kb) for g in goal])
    assert np.sum(~(np.abs(plain - theta) < 1e-6)) >= 2
    recovered = radius_to_theta(goal, kb, HALF_PI)
    assert np.max(np.abs(recovered - theta)) < 1e-9


def test_bisection_alone_is_accurate(monkeypatch: pytest.MonkeyPatch) -> None:
    # With a single Newton step nearly every element is left to bisection on its bracket.
    monkeypatch.setattr(lens, "_NEWTON_ITERATIONS", 1)
    theta = np.linspace(0.0, HALF_PI, 101)
    for kb in [*LENSES, _flat_lens(1e-6)]:
        recovered = radius_to_theta(theta_to_radius(theta, kb), kb, HALF_PI)
        assert np.max(np.abs(recovered - theta)) < 1e-9


@pytest.mark.parametrize("radius", [np.nan, -1e-9, -1.0, np.inf, HALF_PI * (1 + 1e-9)])
def test_radius_to_theta_outside_the_field_is_nan(radius: float) -> None:
    theta = radius_to_theta(np.array([radius, 0.5]), [1.0], HALF_PI)
    assert np.isnan(theta[0])
    assert theta[1] == pytest.approx(0.5, abs=1e-12)


def test_rounding_error_just_past_the_edge_maps_to_the_edge() -> None:
    theta = radius_to_theta(np.array([HALF_PI * (1 + 1e-15)]), [1.0], HALF_PI)
    assert theta[0] == pytest.approx(HALF_PI, abs=1e-15)


@pytest.mark.parametrize(
    ("kb", "theta_max_deg", "expected_deg"),
    [
        ([1.0], 90.0, None),
        ([1.0, -0.5], 90.0, math.degrees(math.sqrt(1 / 1.5))),
        ([1.0, -0.5], 40.0, None),
        ([0.0, 1.0], 90.0, 0.0),
        ([-1.0], 90.0, 0.0),
        ([1.0, -0.032, 0.0021], 95.0, None),
        # The slope dips below zero only on a sliver far narrower than the check's grid spacing.
        (_flat_lens(-1e-9), 90.0, math.degrees(_flattest_theta(_flat_lens(-1e-9)))),
    ],
)
def test_monotonic_violation_table(kb: list[float], theta_max_deg: float, expected_deg: float | None) -> None:
    found = monotonic_violation(kb, math.radians(theta_max_deg))
    if expected_deg is None:
        assert found is None
    else:
        assert found is not None
        assert math.degrees(found) == pytest.approx(expected_deg, abs=0.05)
