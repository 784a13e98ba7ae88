"""The REST server's connections send without Nagle's delay (see service.http.protocol)."""

from __future__ import annotations

import socket
from typing import Any

from service.http.protocol import _no_delay


class _Transport:
    """What the protocol sees of uvicorn's transport: its socket (uvloop's does not set TCP_NODELAY)."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock

    def get_extra_info(self, name: str) -> Any:
        return self.sock if name == "socket" else None


def test_accepted_connections_get_tcp_nodelay() -> None:
    with socket.create_server(("127.0.0.1", 0)) as listener, \
            socket.create_connection(listener.getsockname()):
        accepted, _ = listener.accept()
        with accepted:
            accepted.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 0)
            _no_delay(_Transport(accepted))  # type: ignore[arg-type]
            assert accepted.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1


def test_unix_sockets_are_left_alone() -> None:
    left, right = socket.socketpair()
    with left, right:
        _no_delay(_Transport(left))  # type: ignore[arg-type]  # no TCP option on AF_UNIX: no error
