"""Fit a camera from ruler marks without saving it: the fitting of `fishloc calibrate --marks`.

The answer holds the fitted camera, every mark's residual and coded notes, for a viewer to show at
once; saving the camera is a `PUT /v1/cameras/{id}`. Nothing is written here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.concurrency import run_in_threadpool

from fisheye import (
    CalibrationError,
    RulerFit,
    RulerFitConfig,
    RulerMarks,
    camera_to_dict,
    fit_ruler_calibration,
)
from fisheye.arrays import resolution_scale, scale_pixels
from fisheye.calibration import MAX_COEFFICIENTS
from fisheye.camera import CAMERA_ID_PATTERN
from fisheye.camera_file import describe_validation_error
from service.core.errors import ApiError
from service.http.dependencies import State
from service.http.request_body import BodyLimits, read_json
from service.http.schemas import CalibrationFit, error_responses, inline_schema

router = APIRouter(tags=["calibrations"])

MAX_MARKS = 1000  # far more than anyone clicks; bounds the work of one request
_MAX_BODY_BYTES = 512 * 1024


class Mark(BaseModel):
    """One ruler mark: its pixel, and its floor distance from the nadir or its floor position."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    ruler: str = Field(default="", max_length=64, description="label of the ruler (tape) it lies on")
    u: float = Field(description="px, at frame_size (image_size when no frame_size)")
    v: float
    distance_m: float | None = Field(default=None, ge=0, description="floor distance from the nadir; "
                                                                     "0 marks the nadir")
    x_m: float | None = Field(default=None, description="floor position, when the ruler's direction is known")
    y_m: float | None = None


class FitOptions(BaseModel):
    """The options of `fishloc calibrate --marks` (fisheye.RulerFitConfig)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    coefficients: int = Field(default=3, ge=1, le=MAX_COEFFICIENTS, description="kb terms to fit")
    focal_px: float | None = Field(default=None, gt=0, description="keep this fx (k1 fitted); "
                                                                   "null fits fx with k1 = 1")
    aspect_ratio: float = Field(default=1.0, gt=0, description="fy/fx")
    fit_aspect_ratio: bool = False
    principal_point: tuple[float, float] | None = Field(
        default=None, description="[u0, v0] px at image_size; null: the nadir mark")
    fit_principal_point: bool = False
    max_theta_deg: float | None = Field(default=None, gt=0, lt=180)
    fit_tilt: bool = Field(default=False, description="fit tilt_deg (rulers in 3+ directions)")


class FitRequest(BaseModel):
    """Body of POST /v1/calibrations/fit."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    camera_id: str = Field(default="camera", pattern=CAMERA_ID_PATTERN, description="id of the fitted camera")
    altitude_m: float = Field(gt=0, le=1000, description="lens height above the floor (m)")
    image_size: tuple[int, int] = Field(description="[W, H] the calibration is made at (px)")
    frame_size: tuple[int, int] | None = Field(
        default=None, description="[w, h] of the frame the marks were clicked on, when it is not "
                                  "image_size (same aspect ratio; the marks are scaled)")
    marks: list[Mark] = Field(min_length=1, max_length=MAX_MARKS)
    options: FitOptions = Field(default_factory=FitOptions)


def _marks(request: FitRequest) -> RulerMarks:
    """The request's marks at image_size; CalibrationError when they or the frame size are wrong."""
    uv = np.array([[mark.u, mark.v] for mark in request.marks], dtype=np.float64)
    if request.frame_size is not None and tuple(request.frame_size) != tuple(request.image_size):
        try:
            scale = resolution_scale(request.frame_size, request.image_size)
        except ValueError as error:
            raise CalibrationError(f"frame_size: {error} (image_size)", code="frame_size_mismatch") from None
        uv = scale_pixels(uv, scale)
    xy = np.array([[math.nan if mark.x_m is None else mark.x_m, math.nan if mark.y_m is None else mark.y_m]
                   for mark in request.marks], dtype=np.float64)
    distance = np.array([math.nan if mark.distance_m is None else mark.distance_m for mark in request.marks])
    missing = np.isnan(distance)
    if np.isnan(xy[missing]).any():
        index = int(np.flatnonzero(missing & np.isnan(xy).any(axis=1))[0])
        raise CalibrationError(f"marks.{index}: give distance_m or both x_m and y_m", code="invalid_marks")
    distance[missing] = [math.hypot(x, y) for x, y in xy[missing]]  # as marks.csv reads such a row
    return RulerMarks(uv, distance, xy, tuple(mark.ruler for mark in request.marks))


def fit_request(request: FitRequest) -> RulerFit:
    """Run the fit of `fishloc calibrate` on a request; CalibrationError when it cannot be made."""
    config = RulerFitConfig(**request.options.model_dump())
    return fit_ruler_calibration(_marks(request), request.altitude_m, request.image_size,
                                 request.camera_id, config)


def _number(value: float, digits: int) -> float | None:
    return round(float(value), digits) if math.isfinite(value) else None


def fit_to_json(request: FitRequest, fit: RulerFit) -> dict[str, Any]:
    """The answer: the camera file, each mark with its residuals (as sent, plus fitted_distance_m,
    err_m, pos_err_m, err_px), the RMS figures and the notes."""
    residuals = fit.residuals
    marks = []
    for index, mark in enumerate(request.marks):
        marks.append(mark.model_dump() | {
            "fitted_distance_m": _number(residuals.fitted_distance_m[index], 5),
            "err_m": _number(residuals.distance_error_m[index], 5),
            "pos_err_m": _number(residuals.position_error_m[index], 5),
            "err_px": _number(residuals.pixel_error_px[index], 3),
        })
    return {
        "camera": camera_to_dict(fit.camera),
        "marks": marks,
        "rms_m": _number(fit.rms_m, 5),
        "rms_px": _number(fit.rms_px, 3),
        "max_abs_m": _number(fit.max_abs_m, 5),
        "theta_max_marked_deg": round(fit.theta_max_marked_deg, 3),
        "monotonic_constrained": fit.monotonic_constrained,
        "notes": [{"code": note.code, "level": note.level, "message": note.message} for note in fit.notes],
    }


@router.post(
    "/v1/calibrations/fit", response_model=CalibrationFit, responses=error_responses(400, 413, 422),
    summary="Fit a camera from ruler marks (nothing is saved)",
    description="The fitting of `fishloc calibrate --marks`, with the same options. Answers the fitted "
                "camera file, every mark's residuals and notes (`code`, `level`, `message`); a refused "
                "fit is a 422 whose `code` says why (too_few_marks, one_direction, nadir_mismatch, "
                "not_monotonic, frame_size_mismatch, fit_failed, invalid_marks, invalid_options). Save "
                "the camera with `PUT /v1/cameras/{id}`.",
    openapi_extra={"requestBody": {"required": True, "content": {
        "application/json": {"schema": inline_schema(FitRequest)}}}},
)
async def fit_calibration(request: Request, state: State) -> JSONResponse:
    record = await read_json(request, BodyLimits(_MAX_BODY_BYTES, state.settings.body_timeout_s),
                             "a fit request")
    try:
        fit_body = FitRequest.model_validate(record)
    except ValidationError as error:
        raise ApiError(422, "invalid_request", describe_validation_error(error, "body")) from None
    try:
        fit = await run_in_threadpool(fit_request, fit_body)
    except CalibrationError as error:
        raise ApiError(422, error.code, str(error)) from None
    # The camera record leaves its unset fields out, as GET /v1/cameras/{id} does: not through the
    # response model, which would write them as null.
    return JSONResponse(fit_to_json(fit_body, fit))
