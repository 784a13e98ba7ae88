"""REST errors: every failure answers `{"error": {"code": "...", "message": "..."}}` (DESIGN.md)."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from service.frame_decode import FrameError

log = logging.getLogger(__name__)

# Pipeline refusals and the HTTP status each one answers with.
FRAME_ERROR_STATUS = {
    "empty_body": 400,
    "bad_image": 400,
    "unsupported_image": 415,
    "image_too_large": 413,
    "frame_size_mismatch": 422,
    "frame_too_small": 422,
}

_STATUS_CODES = {
    400: "bad_request", 401: "unauthorized", 404: "not_found", 405: "method_not_allowed",
    408: "request_timeout", 413: "payload_too_large", 415: "unsupported_media_type",
    422: "invalid_request", 503: "unavailable",
}


class ApiError(Exception):
    """An error answer: HTTP `status`, a stable machine-readable `code`, a human `message`."""

    def __init__(self, status: int, code: str, message: str, headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.code = code
        self.message = message
        self.headers = headers or {}


def error_response(status: int, code: str, message: str,
                   headers: dict[str, str] | None = None) -> JSONResponse:
    return JSONResponse({"error": {"code": code, "message": message}}, status_code=status, headers=headers)


def frame_error(error: FrameError) -> ApiError:
    return ApiError(FRAME_ERROR_STATUS.get(error.code, 400), error.code, error.message)


def _validation_message(error: RequestValidationError) -> str:
    parts = []
    for item in error.errors():
        location = ".".join(str(p) for p in item.get("loc", ()) if p != "body") or "request"
        parts.append(f"{location}: {item.get('msg', 'invalid')}")
    return "; ".join(parts)


def install_error_handlers(app: FastAPI) -> None:
    """Answer ApiError, HTTP errors, validation errors and crashes in the error shape."""

    @app.exception_handler(ApiError)
    async def _api_error(_request: Request, error: ApiError) -> JSONResponse:
        return error_response(error.status, error.code, error.message, error.headers)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(_request: Request, error: StarletteHTTPException) -> JSONResponse:
        code = _STATUS_CODES.get(error.status_code, "http_error")
        return error_response(error.status_code, code, str(error.detail), dict(error.headers or {}))

    @app.exception_handler(RequestValidationError)
    async def _validation_error(_request: Request, error: RequestValidationError) -> JSONResponse:
        return error_response(422, "invalid_request", _validation_message(error))

    @app.exception_handler(Exception)
    async def _crash(_request: Request, error: Exception) -> JSONResponse:
        log.error("unhandled error: %s", error, exc_info=error)
        return error_response(500, "internal", "internal error; see the server log for the request id")
