"""Reading a request body with a size limit and a deadline.

A body over the limit is refused from its Content-Length before any of it is read, or as soon as a
chunked body passes the limit; a body that has not fully arrived `timeout_s` after the route began
reading it is refused with 408. Both answers close the connection (`Connection: close`), so the
server does not go on reading (and discarding) the rest of a body it has already refused.
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass
from typing import Any

from fastapi import Request
from starlette.requests import ClientDisconnect

from service.core.errors import ApiError

CLOSE = {"Connection": "close"}


@dataclass(frozen=True)
class BodyLimits:
    """Largest body (`max_bytes`) and the time it may take to arrive (`timeout_s`)."""

    max_bytes: int
    timeout_s: float

    def __post_init__(self) -> None:
        if self.max_bytes < 0 or self.timeout_s <= 0:
            raise ValueError(f"invalid body limits {self}")


def _too_large(message: str) -> ApiError:
    return ApiError(413, "payload_too_large", message, headers=CLOSE)


async def read_json(request: Request, limits: BodyLimits, what: str) -> Any:
    """The body parsed as JSON, or ApiError 400 `bad_json` naming `what` the body should have been
    (and the errors of read_body)."""
    body = await read_body(request, limits)
    try:
        return json.loads(body)
    except ValueError as error:  # JSONDecodeError, UnicodeDecodeError, an int of too many digits
        raise ApiError(400, "bad_json", f"the body is not JSON: {error}") from None
    except RecursionError:
        raise ApiError(400, "bad_json", f"the body is not {what}: JSON nested too deeply") from None


async def read_body(request: Request, limits: BodyLimits) -> bytes:
    """The whole body, or ApiError 413 (too large), 408 (too slow) or 400 (client went away)."""
    declared = request.headers.get("content-length")
    if declared is not None and declared.strip().isdigit() and int(declared) > limits.max_bytes:
        raise _too_large(f"the body is {int(declared)} bytes; the limit is {limits.max_bytes}")
    chunks: list[bytes] = []
    size = 0
    try:
        async with asyncio.timeout(limits.timeout_s):
            async for chunk in request.stream():
                size += len(chunk)
                if size > limits.max_bytes:
                    raise _too_large(f"the body passes the limit of {limits.max_bytes} bytes")
                chunks.append(chunk)
    except TimeoutError:
        raise ApiError(408, "request_timeout",
                       f"the body did not arrive within {limits.timeout_s:g} s ({size} bytes came)",
                       headers=CLOSE) from None
    except ClientDisconnect:
        raise ApiError(400, "client_disconnected", "the client closed the connection mid-body",
                       headers=CLOSE) from None
    return b"".join(chunks)


async def read_json_object(request: Request, limits: BodyLimits, what: str, code: str) -> dict[str, Any]:
    """A body that must be one JSON object (`what`, e.g. "a camera record"): 400 `bad_json` when it
    is not JSON, 422 `code` when it is JSON but not an object."""
    record = await read_json(request, limits, what)
    if not isinstance(record, dict):
        raise ApiError(422, code, f"the body must be a JSON object ({what})")
    return record
