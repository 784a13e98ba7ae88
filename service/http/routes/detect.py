"""Detection: one encoded frame of a registered camera in, every person's box and floor position out."""

from __future__ import annotations

from collections.abc import AsyncGenerator
from typing import Literal

from fastapi import APIRouter, Path, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser

from fisheye.camera import CAMERA_ID_PATTERN
from service.core.capture_time import CaptureTimeError, parse_capture_time
from service.core.errors import ApiError, frame_error
from service.frame_decode import FrameError
from service.http.dependencies import DetectAccess, ServiceState, State
from service.http.render import render_jpeg
from service.http.request_body import CLOSE, BodyLimits, read_body
from service.http.routes.cameras import not_found
from service.http.schemas import DetectResponse, error_responses
from service.result import result_to_json
from service.runner import OverloadedError

router = APIRouter(tags=["detect"])

# A raw body is recognised by its bytes (JPEG or PNG), whichever of these types it is sent as.
RAW_TYPES = frozenset({"image/jpeg", "image/jpg", "image/png", "application/octet-stream"})
_BINARY = {"schema": {"type": "string", "format": "binary"}}
_REQUEST_BODY = {"required": True, "content": {
    "image/jpeg": _BINARY, "image/png": _BINARY, "application/octet-stream": _BINARY,
    "multipart/form-data": {"schema": {"type": "object", "required": ["image"],
                                       "properties": {"image": {"type": "string", "format": "binary"}}}},
}}


async def _image_from_multipart(request: Request, body: bytes) -> bytes:
    async def stream() -> AsyncGenerator[bytes, None]:
        yield body

    parser = MultiPartParser(request.headers, stream(), max_files=4, max_fields=16)
    try:
        form = await parser.parse()
    except MultiPartException as error:
        raise ApiError(400, "bad_multipart", f"unreadable multipart body: {error.message}") from None
    try:
        field = form.get("image")
        if field is None:
            raise ApiError(422, "missing_image", "the multipart body has no field 'image'")
        if isinstance(field, UploadFile):
            return await field.read()
        return field.encode("latin-1")
    finally:
        await form.close()


def frame_media_type(request: Request) -> str:
    """The media type of a detect request's body, or ApiError 415 when it is not one we take."""
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type not in RAW_TYPES and media_type != "multipart/form-data":
        raise ApiError(
            415, "unsupported_media_type",
            f"Content-Type {media_type or '(none)'} is not accepted; send image/jpeg, image/png or "
            "multipart/form-data with a field 'image'",
        )
    return media_type


async def frame_bytes(request: Request, media_type: str, state: ServiceState) -> bytes:
    """The encoded frame of a detect request: raw JPEG/PNG body or multipart field `image`."""
    body = await read_body(request, BodyLimits(state.settings.max_body_bytes, state.settings.body_timeout_s))
    if media_type == "multipart/form-data":
        body = await _image_from_multipart(request, body)
    if not body:
        raise ApiError(400, "empty_body", "the request has no image")
    return body


@router.post(
    "/v1/cameras/{camera_id}/detect",
    response_class=JSONResponse,
    responses={
        200: {"model": DetectResponse, "description": "detections (JSON), or the frame with them drawn "
                                                      "(image/jpeg) with render=jpeg",
              "content": {"image/jpeg": _BINARY}},
        **error_responses(400, 401, 404, 408, 413, 415, 422, 503),
    },
    dependencies=[DetectAccess],
    summary="Find people in one frame and place them on the floor",
    description="Body: the encoded frame (image/jpeg, image/png) or a multipart form with the field "
                "`image`. Positions are in metres in the camera's floor frame (origin at the nadir, "
                "x towards image right, y towards image top); null when a foot point has no floor point.",
    openapi_extra={"requestBody": _REQUEST_BODY},
)
async def detect(
    request: Request,
    state: State,
    camera_id: str = Path(pattern=CAMERA_ID_PATTERN),
    min_score: float | None = Query(None, ge=0.0, le=1.0,
                                    description="score threshold (default: the model's)"),
    frame_id: str | None = Query(None, max_length=128, description="echoed in the answer"),
    render: Literal["jpeg"] | None = Query(None, description="jpeg: answer with the frame, detections drawn"),
    capture_time: str | None = Query(
        None, max_length=64, description="when the camera took the frame: Unix seconds or an RFC 3339 "
                                         "date-time with offset (default: its arrival); a site's tracks "
                                         "follow this clock"),
) -> Response:
    try:
        captured = None if capture_time is None else parse_capture_time(capture_time)
    except CaptureTimeError as error:
        raise ApiError(422, "invalid_capture_time", str(error)) from None
    if not state.runner.ready:
        raise ApiError(503, "not_ready", "the model is warming up", headers={"Retry-After": "1"})
    camera = await run_in_threadpool(state.registry.get, camera_id)
    if camera is None:
        raise not_found(camera_id)
    media_type = frame_media_type(request)
    runner = state.runner
    try:
        # Admitted before the body is read: under overload, bodies are refused unread, so at most
        # the in-flight limit of them are held in memory at once.
        with runner.admitted("rest"):
            data = await frame_bytes(request, media_type, state)
            result = await runner.run_admitted(data, camera, min_score=min_score, frame_id=frame_id,
                                               frontend="rest", capture_time=captured)
    except OverloadedError as error:
        # The body is left unread; closing the connection stops the server reading and discarding it.
        retry = {"Retry-After": str(error.retry_after_s)} | CLOSE
        raise ApiError(503, "overloaded", str(error), headers=retry) from None
    except FrameError as error:
        raise frame_error(error) from None
    if render == "jpeg":
        jpeg = await run_in_threadpool(render_jpeg, result, data, state.settings.max_pixels)
        return Response(jpeg, media_type="image/jpeg", headers={"X-Detections": str(len(result.detections))})
    return JSONResponse(result_to_json(result))
