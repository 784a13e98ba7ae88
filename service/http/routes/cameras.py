"""The camera registry: list, read, create or replace, delete."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi import APIRouter, Path, Request, Response, status
from starlette.concurrency import run_in_threadpool

from fisheye import CalibrationError, FisheyeCamera, camera_from_dict, camera_to_dict
from fisheye.camera import CAMERA_ID_PATTERN
from fisheye.view_plan import ViewPlan, ViewPlanError
from service.core.errors import ApiError
from service.http.dependencies import State, WriteAccess
from service.http.request_body import BodyLimits, read_json_object
from service.http.schemas import CameraList, CameraView, error_responses
from service.pipeline import ViewBudgetError

router = APIRouter(tags=["cameras"])

CameraId = Path(pattern=CAMERA_ID_PATTERN, description="camera id")
_MAX_RECORD_BYTES = 64 * 1024


def _record_schema() -> dict[str, Any]:
    """The JSON schema of a PUT body: the camera record with `id` optional (the path gives it)."""
    schema = FisheyeCamera.model_json_schema(ref_template="#/components/schemas/{model}")
    schema.pop("$defs", None)  # SitePose is in the components already, by FisheyeCamera
    schema["required"] = [name for name in schema.get("required", []) if name != "id"]
    schema["title"] = "CameraRecord"
    return schema


def not_found(camera_id: str) -> ApiError:
    return ApiError(404, "camera_not_found", f"no camera {camera_id!r} in the registry")


@router.get("/v1/cameras", response_model=CameraList, response_model_exclude_none=True,
            summary="Every camera of the registry")
async def list_cameras(state: State) -> dict[str, list[dict[str, Any]]]:
    cameras = await run_in_threadpool(state.registry.all)
    return {"cameras": [camera_to_dict(camera) for camera in cameras]}


@router.get("/v1/cameras/{camera_id}", response_model=CameraView, response_model_exclude_none=True,
            responses=error_responses(404, 422), summary="One camera's calibration record",
            description="With a planned model, `view` is the view planned for the camera's frames: the "
                        "model input (`input_wh`, `pixels`, `cost_ratio` against the trained strip; "
                        "`wanted_pixels`: what the view the camera's people ask for takes before any "
                        "budget), its "
                        "bands, the smallest person in input px and where, its nadir view (`nadir`: the disc "
                        "below the lens as a second, upright input; null where the budget leaves no room), "
                        "notes (a budget that binds), its `layout`, the `budget` it was planned within "
                        "(`source`: the server's `--max-view-pixels`, or the camera record's own "
                        "`max_view_pixels`), its `second_look` where it has one (its `source`: the "
                        "server's `--second-look` or the record's own `second_look_pixels`; "
                        "`max_cost_ratio`: its px at most against the trained strip's), its "
                        "`longest_person_ratio` (the server's `--longest-person-ratio` or the record's "
                        "own; null: no bound) and the `operating_point` its frames run at (the "
                        "model's own for that layout where it has one).")
async def get_camera(state: State, camera_id: str = CameraId) -> dict[str, Any]:
    camera = await run_in_threadpool(state.registry.get, camera_id)
    if camera is None:
        raise not_found(camera_id)
    record = camera_to_dict(camera)
    pipeline = state.runner.pipeline
    plan = await run_in_threadpool(_plan_or_refuse, pipeline.plan, camera)
    if plan is not None:
        point = pipeline.point(plan.layout)
        budget = pipeline.view_config(camera).max_pixels
        notes = list(plan.notes)
        if camera.max_view_pixels is not None and camera.max_view_pixels > budget:
            notes.insert(0, f"the camera's max_view_pixels {camera.max_view_pixels} is over this server's "
                            f"limit: planned at {budget} px")
        public = plan.public()
        look = public["second_look"]
        if isinstance(look, dict):
            public["second_look"] = {**look, "source": _source(camera.second_look_pixels)}
        record["view"] = {**public, "notes": notes,
                          "budget": {"max_pixels": budget, "source": _source(camera.max_view_pixels)},
                          "operating_point": {"min_score": point.min_score, "nms_iou": point.nms_iou}}
    return record


def _source(own: int | None) -> str:
    """Whose budget a camera's view was planned within: the camera record's own, or the server's."""
    return "server" if own is None else "camera"


def _plan_or_refuse(plan: Callable[[FisheyeCamera], ViewPlan | None], camera: FisheyeCamera
                    ) -> ViewPlan | None:
    """`plan(camera)`: the view planned for `camera` (None for a model of a fixed view); 422 when
    its record asks for a budget over the server's limit or no view can be made."""
    try:
        return plan(camera)
    except ViewBudgetError as error:
        raise ApiError(422, "view_budget_over_limit", f"camera {camera.id}: {error}") from None
    except ViewPlanError as error:
        raise ApiError(422, "view_unplannable", f"camera {camera.id}: {error}") from None


@router.put(
    "/v1/cameras/{camera_id}", response_model=FisheyeCamera, response_model_exclude_none=True,
    dependencies=[WriteAccess], responses={201: {"model": FisheyeCamera, "description": "created"},
                                           **error_responses(400, 401, 413, 422)},
    summary="Create or replace a camera (the next frame uses it)",
    description="Body: the camera-file record of DESIGN.md as JSON; `id` may be left out and must "
                "match the path when given; `max_view_pixels` gives the camera its own view budget, at "
                "most the server's `--max-camera-view-pixels` (422 `view_budget_over_limit` above it); "
                "`second_look_pixels` its own second look in place of the server's `--second-look` "
                "(0: none); `longest_person_ratio` its own bound on a detection's length along the ray "
                "in place of the server's `--longest-person-ratio` (1-10 standing adults; 0: none). "
                "Answers 201 when the camera is new, 200 when replaced.",
    openapi_extra={"requestBody": {"required": True, "content": {
        "application/json": {"schema": _record_schema()}}}},
)
async def put_camera(request: Request, response: Response, state: State,
                     camera_id: str = CameraId) -> dict[str, Any]:
    limits = BodyLimits(_MAX_RECORD_BYTES, state.settings.body_timeout_s)
    record = await read_json_object(request, limits, "a camera record", "invalid_camera")
    record.pop("view", None)  # what GET adds (the planned view) is the service's, not the camera's
    try:
        candidate = camera_from_dict({**record, "id": record.get("id", camera_id)})
    except CalibrationError as error:
        raise ApiError(422, "invalid_camera", str(error)) from None
    # nothing is saved for a view that cannot be planned or a budget over the limit
    await run_in_threadpool(_plan_or_refuse, state.runner.pipeline.admit, candidate)
    try:
        outcome = await run_in_threadpool(state.registry.put_record, camera_id, record)
    except CalibrationError as error:
        raise ApiError(422, "invalid_camera", str(error)) from None
    await run_in_threadpool(state.sites.camera_changed, camera_id, outcome.camera)
    response.status_code = status.HTTP_201_CREATED if outcome.created else status.HTTP_200_OK
    return camera_to_dict(outcome.camera)


@router.delete("/v1/cameras/{camera_id}", status_code=204, response_class=Response,
               dependencies=[WriteAccess], responses=error_responses(401, 404, 422),
               summary="Remove a camera")
async def delete_camera(state: State, camera_id: str = CameraId) -> Response:
    if not await run_in_threadpool(state.registry.delete, camera_id):
        raise not_found(camera_id)
    await run_in_threadpool(state.sites.camera_changed, camera_id, None)
    return Response(status_code=204)
