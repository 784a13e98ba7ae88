"""Tilt fitting, checked against marks that OpenCV projects (tests/fisheye/opencv_tilt.py)."""

from typing import Any

import numpy as np
import pytest
from opencv_tilt import ALTITUDE_M, EVERY_QUARTER_METRE, IMAGE_SIZE, project_floor, ring_m, tape_marks

from fisheye import CalibrationError, FisheyeCamera
from fisheye.calibration import RulerFit, RulerFitConfig, fit_ruler_calibration
from fisheye.ruler_marks import RulerMarks

TILTS_UP_TO_3_DEG = [(2.0, -1.5), (3.0, 0.0), (0.0, -3.0), (-2.1, 2.1)]


def fit(marks: RulerMarks, **config: Any) -> RulerFit:
    return fit_ruler_calibration(marks, ALTITUDE_M, IMAGE_SIZE, "fitted", RulerFitConfig(**config))


def errors_at_m(camera: FisheyeCamera, tilt_deg: tuple[float, float], distance_m: float) -> np.ndarray:
    """Floor-position errors (m) of `camera` on a ring of the true (OpenCV) camera's floor."""
    ring = ring_m(distance_m)
    return np.asarray(np.hypot(*(camera.pixels_to_floor(project_floor(ring, tilt_deg)) - ring).T))


@pytest.mark.parametrize("tilt_deg", TILTS_UP_TO_3_DEG)
@pytest.mark.parametrize("noise_px", [0.0, 0.5])
def test_fitted_tilt_gives_positions_within_2_cm_at_8_m(tilt_deg: tuple[float, float],
                                                         noise_px: float) -> None:
    fitted = fit(tape_marks(tilt_deg, noise_px=noise_px, seed=7), fit_tilt=True)
    assert errors_at_m(fitted.camera, tilt_deg, 8.0).max() < 0.02
    assert fitted.camera.tilt_deg is not None
    np.testing.assert_allclose(fitted.camera.tilt_deg, tilt_deg, atol=0.15 if noise_px else 1e-6)
    assert [note.code for note in fitted.notes if note.code.startswith("tilt")] == ["tilt"]


def test_without_the_tilt_the_error_hides_behind_a_small_rms() -> None:
    marks = tape_marks((2.0, -1.5))
    level = fit(marks)
    assert level.camera.tilt_deg is None
    assert errors_at_m(level.camera, (2.0, -1.5), 8.0).max() > 0.1  # off by more than 10 cm at 8 m
    assert level.rms_m < 0.05
    assert "tilt_fittable" in [note.code for note in level.notes]
    tilted = fit(marks, fit_tilt=True)
    assert tilted.rms_m < 1e-6 and tilted.rms_px < 1e-4


def test_tilt_with_a_given_principal_point() -> None:
    fitted = fit(tape_marks((2.0, -1.5)), fit_tilt=True, principal_point=(1480.3, 1469.8))
    assert fitted.camera.principal_point == (1480.3, 1469.8)
    np.testing.assert_allclose(fitted.camera.tilt_deg or (0.0, 0.0), (2.0, -1.5), atol=1e-6)


def test_a_level_lens_fits_a_tilt_of_zero() -> None:
    fitted = fit(tape_marks((0.0, 0.0)), fit_tilt=True)
    np.testing.assert_allclose(fitted.camera.tilt_deg or (1.0, 1.0), (0.0, 0.0), atol=1e-6)


def test_marks_near_the_centre_cannot_pin_the_tilt_down() -> None:
    fitted = fit(tape_marks((2.0, -1.5), distances_m=np.arange(0.25, 2.001, 0.25), noise_px=0.5),
                 fit_tilt=True)
    notes = {note.code: note for note in fitted.notes}
    assert notes["tilt_undetermined"].level == "warning"
    assert "cannot pin the tilt down" in notes["tilt_undetermined"].message
    assert notes["marks_short"].level == "warning"


@pytest.mark.parametrize("directions", [(0.0,), (0.0, 180.0), (0.0, 90.0)])
def test_tilt_needs_three_directions(directions: tuple[float, ...]) -> None:
    with pytest.raises(CalibrationError, match="3 or more directions") as raised:
        fit(tape_marks((2.0, -1.5), directions_deg=directions), fit_tilt=True)
    assert raised.value.code == "one_direction"


def test_marks_on_one_radius_are_refused_even_without_the_tilt() -> None:
    with pytest.raises(CalibrationError, match="one radius from the nadir") as raised:
        fit(tape_marks((0.0, 0.0), directions_deg=(30.0,)))
    assert raised.value.code == "one_direction"
    assert fit(tape_marks((0.0, 0.0), directions_deg=(30.0, 210.0))).rms_m < 1e-9  # one line, two radii


def test_many_rulers_count_as_many_directions_up_to_the_limit() -> None:
    fitted = fit(tape_marks((2.0, -1.5), directions_deg=tuple(np.arange(0.0, 360.0, 11.25)),
                            distances_m=np.arange(1.0, 10.001, 1.0)), fit_tilt=True)
    assert errors_at_m(fitted.camera, (2.0, -1.5), 8.0).max() < 1e-6
    with pytest.raises(CalibrationError, match="at most 32 can be") as raised:
        fit(tape_marks((2.0, -1.5), directions_deg=tuple(np.arange(0.0, 360.0, 9.0)),
                       distances_m=np.arange(1.0, 10.001, 1.0)), fit_tilt=True)
    assert raised.value.code == "invalid_marks"


def test_tilt_needs_every_marks_direction() -> None:
    marks = tape_marks((2.0, -1.5))
    unlabelled = RulerMarks(marks.uv_px, marks.distance_m, marks.xy_m, ("",) * len(marks))
    with pytest.raises(CalibrationError, match="neither a ruler label nor x_m, y_m"):
        fit(unlabelled, fit_tilt=True)


def _edited(marks: RulerMarks, index: int, uv: Any = None, distance: float | None = None) -> RulerMarks:
    pixels, distances = marks.uv_px.copy(), marks.distance_m.copy()
    if uv is not None:
        pixels[index] = uv
    if distance is not None:
        distances[index] = distance
    return RulerMarks(pixels, distances, marks.xy_m, marks.ruler)


@pytest.mark.parametrize(
    ("edit", "config", "code", "message"),
    [
        (lambda m: tape_marks((2.0, -1.5), distances_m=np.array([1.0, 2.0])), {"coefficients": 3},
         "too_few_marks", "3 coefficients need marks at 3 or more different non-zero distances"),
        (lambda m: _edited(m, 5, distance=0.0), {}, "nadir_mismatch", "has distance 0 but lies"),
        (lambda m: _edited(m, 12, uv=m.uv_px[8]), {}, "not_monotonic", "nearer the nadir in the image"),
        (lambda m: _edited(m, 3, uv=(3100.0, 20.0)), {}, "frame_size_mismatch",
         "outside the 2952x2952 image"),
        (lambda m: m, {"fit_principal_point": True, "coefficients": 9}, "invalid_options", "coefficients"),
    ],
)
def test_bad_marks_are_refused_with_a_code(edit: Any, config: dict[str, Any], code: str,
                                           message: str) -> None:
    marks = edit(tape_marks((2.0, -1.5), distances_m=EVERY_QUARTER_METRE))
    with pytest.raises(CalibrationError, match=message) as raised:
        fit(marks, **config)
    assert raised.value.code == code


def test_marks_that_leave_the_lens_undetermined_are_refused_not_crashed() -> None:
    # Three marks and an aspect ratio of 1e-6: the monotonicity constraints have no common solution.
    marks = RulerMarks.from_arrays([[11.0, 82.0], [74.0, 34.0], [48.0, 72.0]], [2.0, 0.0, 1.0],
                                   ruler=["c", "c", "c"])
    with pytest.raises(CalibrationError, match="do not determine a lens") as raised:
        fit_ruler_calibration(marks, 3.2, (100, 100), "x", RulerFitConfig(coefficients=2, aspect_ratio=1e-6))
    assert raised.value.code == "fit_failed"
