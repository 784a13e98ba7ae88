import math
from typing import Any

import numpy as np
import pytest

from fisheye import CalibrationError, FisheyeCamera, camera_from_dict
from fisheye.calibration import RulerFit, RulerFitConfig, fit_ruler_calibration
from fisheye.lens import monotonic_violation
from fisheye.ruler_marks import RulerMarks, simulate_ruler_marks

SIZE = (2952, 2952)
BASE: dict[str, Any] = {
    "id": "lobby-1", "altitude_m": 3.2, "image_size": list(SIZE), "principal_point": [1480.3, 1469.8],
    "focal_px": [940.0, 940.0], "kb": [1.0, -0.02, 0.001],
}
TRUE = camera_from_dict(BASE)
FOUR_RULERS = [0.0, 90.0, 180.0, 270.0]
EVERY_HALF_METRE = np.arange(0.5, 10.001, 0.5)


def _fit(marks: RulerMarks, camera_id: str = "fitted", **config: Any) -> RulerFit:
    return fit_ruler_calibration(marks, 3.2, SIZE, camera_id, RulerFitConfig(**config))


def _ring_errors_m(fitted: FisheyeCamera, truth: FisheyeCamera, distance_m: float) -> np.ndarray:
    """Floor-position error (m) of the fitted camera for true pixels of floor points on a ring."""
    phi = np.radians(np.arange(0.0, 360.0, 5.0))
    xy = distance_m * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return np.hypot(*(fitted.pixels_to_floor(truth.floor_to_pixels(xy)) - xy).T)


@pytest.mark.parametrize(
    "kb",
    [[1.0], [1.0, -0.05], [1.0, -0.02, 0.001], [0.97, -0.03, 0.002, -0.0001],
     [1.0, -0.02, 0.001, 0.0002, -0.00003]],
)
def test_noise_free_marks_recover_the_lens(kb: list[float]) -> None:
    truth = camera_from_dict({**BASE, "kb": kb})
    fit = _fit(simulate_ruler_marks(truth, FOUR_RULERS, EVERY_HALF_METRE), coefficients=len(kb))
    assert fit.camera.kb[0] == 1.0  # fx fitted, k1 = 1
    # The same lens: fx·k_j agree.
    np.testing.assert_allclose(np.array(fit.camera.kb) * fit.camera.focal_px[0], np.array(kb) * 940.0,
                               rtol=1e-7, atol=1e-7)
    assert fit.camera.principal_point == TRUE.principal_point
    assert fit.rms_m < 1e-9 and fit.rms_px < 1e-6 and fit.max_abs_m < 1e-9
    assert _ring_errors_m(fit.camera, truth, 10.0).max() < 1e-9
    assert not fit.monotonic_constrained


def test_more_coefficients_than_the_lens_has() -> None:
    fit = _fit(simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE), coefficients=5)
    assert len(fit.camera.kb) == 5
    assert _ring_errors_m(fit.camera, TRUE, 10.0).max() < 1e-6


def test_fixed_focal_keeps_fx_and_fits_k1() -> None:
    fit = _fit(simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE), focal_px=900.0)
    assert fit.camera.focal_px == (900.0, 900.0)
    assert fit.camera.kb[0] == pytest.approx(940.0 / 900.0, rel=1e-9)
    assert _ring_errors_m(fit.camera, TRUE, 10.0).max() < 1e-9


@pytest.mark.parametrize(
    ("directions_deg", "worst_median_m", "rms_median_m"),
    [
        # Measured over 200 seeds: worst direction p50 1.06 cm / p95 2.10 cm, RMS p50 0.69 cm.
        (FOUR_RULERS, 0.015, 0.01),
        # Measured over 200 seeds: worst direction p50 0.77 cm / p95 1.49 cm, RMS p50 0.52 cm.
        ([0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0], 0.01, 0.0075),
    ],
)
def test_one_pixel_noise_at_ten_metres(directions_deg: list[float], worst_median_m: float,
                                       rms_median_m: float) -> None:
    # The protocol: rulers in several directions, a mark every 25 cm up to 10 m, every mark (the
    # nadir too) clicked with 1 px of Gaussian noise per axis; θ at 10 m is 72°. The error is that
    # of the fitted camera's floor positions for true pixels 10 m out, in 72 directions.
    worst, rms = [], []
    for seed in range(20):
        marks = simulate_ruler_marks(TRUE, directions_deg, np.arange(0.25, 10.001, 0.25), noise_px=1.0,
                                     seed=seed)
        fit = _fit(marks, fit_principal_point=True)
        errors = _ring_errors_m(fit.camera, TRUE, 10.0)
        worst.append(errors.max())
        rms.append(math.sqrt(np.mean(errors ** 2)))
        assert 0.5 < fit.rms_px < 1.5
    assert np.median(worst) < worst_median_m
    assert np.median(rms) < rms_median_m
    assert max(worst) < 0.03


def test_principal_point_from_a_noisy_nadir_is_worse_than_fitted() -> None:
    fixed, fitted = [], []
    for seed in range(10):
        marks = simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE, noise_px=1.0, seed=seed)
        fixed.append(_ring_errors_m(_fit(marks).camera, TRUE, 10.0).max())
        fitted.append(_ring_errors_m(_fit(marks, fit_principal_point=True).camera, TRUE, 10.0).max())
    assert np.median(fitted) < np.median(fixed)


@pytest.mark.parametrize("with_xy", [False, True])
def test_aspect_ratio_and_principal_point_are_fitted(with_xy: bool) -> None:
    truth = camera_from_dict({**BASE, "focal_px": [940.0, 930.6]})
    marks = simulate_ruler_marks(truth, [0.0, 60.0, 150.0, 250.0], EVERY_HALF_METRE, with_xy=with_xy)
    fit = _fit(marks, fit_aspect_ratio=True, fit_principal_point=True, principal_point=(1470.0, 1480.0))
    np.testing.assert_allclose(fit.camera.focal_px, truth.focal_px, rtol=1e-7)
    np.testing.assert_allclose(fit.camera.principal_point, truth.principal_point, atol=1e-5)
    assert fit.rms_m < 1e-6


def test_principal_point_fitted_without_a_nadir_mark() -> None:
    marks = simulate_ruler_marks(TRUE, [10.0, 100.0, 200.0, 300.0], EVERY_HALF_METRE)
    away = ~marks.is_nadir
    no_nadir = RulerMarks(marks.uv_px[away], marks.distance_m[away], marks.xy_m[away],
                          tuple(np.asarray(marks.ruler)[away]))
    fit = _fit(no_nadir, fit_principal_point=True)
    np.testing.assert_allclose(fit.camera.principal_point, TRUE.principal_point, atol=1e-6)
    assert "image centre" in fit.notes[0].message


def test_monotonicity_constraint_keeps_the_lens_valid() -> None:
    # An orthographic-like lens (r = sin θ) seen to 75°: two coefficients cannot follow it, and the
    # unconstrained fit turns back before 89°.
    kb = [1.0, -1 / 6, 1 / 120, -1 / 5040, 1 / 362880]
    truth = camera_from_dict({**BASE, "kb": kb, "max_theta_deg": 89})
    marks = simulate_ruler_marks(truth, FOUR_RULERS, np.arange(0.5, 12.001, 0.5))
    fit = _fit(marks, coefficients=2, max_theta_deg=89)
    assert fit.monotonic_constrained
    assert any("strictly increasing" in note.message for note in fit.notes)
    assert monotonic_violation(fit.camera.kb, math.radians(89)) is None
    unconstrained = -1 / (3 * fit.camera.kb[1])  # θ² where 1 + 3·k2·θ² would reach 0 for k1 = 1
    assert fit.camera.kb[1] < 0 and math.sqrt(unconstrained) <= math.radians(89) + 1e-3
    # With three coefficients the fit follows the lens and needs no constraint.
    assert not _fit(marks, coefficients=3, max_theta_deg=89).monotonic_constrained


def test_residuals_point_at_a_bad_mark() -> None:
    marks = simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE)
    bad = 15
    distance = marks.distance_m.copy()
    distance[bad] += 0.05  # a misread tape
    fit = _fit(RulerMarks(marks.uv_px, distance, marks.xy_m, marks.ruler), coefficients=3)
    residuals = fit.residuals
    assert int(np.argmax(np.abs(residuals.distance_error_m))) == bad
    assert residuals.distance_error_m[bad] < -0.02  # the camera puts it nearer than the tape says
    assert int(np.argmax(residuals.pixel_error_px)) == bad
    assert np.isnan(residuals.position_error_m).all()
    assert fit.rms_m == pytest.approx(math.sqrt(np.mean(residuals.distance_error_m ** 2)))
    np.testing.assert_allclose(residuals.fitted_distance_m - distance, residuals.distance_error_m)


def test_position_residuals_with_floor_coordinates() -> None:
    marks = simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE, noise_px=0.5, seed=1, with_xy=True)
    fit = _fit(marks, fit_principal_point=True)
    assert np.isfinite(fit.residuals.position_error_m).all()
    assert (fit.residuals.position_error_m >= np.abs(fit.residuals.distance_error_m) - 1e-12).all()
    assert fit.residuals.position_error_m.max() < 0.05


def test_notes_say_how_far_the_marks_reach() -> None:
    fit = _fit(simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE))
    assert fit.theta_max_marked_deg == pytest.approx(math.degrees(math.atan(10 / 3.2)))
    assert "nadir mark" in fit.notes[0].message
    assert "10.00 m" in fit.notes[1].message and "extrapolated" in fit.notes[1].message


def _marks_on_one_line() -> RulerMarks:
    return simulate_ruler_marks(TRUE, [0.0, 180.0], EVERY_HALF_METRE)


@pytest.mark.parametrize(
    ("altitude_m", "config", "camera_id", "marks", "message"),
    [
        (0.0, {}, "cam", None, "altitude_m"),
        (-3.2, {}, "cam", None, "altitude_m"),
        (float("nan"), {}, "cam", None, "altitude_m"),
        (float("inf"), {}, "cam", None, "altitude_m"),
        (3.2, {"coefficients": 3}, "cam",
         simulate_ruler_marks(TRUE, FOUR_RULERS, [1.0, 2.0]), "coefficients: 3 coefficients need marks at 3"),
        (3.2, {"principal_point": (4000.0, 10.0)}, "cam", None, "principal_point"),
        (3.2, {"fit_principal_point": True}, "cam", _marks_on_one_line(), "two directions"),
        (3.2, {"max_theta_deg": 60.0}, "cam", None, "max_theta_deg"),
        (3.2, {}, "bad id!", None, "id"),
    ],
)
def test_refused_fits_name_the_field(altitude_m: float, config: dict[str, Any], camera_id: str,
                                     marks: RulerMarks | None, message: str) -> None:
    marks = marks if marks is not None else simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE)
    with pytest.raises(CalibrationError, match=message):
        fit_ruler_calibration(marks, altitude_m, SIZE, camera_id, RulerFitConfig(**config))


def test_marks_without_a_nadir_need_a_principal_point() -> None:
    marks = simulate_ruler_marks(TRUE, FOUR_RULERS, EVERY_HALF_METRE)
    away = ~marks.is_nadir
    unlabelled = ("",) * int(away.sum())
    no_nadir = RulerMarks(marks.uv_px[away], marks.distance_m[away], marks.xy_m[away], unlabelled)
    with pytest.raises(CalibrationError, match="principal_point: the marks have no nadir"):
        _fit(no_nadir)
    given = _fit(no_nadir, principal_point=TRUE.principal_point)
    assert given.camera.principal_point == TRUE.principal_point


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"coefficients": 0}, "coefficients must be 1 to 5"),
        ({"coefficients": 6}, "coefficients must be 1 to 5"),
        ({"focal_px": 0.0}, "focal_px"),
        ({"focal_px": float("nan")}, "focal_px"),
        ({"aspect_ratio": -1.0}, "aspect_ratio"),
        ({"principal_point": (float("nan"), 1.0)}, "principal_point"),
        ({"max_theta_deg": 180.0}, "max_theta_deg"),
    ],
)
def test_refused_configs_name_the_field(config: dict[str, Any], message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        RulerFitConfig(**config)
