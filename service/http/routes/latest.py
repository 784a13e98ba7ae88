"""The latest frame of a camera (from any front end) and its detections, for the viewer."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

import cv2
import numpy as np
from fastapi import APIRouter, Path, Query
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from fisheye.camera import CAMERA_ID_PATTERN
from service.core.errors import ApiError
from service.http.dependencies import ReadAccess, ServiceState, State
from service.http.routes.cameras import not_found
from service.http.schemas import DetectResponse, error_responses
from service.latest import LatestFrame
from service.result import result_to_json

# Latest frames show where people are: with a read token configured they need it.
router = APIRouter(tags=["latest frame"], dependencies=[ReadAccess])

CameraId = Path(pattern=CAMERA_ID_PATTERN, description="camera id")
_NO_STORE = {"Cache-Control": "no-store"}
_JPEG_ERRORS = error_responses(404, 409, 422)
_JPEG_ERRORS[409]["description"] = "`sequence` was given and a newer frame has replaced that one"


class LatestResponse(BaseModel):
    camera_id: str
    sequence: int = Field(description="grows with every frame the process receives (any camera); "
                                      "pass it to latest.jpg to get this very frame")
    received_at: str = Field(description="when the frame arrived (UTC, ISO 8601)")
    frontend: str = Field(description="the API the frame came through: rest or grpc")
    media_type: str = Field(description="encoding of the frame as it arrived")
    result: DetectResponse = Field(description="the detect answer for that frame")


async def latest_frame(state: ServiceState, camera_id: str) -> LatestFrame:
    """The camera's latest frame; 404 when the camera is unknown or has had no frame yet."""
    camera = await run_in_threadpool(state.registry.get, camera_id)
    if camera is None:
        raise not_found(camera_id)
    frame = state.runner.latest.get(camera_id)
    if frame is None:
        raise ApiError(404, "no_frame", f"camera {camera_id!r} has had no frame since the service started")
    return frame


def frame_to_jpeg(frame: LatestFrame, quality: int = 90) -> bytes:
    """The frame as JPEG: JPEG bytes as they arrived, anything else decoded and re-encoded."""
    if frame.media_type == "image/jpeg":
        return frame.data
    image = cv2.imdecode(np.frombuffer(frame.data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ApiError(500, "bad_stored_frame", "the stored frame cannot be decoded")
    ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ApiError(500, "encode_failed", "JPEG encoding of the stored frame failed")
    return encoded.tobytes()


@router.get(
    "/v1/cameras/{camera_id}/latest", response_model=LatestResponse,
    responses=error_responses(404, 422),
    summary="The latest frame's detections (REST or gRPC)",
    description="The answer the service gave for the most recent frame of this camera, whichever API "
                "it came through. 404 `no_frame` until the camera's first frame. Frames are kept in "
                "memory only: one per camera, the least recently updated camera is forgotten first.",
)
async def get_latest(state: State, camera_id: str = CameraId) -> Response:
    frame = await latest_frame(state, camera_id)
    body: dict[str, Any] = {
        "camera_id": frame.camera_id,
        "sequence": frame.sequence,
        "received_at": datetime.fromtimestamp(frame.received_unix_s, UTC).isoformat(),
        "frontend": frame.frontend,
        "media_type": frame.media_type,
        "result": result_to_json(frame.result),
    }
    # Built by hand like the detect answer; LatestResponse documents the shape.
    return JSONResponse(body, headers=_NO_STORE)


@router.get(
    "/v1/cameras/{camera_id}/latest.jpg", response_class=Response,
    responses={200: {"content": {"image/jpeg": {"schema": {"type": "string", "format": "binary"}}},
                     "description": "the latest frame as JPEG (header X-Frame-Sequence)"},
               **_JPEG_ERRORS},
    summary="The latest frame itself, as JPEG",
)
async def get_latest_jpeg(
    state: State, camera_id: str = CameraId,
    sequence: int | None = Query(None, ge=1, description="answer 409 unless the latest frame is this one"),
) -> Response:
    frame = await latest_frame(state, camera_id)
    if sequence is not None and sequence != frame.sequence:
        raise ApiError(409, "frame_replaced",
                       f"frame {sequence} was replaced by frame {frame.sequence}; fetch /latest again")
    jpeg = await run_in_threadpool(frame_to_jpeg, frame)
    headers = dict(_NO_STORE, **{"X-Frame-Sequence": str(frame.sequence)})
    return Response(jpeg, media_type="image/jpeg", headers=headers)
