"""The altitude check: the altitude that best explains marks at known floor positions."""

from __future__ import annotations

import numpy as np
import pytest

from fisheye import camera_from_dict
from fisheye.altitude_check import check_altitude
from fisheye.camera_file import CalibrationError
from fisheye.ruler_marks import RulerMarks, simulate_ruler_marks

TRUE = camera_from_dict({
    "id": "hall", "altitude_m": 3.2, "image_size": [2952, 2952], "principal_point": [1480.3, 1469.8],
    "focal_px": [940.0, 940.0], "kb": [1.0, -0.02, 0.001],
})


@pytest.mark.parametrize("with_xy", [False, True])
@pytest.mark.parametrize("configured_m", [3.2, 3.0, 3.5])
def test_finds_the_true_altitude_beside_a_wrong_one(with_xy: bool, configured_m: float) -> None:
    marks = simulate_ruler_marks(TRUE, [0.0, 120.0, 240.0], np.arange(1.0, 9.01, 1.0), noise_px=0.3, seed=4,
                                 with_xy=with_xy)
    configured = TRUE.model_copy(update={"altitude_m": configured_m})
    check = check_altitude(configured, marks)
    assert check.used == 27 and check.configured_altitude_m == configured_m
    assert check.fitted_altitude_m == pytest.approx(3.2, abs=0.01)
    assert check.scale_error == pytest.approx(configured_m / 3.2 - 1.0, abs=0.005)
    assert check.rms_fitted_m < 0.02
    if configured_m != 3.2:  # a wrong altitude shows in the marks' errors and the report
        assert check.rms_configured_m > 5 * check.rms_fitted_m
        assert f"fitted {check.fitted_altitude_m:.3f} m" in check.report()


def test_is_exact_without_noise_and_refuses_too_few_marks() -> None:
    marks = simulate_ruler_marks(TRUE, [45.0], [2.0, 6.0])
    check = check_altitude(TRUE.model_copy(update={"altitude_m": 2.5}), marks)
    assert check.fitted_altitude_m == pytest.approx(3.2, rel=1e-9)
    assert check.rms_fitted_m == pytest.approx(0.0, abs=1e-9)
    nadir_and_one = RulerMarks.from_arrays(marks.uv_px[:2], marks.distance_m[:2])
    with pytest.raises(CalibrationError, match="at least 2 marks off the nadir"):
        check_altitude(TRUE, nadir_and_one)
