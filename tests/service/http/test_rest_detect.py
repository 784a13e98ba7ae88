"""POST /v1/cameras/{id}/detect against a real uvicorn server on a loopback port.

The model is the plumbing test double (see service_doubles): a bright disk drawn where a person
stands on the demo camera's floor must come back at that floor position.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Iterator

import cv2
import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer

from fisheye import FisheyeCamera, camera_to_dict
from service.core.config import Settings

JPEG = {"content-type": "image/jpeg"}


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, double_model_path: object) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("rest")
    settings = Settings(model=double_model_path, database=str(folder / "cameras.db"), http_port=0,
                        grpc_port=-1, threads=1, max_body_bytes=4 * 1024 * 1024, max_pixels=9_000_000)
    with LiveServer(settings) as live:
        yield live


@pytest.fixture(scope="module")
def frame(demo_camera: FisheyeCamera) -> tuple[bytes, tuple[float, float]]:
    truth = person_frame(demo_camera, (1.5, -1.1), (2048, 2048))
    return encode(truth.bgr), truth.floor_xy_m


def detect_url(server: LiveServer, camera_id: str = "demo") -> str:
    return f"{server.url}/v1/cameras/{camera_id}/detect"


def test_detect_answers_positions(server: LiveServer, frame: tuple[bytes, tuple[float, float]]) -> None:
    data, floor_xy = frame
    response = httpx.post(detect_url(server), content=data, headers=JPEG, params={"frame_id": "42"})
    assert response.status_code == 200, response.text
    body = response.json()
    assert set(body) == {"camera_id", "frame_id", "image", "model", "detections", "timing_ms"}
    assert body["camera_id"] == "demo" and body["frame_id"] == "42"
    assert body["image"] == {"width": 2048, "height": 2048}
    assert body["model"] == {"name": "plumbing-double", "version": "0.0-test"}
    assert set(body["timing_ms"]) == {"decode", "preprocess", "inference", "postprocess", "total"}
    person = body["detections"][0]
    assert set(person) == {
        "score", "box", "corners", "foot_px", "position_m", "distance_m", "site_position_m", "track_id",
    }
    assert person["track_id"] is None  # the demo camera belongs to no site
    assert person["score"] == pytest.approx(0.9)
    assert set(person["box"]) == {"cx", "cy", "w", "h", "angle_deg"}
    assert len(person["corners"]) == 4
    np.testing.assert_allclose(person["position_m"], floor_xy, atol=0.005)
    # The demo camera has a site pose at the origin with no turn: site = floor position.
    np.testing.assert_allclose(person["site_position_m"], person["position_m"], atol=1e-4)
    assert response.headers["x-request-id"]


def test_multipart_and_png_give_the_same_answer(server: LiveServer, demo_camera: FisheyeCamera) -> None:
    truth = person_frame(demo_camera, (-0.7, 2.0), (1024, 1024), disk_radius_px=20)
    png = encode(truth.bgr, ".png")
    raw = httpx.post(detect_url(server), content=png, headers={"content-type": "image/png"})
    form = httpx.post(detect_url(server), files={"image": ("f.png", encode(truth.bgr, ".png"), "image/png")})
    octets = httpx.post(detect_url(server), content=png, headers={"content-type": "application/octet-stream"})
    assert raw.status_code == form.status_code == octets.status_code == 200
    assert raw.json()["detections"] == form.json()["detections"] == octets.json()["detections"]
    np.testing.assert_allclose(raw.json()["detections"][0]["position_m"], truth.floor_xy_m, atol=0.005)


def test_min_score_query(server: LiveServer, frame: tuple[bytes, tuple[float, float]]) -> None:
    data, _ = frame
    high = httpx.post(detect_url(server), content=data, headers=JPEG, params={"min_score": 0.85})
    low = httpx.post(detect_url(server), content=data, headers=JPEG, params={"min_score": 0.1})
    assert [d["score"] for d in high.json()["detections"]] == pytest.approx([0.9])
    assert [d["score"] for d in low.json()["detections"]] == pytest.approx([0.9, 0.8, 0.2])
    assert high.json()["frame_id"] is None


def test_render_jpeg(server: LiveServer, frame: tuple[bytes, tuple[float, float]]) -> None:
    data, _ = frame
    response = httpx.post(detect_url(server), content=data, headers=JPEG, params={"render": "jpeg"})
    assert response.status_code == 200 and response.headers["content-type"] == "image/jpeg"
    assert response.headers["x-detections"] == "2"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (1024, 1024, 3)
    plain = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_REDUCED_COLOR_2)
    assert np.abs(image.astype(int) - plain.astype(int)).sum() > 0  # something was drawn


def test_a_camera_change_applies_to_the_next_frame(server: LiveServer, demo_camera: FisheyeCamera,
                                                   frame: tuple[bytes, tuple[float, float]]) -> None:
    data, floor_xy = frame
    record = camera_to_dict(demo_camera) | {"id": "tall", "altitude_m": 2 * demo_camera.altitude_m}
    assert httpx.put(f"{server.url}/v1/cameras/tall", json=record).status_code == 201
    tall = httpx.post(detect_url(server, "tall"), content=data, headers=JPEG).json()
    # Same pixels, twice the height: every floor position doubles.
    np.testing.assert_allclose(tall["detections"][0]["position_m"], 2 * np.array(floor_xy), atol=0.01)
    record["altitude_m"] = demo_camera.altitude_m
    assert httpx.put(f"{server.url}/v1/cameras/tall", json=record).status_code == 200
    again = httpx.post(detect_url(server, "tall"), content=data, headers=JPEG).json()
    np.testing.assert_allclose(again["detections"][0]["position_m"], floor_xy, atol=0.005)


# ----- errors: every one answers {"error": {"code", "message"}}


def error_of(response: httpx.Response, status: int) -> str:
    assert response.status_code == status, response.text
    body = response.json()
    assert set(body) == {"error"} and set(body["error"]) == {"code", "message"} and body["error"]["message"]
    return str(body["error"]["code"])


ErrorCase = Callable[[LiveServer, bytes], httpx.Response]


def post(server: LiveServer, content: bytes | object, headers: dict[str, str] | None = None,
         camera_id: str = "demo", **params: object) -> httpx.Response:
    return httpx.post(detect_url(server, camera_id), content=content,  # type: ignore[arg-type]
                      headers=JPEG if headers is None else headers, params=params)  # type: ignore[arg-type]


BLACK_VGA = encode(np.zeros((480, 640, 3), np.uint8))
HUGE = encode(np.zeros((3100, 3100, 3), np.uint8))  # 9.6 Mpx > max_pixels of the test server
BROKEN_FORM = {"content-type": "multipart/form-data; boundary=y"}


@pytest.mark.parametrize(("status", "code", "call"), [
    (400, "bad_image", lambda s, d: post(s, d[:2] + b"\xff" + bytes(500))),
    (400, "empty_body", lambda s, d: post(s, b"")),
    (400, "bad_multipart", lambda s, d: post(s, b"--x\r\nbroken", BROKEN_FORM)),
    (404, "camera_not_found", lambda s, d: post(s, d, camera_id="nowhere")),
    (404, "not_found", lambda s, d: httpx.get(f"{s.url}/v1/nothing")),
    (413, "payload_too_large", lambda s, d: post(s, bytes(5 * 1024 * 1024))),
    (413, "payload_too_large", lambda s, d: post(s, iter([bytes(1024 * 1024)] * 5))),  # chunked
    (413, "image_too_large", lambda s, d: post(s, HUGE)),
    (415, "unsupported_media_type", lambda s, d: post(s, d, {"content-type": "text/plain"})),
    (415, "unsupported_media_type", lambda s, d: post(s, d, {})),
    (415, "unsupported_image", lambda s, d: post(s, b"GIF89a" + bytes(64))),
    (422, "invalid_request", lambda s, d: post(s, d, min_score=2)),
    (422, "invalid_request", lambda s, d: post(s, d, render="png")),
    (422, "missing_image", lambda s, d: httpx.post(detect_url(s), files={"frame": ("f.jpg", d)})),
    (422, "frame_size_mismatch", lambda s, d: post(s, BLACK_VGA)),
])
def test_error_statuses(server: LiveServer, frame: tuple[bytes, tuple[float, float]], status: int,
                        code: str, call: ErrorCase) -> None:
    assert error_of(call(server, frame[0]), status) == code
    assert server.state.runner.in_flight == 0  # a refused frame gives its in-flight slot back


def test_overload_answers_503_with_retry_after(tmp_path: object, settings_for: Callable[..., Settings],
                                               frame: tuple[bytes, tuple[float, float]]) -> None:
    with LiveServer(settings_for(max_in_flight=1, retry_after_s=2)) as live:
        runner = live.state.runner
        assert runner.try_admit()  # hold the only in-flight slot, as a long frame would
        try:
            busy = httpx.post(detect_url(live), content=frame[0], headers=JPEG)
            assert error_of(busy, 503) == "overloaded" and busy.headers["retry-after"] == "2"
        finally:
            runner.release()
        assert httpx.post(detect_url(live), content=frame[0], headers=JPEG).status_code == 200
        metrics = httpx.get(f"{live.url}/metrics").text
        assert 'fishloc_overload_rejections_total{frontend="rest"} 1.0' in metrics


def test_overload_is_answered_before_the_body_is_read(settings_for: Callable[..., Settings],
                                                     frame: tuple[bytes, tuple[float, float]]) -> None:
    """A frame refused for overload is refused unread: the 503 comes while most of its body has not
    even been sent (reading it first would end in 408 once the body deadline passed), and the
    connection is closed so the rest is not read either."""
    with LiveServer(settings_for(max_in_flight=2, retry_after_s=3, body_timeout_s=5)) as live:
        runner = live.state.runner
        assert runner.try_admit() and runner.try_admit()  # every slot held, as by long frames
        try:
            port = int(live.url.rsplit(":", 1)[1])
            with socket.create_connection(("127.0.0.1", port), timeout=30) as client:  # a bound
                client.sendall(b"POST /v1/cameras/demo/detect HTTP/1.1\r\nhost: x\r\n"
                               b"content-type: image/jpeg\r\ncontent-length: 20000000\r\n\r\n"
                               + frame[0][:100])
                answer = b""
                while chunk := client.recv(65536):  # until the server closes the connection
                    answer += chunk
            head, _, body = answer.partition(b"\r\n\r\n")
            lines = head.decode("latin-1").lower().split("\r\n")
            assert lines[0].startswith("http/1.1 503") and b'"overloaded"' in body
            assert "retry-after: 3" in lines and "connection: close" in lines
            assert runner.in_flight == 2  # nothing taken, nothing given back twice
        finally:
            runner.release()
            runner.release()
        assert httpx.post(detect_url(live), content=frame[0], headers=JPEG).status_code == 200
        assert runner.in_flight == 0


def test_not_ready_answers_503(settings_for: Callable[..., Settings],
                               frame: tuple[bytes, tuple[float, float]]) -> None:
    live = LiveServer(settings_for(), warm_up=False).start(wait_ready=False)
    try:
        assert error_of(httpx.get(f"{live.url}/readyz"), 503) == "not_ready"
        answer = httpx.post(detect_url(live), content=frame[0], headers=JPEG)
        assert error_of(answer, 503) == "not_ready" and answer.headers["retry-after"]
        assert httpx.get(f"{live.url}/healthz").json() == {"status": "ok"}
    finally:
        live.stop()
