"""Per-request context: a request id (taken from X-Request-ID or made), an access log line and the
request counters, as plain ASGI middleware so it also sees errors and streaming answers."""

from __future__ import annotations

import logging
import re
import time
import uuid

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.core.logs import request_id_var
from service.core.metrics import ServiceMetrics

log = logging.getLogger("fishloc.access")

_REQUEST_ID_RE = re.compile(r"^[A-Za-z0-9._-]{1,128}$")


class RequestContextMiddleware:
    def __init__(self, app: ASGIApp, metrics: ServiceMetrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        given = dict(scope["headers"]).get(b"x-request-id", b"").decode("latin-1")
        request_id = given if _REQUEST_ID_RE.match(given) else uuid.uuid4().hex
        token = request_id_var.set(request_id)
        status = 500
        start = time.perf_counter()

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
                message["headers"] = [*message.get("headers", []), (b"x-request-id", request_id.encode())]
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        finally:
            elapsed = time.perf_counter() - start
            route = scope.get("route")
            template = str(getattr(route, "path", "unmatched"))
            method = str(scope["method"])
            self.metrics.requests.labels(route=template, method=method, status=str(status)).inc()
            self.metrics.request_seconds.labels(route=template).observe(elapsed)
            log.info("%s %s %d", method, scope["path"], status, extra={
                "method": method, "path": scope["path"], "route": template, "status": status,
                "duration_ms": round(elapsed * 1e3, 3),
                "camera_id": scope.get("path_params", {}).get("camera_id"),
            })
            request_id_var.reset(token)
