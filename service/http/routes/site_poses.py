"""Placing a camera on its site's map: fit its `site_pose` from floor points of known site position."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Path, Request
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.concurrency import run_in_threadpool

from fisheye import FisheyeCamera, camera_to_dict, fit_site_pose
from fisheye.camera import CAMERA_ID_PATTERN
from fisheye.camera_file import describe_validation_error
from service.core.errors import ApiError
from service.http.dependencies import State, require_write_token
from service.http.request_body import BodyLimits, read_json_object
from service.http.routes.cameras import not_found
from service.http.schemas import error_responses, inline_schema

router = APIRouter(tags=["cameras"])

Pair = Annotated[list[Annotated[float, Field(allow_inf_nan=False)]], Field(min_length=2, max_length=2)]


class PosePoint(BaseModel):
    """A floor point seen by the camera (its floor position, or the pixel of it in a frame at the
    calibration's resolution) and where it lies on the site's map."""

    model_config = ConfigDict(extra="forbid")

    floor_m: Pair | None = Field(None, description="[x, y] m in the camera's floor frame")
    pixel: Pair | None = Field(None, description="[u, v] px of the point in a frame at image_size")
    site_m: Pair = Field(description="[x, y] m of the point in the site frame")


class PoseFitRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")

    points: list[PosePoint] = Field(min_length=2, max_length=256)
    save: bool = Field(False, description="store the fitted pose in the camera's record (needs the API "
                                          "token like a camera write)")


_REQUEST_BODY = {"required": True, "content": {"application/json": {
    "schema": inline_schema(PoseFitRequest)}}}
_MAX_BODY_BYTES = 64 * 1024


class PoseFitResponse(BaseModel):
    camera_id: str
    site_pose: dict[str, float]
    points: list[dict[str, Any]] = Field(description="each point with `fitted_m` (where the pose puts it) "
                                                     "and `err_m` (its distance from `site_m`)")
    rms_m: float
    max_err_m: float
    saved: bool


def _floor_points(camera: FisheyeCamera, points: list[PosePoint]) -> np.ndarray:
    floor = np.full((len(points), 2), np.nan)
    for index, point in enumerate(points):
        if (point.floor_m is None) == (point.pixel is None):
            raise ApiError(422, "invalid_points", f"point {index}: give exactly one of floor_m and pixel")
        if point.floor_m is not None:
            floor[index] = point.floor_m
            continue
        floor[index] = camera.pixels_to_floor(np.array([point.pixel]))[0]
        if not np.isfinite(floor[index]).all():
            raise ApiError(422, "invalid_points", f"point {index}: pixel {point.pixel} has no floor point")
    return floor


@router.post(
    "/v1/cameras/{camera_id}/site-pose/fit", response_model=PoseFitResponse,
    responses=error_responses(400, 401, 404, 413, 422), openapi_extra={"requestBody": _REQUEST_BODY},
    summary="Fit a camera's site pose from floor points whose site positions are known",
    description="Two or more points, each seen by the camera (`floor_m` in its floor frame, or the `pixel` "
                "of it) with its `site_m` on the map. Answers the rigid pose that fits them best and each "
                "point's residual in metres (a 1° yaw error is 14 cm at 8 m from the nadir). `save` "
                "stores the pose in the camera's record.",
)
async def fit_pose(request: Request, state: State,
                   camera_id: str = Path(pattern=CAMERA_ID_PATTERN)) -> dict[str, Any]:
    limits = BodyLimits(_MAX_BODY_BYTES, state.settings.body_timeout_s)
    record = await read_json_object(request, limits, "a pose fit request", "invalid_request")
    try:
        body = PoseFitRequest.model_validate(record)
    except ValidationError as error:
        raise ApiError(422, "invalid_request", describe_validation_error(error, "request")) from None
    if body.save:
        require_write_token(request, state)
    camera = await run_in_threadpool(state.registry.get, camera_id)
    if camera is None:
        raise not_found(camera_id)
    floor = _floor_points(camera, body.points)
    site = np.array([point.site_m for point in body.points])
    try:
        fit = fit_site_pose(floor, site)
    except ValueError as error:
        raise ApiError(422, "invalid_points", str(error)) from None
    pose = fit.pose.model_dump()
    if body.save:
        outcome = await run_in_threadpool(state.registry.put_record, camera_id,
                                          {**camera_to_dict(camera), "site_pose": pose})
        await run_in_threadpool(state.sites.camera_changed, camera_id, outcome.camera)
    fitted = fit.pose.floor_to_site(floor)
    return {
        "camera_id": camera_id,
        "site_pose": {name: round(value, 6) for name, value in pose.items()},
        "points": [{"floor_m": [round(float(v), 4) for v in floor[i]], "site_m": body.points[i].site_m,
                    "fitted_m": [round(float(v), 4) for v in fitted[i]],
                    "err_m": round(float(fit.residuals_m[i]), 4)} for i in range(len(floor))],
        "rms_m": round(fit.rms_m, 4),
        "max_err_m": round(fit.max_m, 4),
        "saved": body.save,
    }
