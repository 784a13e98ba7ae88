"""uvicorn's HTTP/1.1 protocol with a deadline on the request head.

uvicorn times out idle keep-alive connections but waits for ever for a request line and headers
that arrive slowly (or never, after the connection opens): a few hundred such clients would hold
as many sockets open. This protocol gives each request head `head_timeout_s` from the moment the
connection opens or the request's first byte arrives; past it the client gets `408 Request
Timeout` and the connection is closed. The body has its own deadline (`service.http.request_body`).
"""

from __future__ import annotations

import asyncio
import socket
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

_TIMEOUT_BODY = (
    b'{"error": {"code": "request_timeout", "message": "the request head did not arrive in time"}}'
)
_TIMEOUT_ANSWER = (
    b"HTTP/1.1 408 Request Timeout\r\ncontent-type: application/json\r\nconnection: close\r\n"
    + b"content-length: %d\r\n\r\n" % len(_TIMEOUT_BODY) + _TIMEOUT_BODY
)


def _no_delay(transport: asyncio.Transport) -> None:
    """TCP_NODELAY on the connection. uvicorn writes a response's head and body as two sends; with
    Nagle's algorithm the body waits for the client to ACK the head, which a client that delays its
    ACKs does after 40 ms (measured: a 2952x2952 frame answered in 71 ms instead of 29 ms)."""
    sock = transport.get_extra_info("socket")
    if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


class HeadDeadlineProtocol(HttpToolsProtocol):
    """HttpToolsProtocol that closes connections whose request head is not complete in time."""

    head_timeout_s: float = 10.0

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._head_deadline: asyncio.TimerHandle | None = None

    def _arm_head_deadline(self) -> None:
        self._cancel_head_deadline()
        self._head_deadline = self.loop.call_later(self.head_timeout_s, self._head_timed_out)

    def _cancel_head_deadline(self) -> None:
        if self._head_deadline is not None:
            self._head_deadline.cancel()
            self._head_deadline = None

    def _head_timed_out(self) -> None:
        self._head_deadline = None
        if not self.transport.is_closing():
            self.transport.write(_TIMEOUT_ANSWER)
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        _no_delay(transport)
        self._arm_head_deadline()

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_head_deadline()
        super().connection_lost(exc)

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._arm_head_deadline()

    def on_headers_complete(self) -> None:
        self._cancel_head_deadline()
        super().on_headers_complete()

    def on_response_complete(self) -> None:
        # Between requests the keep-alive timeout applies, not the head deadline.
        self._cancel_head_deadline()
        super().on_response_complete()


def head_deadline_protocol(head_timeout_s: float) -> type[HeadDeadlineProtocol]:
    """A HeadDeadlineProtocol class with this deadline (uvicorn instantiates the class itself)."""
    if head_timeout_s <= 0:
        raise ValueError(f"head_timeout_s must be positive, got {head_timeout_s}")
    return type("HeadDeadlineProtocol", (HeadDeadlineProtocol,), {"head_timeout_s": float(head_timeout_s)})
