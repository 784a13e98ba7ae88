"""Slow clients: a request head or body that does not arrive in time is answered 408 and its
connection closed, while other clients are served as usual."""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator

import pytest
from reliability_cases import JPEG, SCENARIO
from reliability_samples import Samples
from reliability_support import LiveServer, raw_request

from fisheye import FisheyeCamera
from service.core.config import Settings

pytest_plugins = ["reliability_fixtures"]

DEADLINE_S = 1.0


@pytest.fixture
def server(settings_for: Callable[..., Settings]) -> Iterator[LiveServer]:
    with LiveServer(settings_for(head_timeout_s=DEADLINE_S, body_timeout_s=DEADLINE_S)) as live:
        yield live


def _connect(server: LiveServer) -> socket.socket:
    port = int(server.url.rsplit(":", 1)[1])
    return socket.create_connection(("127.0.0.1", port), timeout=30)  # a bound, not an assertion


def _answer_then_close(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes the connection."""
    data = b""
    while chunk := sock.recv(65536):
        data += chunk
    return data


def _good_frame_works(server: LiveServer, samples: Samples) -> None:
    response = raw_request(server.url, "POST", "/v1/cameras/demo/detect", samples.good_jpeg, JPEG)
    assert response.status == 200


def _status(answer: bytes) -> int:
    return int(answer.split(b" ", 2)[1])


def test_slow_body_gets_408_and_others_are_served(server: LiveServer, demo_camera: FisheyeCamera) -> None:
    samples = Samples(demo_camera)
    row = SCENARIO["slow_body"]
    with _connect(server) as slow:
        slow.sendall(b"POST /v1/cameras/demo/detect HTTP/1.1\r\nhost: x\r\ncontent-type: image/jpeg\r\n"
                     b"content-length: 100000\r\n\r\n" + samples.good_jpeg[:100])
        _good_frame_works(server, samples)  # while the slow body is pending
        answer = _answer_then_close(slow)
    assert _status(answer) == row.status and b"request_timeout" in answer
    assert b"connection: close" in answer.lower()
    _good_frame_works(server, samples)


def test_trickled_body_gets_408(server: LiveServer, demo_camera: FisheyeCamera) -> None:
    """A byte every 50 ms keeps the connection busy but the body never completes: the deadline is
    on the whole body, not on the gap between bytes."""
    samples = Samples(demo_camera)
    with _connect(server) as slow:
        slow.sendall(b"POST /v1/cameras/demo/detect HTTP/1.1\r\nhost: x\r\ncontent-type: image/jpeg\r\n"
                     b"content-length: 100000\r\n\r\n")
        slow.settimeout(0.05)
        answer = b""
        for byte in samples.good_jpeg[:2000]:  # bounded: at most 2000 bytes, ~100 s worst case
            try:
                slow.sendall(bytes([byte]))
                answer += slow.recv(65536)
            except TimeoutError:
                continue
            except (BrokenPipeError, ConnectionResetError):
                break
            if answer:
                break
        slow.settimeout(30)
        answer += _answer_then_close(slow)
    assert _status(answer) == SCENARIO["trickled_body"].status and b"request_timeout" in answer
    _good_frame_works(server, samples)


def test_slow_camera_record_gets_408(server: LiveServer) -> None:
    with _connect(server) as slow:
        slow.sendall(b"PUT /v1/cameras/slow HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
                     b"content-length: 500\r\n\r\n{\"altitude_m\": ")
        answer = _answer_then_close(slow)
    assert _status(answer) == 408 and b"request_timeout" in answer
    assert raw_request(server.url, "GET", "/v1/cameras/slow").status == 404


@pytest.mark.parametrize("sent", [b"", b"POST /v1/cameras/demo/detect HTTP/1.1\r\nhost: x\r\n"],
                         ids=["silent_connection", "slow_head"])
def test_slow_or_silent_head_gets_408(server: LiveServer, demo_camera: FisheyeCamera, sent: bytes) -> None:
    samples = Samples(demo_camera)
    with _connect(server) as slow:
        slow.sendall(sent)
        _good_frame_works(server, samples)
        answer = _answer_then_close(slow)
    assert _status(answer) == SCENARIO["slow_head"].status and b"request_timeout" in answer
    _good_frame_works(server, samples)


def test_idle_keep_alive_connection_is_closed(settings_for: Callable[..., Settings]) -> None:
    with LiveServer(settings_for(keep_alive_timeout_s=1)) as live, _connect(live) as idle:
        idle.sendall(b"GET /healthz HTTP/1.1\r\nhost: x\r\n\r\n")
        answer = _answer_then_close(idle)  # returns only because the server closes the connection
    assert _status(answer) == 200 and answer.count(b"HTTP/1.1") == 1
