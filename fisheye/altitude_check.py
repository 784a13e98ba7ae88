"""Check a camera's altitude against marks at known floor positions.

A wrong altitude scales every position FishLoc reports: the floor point of a pixel is the altitude
times what the lens alone gives (`x = Z·tan θ·cos φ`, tilt included, since a tilted ray still meets
the floor at a distance proportional to Z). So with the lens fixed, the altitude that best explains
marks at known distances (or x, y) from the nadir is a one-parameter linear least-squares fit:

    Z* = Σ ⟨p_i, u_i⟩ / Σ |u_i|²

over the marks' known floor vectors `p_i` (or known distances against `|u_i|`) and their pixels'
floor points at unit altitude `u_i`. The report gives Z* beside the configured altitude, the RMS
position error of the marks at each, and the scale error a wrong altitude causes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fisheye.camera import FisheyeCamera
from fisheye.camera_file import CalibrationError
from fisheye.ruler_marks import RulerMarks

FloatArray = NDArray[np.float64]
MIN_MARKS = 2  # off the nadir, with a floor point


@dataclass(frozen=True)
class AltitudeCheck:
    """`fitted_altitude_m` (Z*) beside `configured_altitude_m`; `rms_*_m` the marks' RMS position
    (or distance) error at each; `used` how many marks took part."""

    configured_altitude_m: float
    fitted_altitude_m: float
    rms_configured_m: float
    rms_fitted_m: float
    used: int

    @property
    def scale_error(self) -> float:
        """Relative error of every position at the configured altitude (+0.02: 2 % too far)."""
        return self.configured_altitude_m / self.fitted_altitude_m - 1.0

    def report(self) -> str:
        return (f"altitude: configured {self.configured_altitude_m:.3f} m, "
                f"fitted {self.fitted_altitude_m:.3f} m from {self.used} marks "
                f"(positions scaled by {self.scale_error:+.2%} at the configured one)\n"
                f"mark RMS: {self.rms_configured_m:.3f} m at the configured altitude, "
                f"{self.rms_fitted_m:.3f} m at the fitted one")


def _errors(altitude_m: float, unit_xy: FloatArray, marks: RulerMarks) -> FloatArray:
    """(K,) position errors m (distance errors where only the distance is known)."""
    predicted = altitude_m * unit_xy
    with_xy = marks.has_xy
    error = np.abs(np.hypot(predicted[:, 0], predicted[:, 1]) - marks.distance_m)
    error[with_xy] = np.linalg.norm(predicted[with_xy] - marks.xy_m[with_xy], axis=1)
    return error


def check_altitude(camera: FisheyeCamera, marks: RulerMarks) -> AltitudeCheck:
    """The altitude that best explains `marks` with `camera`'s lens (module docstring);
    CalibrationError when fewer than MIN_MARKS marks off the nadir have a floor point."""
    unit_camera = camera.model_copy(update={"altitude_m": 1.0})
    unit_xy = unit_camera.pixels_to_floor(marks.uv_px)  # (N, 2) floor point per metre of altitude
    usable = ~marks.is_nadir & np.all(np.isfinite(unit_xy), axis=1)
    if int(usable.sum()) < MIN_MARKS:
        raise CalibrationError(f"the altitude check needs at least {MIN_MARKS} marks off the nadir whose "
                               f"pixels have a floor point; got {int(usable.sum())}")
    unit, kept = unit_xy[usable], RulerMarks(marks.uv_px[usable], marks.distance_m[usable],
                                             marks.xy_m[usable], tuple(np.array(marks.ruler)[usable]))
    with_xy = kept.has_xy
    # Known (x, y): ⟨p, u⟩ against |u|²; known distance only: d·|u| against |u|².
    numerator = float(np.sum(kept.xy_m[with_xy] * unit[with_xy]))
    numerator += float(np.sum(kept.distance_m[~with_xy] * np.hypot(unit[~with_xy, 0], unit[~with_xy, 1])))
    fitted = numerator / float(np.sum(unit ** 2))
    if not (math.isfinite(fitted) and fitted > 0):
        raise CalibrationError(f"the marks give no positive altitude (fit {fitted:g} m)")
    rms = [float(np.sqrt(np.mean(_errors(z, unit, kept) ** 2))) for z in (camera.altitude_m, fitted)]
    return AltitudeCheck(camera.altitude_m, fitted, rms[0], rms[1], int(usable.sum()))
