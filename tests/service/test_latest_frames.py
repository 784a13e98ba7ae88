"""The latest frame per camera: the bounded store, the runner's hook (any front end), the REST routes,
and the viewer's page and assets as the service serves them."""

from __future__ import annotations

import asyncio
import re
from collections.abc import Callable

import cv2
import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer

from fisheye import FisheyeCamera
from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.http.routes.viewer import ASSETS_DIR
from service.latest import LatestFrames, LatestFramesConfig, sniff_media_type
from service.result import DetectionResult, Detections
from service.runner import build_runner

JPEG = {"content-type": "image/jpeg"}


def result_of(camera_id: str) -> DetectionResult:
    return DetectionResult(camera_id=camera_id, frame_id=None, image_wh=(4, 4), model_name="m",
                           model_version="1", detections=Detections.empty(with_site=False))


# ----- the store


@pytest.mark.parametrize(("data", "media_type"), [
    (b"", "application/octet-stream"),
    (b"\xff\xd8\xff\xe0rest", "image/jpeg"),
    (b"\x89PNG\r\n\x1a\nrest", "image/png"),
    (b"GIF89a", "application/octet-stream"),
])
def test_sniff_media_type(data: bytes, media_type: str) -> None:
    assert sniff_media_type(data) == media_type


def test_one_frame_per_camera_with_growing_sequence() -> None:
    store = LatestFrames()
    first = store.record(b"a" * 10, result_of("one"), "rest")
    second = store.record(b"b" * 7, result_of("two"), "grpc")
    third = store.record(b"c" * 3, result_of("one"), "grpc")
    assert first is not None and second is not None and third is not None
    assert (first.sequence, second.sequence, third.sequence) == (1, 2, 3)
    assert len(store) == 2 and store.total_bytes == 10
    latest = store.get("one")
    assert latest is not None and latest.data == b"ccc" and latest.frontend == "grpc"
    assert store.get("three") is None
    assert store.camera_ids() == ["two", "one"]  # least recently updated first
    assert store.forget("two") and not store.forget("two")
    assert store.camera_ids() == ["one"] and store.total_bytes == 3


def test_least_recently_updated_camera_goes_first_when_full() -> None:
    store = LatestFrames(LatestFramesConfig(max_cameras=2, max_bytes=100))
    for camera_id in ("a", "b", "a", "c"):
        store.record(b"x", result_of(camera_id), "rest")
    assert store.camera_ids() == ["a", "c"]
    store.record(b"y" * 60, result_of("d"), "rest")  # 1 + 60 bytes fit; "a" is evicted for the count
    store.record(b"z" * 50, result_of("e"), "rest")  # 60 + 50 > 100: "d" goes too
    assert store.camera_ids() == ["e"] and store.total_bytes == 50
    assert store.record(b"w" * 101, result_of("f"), "rest") is None  # larger than the whole budget
    assert store.camera_ids() == ["e"]


@pytest.mark.parametrize("config", [{"max_cameras": 0}, {"max_bytes": 0}])
def test_config_refuses_empty_bounds(config: dict[str, int]) -> None:
    with pytest.raises(ValueError, match="positive"):
        LatestFramesConfig(**config)


def test_runner_records_frames_of_any_front_end(settings_for: Callable[..., Settings],
                                                demo_camera: FisheyeCamera) -> None:
    runner = build_runner(settings_for(), ServiceMetrics())
    data = encode(person_frame(demo_camera, (0.5, 1.0), (512, 512), 10).bgr)

    async def run() -> DetectionResult:
        return await runner.detect(data, demo_camera, min_score=None, frame_id="g1", frontend="grpc")

    try:
        result = asyncio.run(run())
    finally:
        runner.close()
    latest = runner.latest.get("demo")
    assert latest is not None and latest.frontend == "grpc"
    assert latest.data is data and latest.result is result


# ----- REST


def test_latest_routes_answer_the_last_frame(live_server: LiveServer, demo_camera: FisheyeCamera) -> None:
    base = f"{live_server.url}/v1/cameras"
    unknown = httpx.get(f"{base}/nobody/latest")
    assert unknown.status_code == 404 and unknown.json()["error"]["code"] == "camera_not_found"
    for path in ("latest", "latest.jpg"):
        none_yet = httpx.get(f"{base}/demo/{path}")
        assert none_yet.status_code == 404 and none_yet.json()["error"]["code"] == "no_frame"

    first = encode(person_frame(demo_camera, (1.0, 1.0), (1024, 1024), 20).bgr)
    answer = httpx.post(f"{base}/demo/detect", content=first, headers=JPEG, params={"frame_id": "f1"}).json()
    latest = httpx.get(f"{base}/demo/latest")
    assert latest.status_code == 200 and latest.headers["cache-control"] == "no-store"
    body = latest.json()
    assert set(body) == {"camera_id", "sequence", "received_at", "frontend", "media_type", "result"}
    assert body["camera_id"] == "demo" and body["frontend"] == "rest" and body["media_type"] == "image/jpeg"
    assert body["result"] == answer
    assert re.match(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d", body["received_at"])
    frame = httpx.get(f"{base}/demo/latest.jpg", params={"sequence": body["sequence"]})
    assert frame.status_code == 200 and frame.headers["content-type"] == "image/jpeg"
    assert frame.content == first and frame.headers["x-frame-sequence"] == str(body["sequence"])

    # A frame the pipeline refuses does not replace the latest one.
    bad = httpx.post(f"{base}/demo/detect", content=b"\xff\xd8\xffnot a jpeg", headers=JPEG)
    assert bad.status_code == 400
    assert httpx.get(f"{base}/demo/latest").json()["sequence"] == body["sequence"]

    truth = person_frame(demo_camera, (-1.0, 0.5), (1024, 1024), 20)
    second = encode(truth.bgr, ".png")
    httpx.post(f"{base}/demo/detect", content=second, headers={"content-type": "image/png"})
    newer = httpx.get(f"{base}/demo/latest").json()
    assert newer["sequence"] > body["sequence"] and newer["media_type"] == "image/png"
    stale = httpx.get(f"{base}/demo/latest.jpg", params={"sequence": body["sequence"]})
    assert stale.status_code == 409 and stale.json()["error"]["code"] == "frame_replaced"
    transcoded = httpx.get(f"{base}/demo/latest.jpg")
    assert transcoded.headers["content-type"] == "image/jpeg"
    image = cv2.imdecode(np.frombuffer(transcoded.content, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == truth.bgr.shape
    assert np.abs(image.astype(int) - truth.bgr.astype(int)).mean() < 2.0


def test_openapi_documents_latest_but_not_the_page(live_server: LiveServer) -> None:
    paths = httpx.get(f"{live_server.url}/openapi.json").json()["paths"]
    assert "get" in paths["/v1/cameras/{camera_id}/latest"]
    jpeg = paths["/v1/cameras/{camera_id}/latest.jpg"]["get"]
    assert "image/jpeg" in jpeg["responses"]["200"]["content"]
    assert {"404", "409"} <= set(jpeg["responses"])
    assert "/" not in paths and not any(path.startswith("/viewer") for path in paths)


# ----- the page and its assets


def test_page_and_assets_are_served_from_the_package(live_server: LiveServer) -> None:
    page = httpx.get(f"{live_server.url}/")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert "default-src 'self'" in page.headers["content-security-policy"]
    names = sorted(path.name for path in ASSETS_DIR.iterdir() if path.suffix in (".js", ".css"))
    assert {"viewer.js", "viewer.css", "geometry.js"} <= set(names)
    for name in names:
        asset = httpx.get(f"{live_server.url}/viewer/{name}")
        assert asset.status_code == 200, name
        expected = "text/javascript" if name.endswith(".js") else "text/css"
        assert asset.headers["content-type"].startswith(expected)
        # Modules import only sibling modules: nothing from another origin, no build step.
        for target in re.findall(r'from\s+"([^"]+)"', asset.text):
            assert target.startswith("./") and target[2:] in names, (name, target)
    # Everything the page loads is on this service (or inline data).
    for target in re.findall(r'(?:src|href)="([^"]+)"', page.text):
        assert target.startswith(("/", "#", "data:")), target
        if target.startswith("/viewer/"):
            assert httpx.get(f"{live_server.url}{target}").status_code == 200


@pytest.mark.parametrize("name", ["nothing.js", "viewer.py", "..%2Fapp.py", "index.html"])
def test_unknown_assets_are_not_found(live_server: LiveServer, name: str) -> None:
    response = httpx.get(f"{live_server.url}/viewer/{name}")
    assert response.status_code == 404
    assert response.json()["error"]["code"] == "not_found"
