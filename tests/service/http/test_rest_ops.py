"""Health, model info, metrics, request ids, OpenAPI, and `fishloc serve` start-up failures."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer, free_port, wait_until_ready

from fisheye import FisheyeCamera

JPEG = {"content-type": "image/jpeg"}


def test_health_and_model(live_server: LiveServer) -> None:
    assert httpx.get(f"{live_server.url}/healthz").json() == {"status": "ok"}
    ready = httpx.get(f"{live_server.url}/readyz").json()
    assert ready["status"] == "ready"
    assert ready["outputs"]["history"] == {"ok": True} and ready["outputs"]["webhooks"] == {"ok": True}
    model = httpx.get(f"{live_server.url}/v1/model").json()
    assert model["name"] == "plumbing-double" and model["version"] == "0.0-test"
    assert model["input_size"] == 256 and model["trained_on"] == "nothing (test double)"
    assert len(model["sha256"]) == 64


def test_request_id_is_echoed_or_made(live_server: LiveServer) -> None:
    given = httpx.get(f"{live_server.url}/healthz", headers={"X-Request-ID": "abc-123"})
    assert given.headers["x-request-id"] == "abc-123"
    made = httpx.get(f"{live_server.url}/healthz", headers={"X-Request-ID": "bad id with spaces"})
    assert made.headers["x-request-id"] != "bad id with spaces" and len(made.headers["x-request-id"]) == 32


def test_metrics_count_requests_stages_frames_and_detections(live_server: LiveServer,
                                                            demo_camera: FisheyeCamera) -> None:
    truth = person_frame(demo_camera, (1.0, 1.0), (1024, 1024), disk_radius_px=20)
    url = f"{live_server.url}/v1/cameras/demo/detect"
    for _ in range(2):
        assert httpx.post(url, content=encode(truth.bgr), headers=JPEG).status_code == 200
    httpx.post(f"{live_server.url}/v1/cameras/zzz/detect", content=b"x", headers=JPEG)
    response = httpx.get(f"{live_server.url}/metrics")
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/plain")
    text = response.text
    route = "/v1/cameras/{camera_id}/detect"
    assert f'fishloc_http_requests_total{{method="POST",route="{route}",status="200"}} 2.0' in text
    assert f'fishloc_http_requests_total{{method="POST",route="{route}",status="404"}} 1.0' in text
    assert 'fishloc_frames_total{camera_id="demo",frontend="rest"} 2.0' in text
    assert 'fishloc_detections_total{camera_id="demo"} 4.0' in text  # the person and box A, twice
    for stage in ("decode", "preprocess", "inference", "postprocess", "total"):
        assert f'fishloc_stage_seconds_count{{stage="{stage}"}} 2.0' in text
    assert "fishloc_ready 1.0" in text
    assert 'fishloc_model_info{input_size="256",name="plumbing-double",version="0.0-test"} 1.0' in text


def test_openapi_documents_the_behaviour(live_server: LiveServer) -> None:
    spec = httpx.get(f"{live_server.url}/openapi.json").json()
    paths = spec["paths"]
    assert {"/healthz", "/readyz", "/v1/model", "/v1/cameras", "/v1/cameras/{camera_id}",
            "/v1/cameras/{camera_id}/detect", "/metrics"} <= set(paths)
    assert {"get", "put", "delete"} <= set(paths["/v1/cameras/{camera_id}"])
    detect = paths["/v1/cameras/{camera_id}/detect"]["post"]
    assert set(detect["requestBody"]["content"]) == {
        "image/jpeg", "image/png", "application/octet-stream", "multipart/form-data",
    }
    assert {"200", "400", "404", "413", "415", "422", "503"} <= set(detect["responses"])
    assert set(detect["responses"]["200"]["content"]) == {"application/json", "image/jpeg"}
    assert {p["name"] for p in detect["parameters"]} == {"camera_id", "min_score", "frame_id", "render",
                                                        "capture_time"}
    error = spec["components"]["schemas"]["ErrorResponse"]
    assert error["properties"]["error"]["$ref"].endswith("/ErrorBody")
    assert "FisheyeCamera" in spec["components"]["schemas"]


def _serve(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "service.cli", "serve", *args], capture_output=True,
                          text=True, timeout=60, check=False)


def test_serve_refuses_a_missing_or_corrupt_model(tmp_path: Path) -> None:
    missing = _serve("--model", str(tmp_path / "nope.onnx"), "--database", str(tmp_path / "db.sqlite"))
    assert missing.returncode == 2
    assert "cannot load the model" in missing.stderr and "does not exist" in missing.stderr
    corrupt = tmp_path / "corrupt.onnx"
    corrupt.write_bytes(b"this is not a model" * 10)
    failed = _serve("--model", str(corrupt), "--database", str(tmp_path / "db.sqlite"))
    assert failed.returncode == 2 and "not a loadable ONNX model" in failed.stderr


def test_model_without_the_contract_is_refused(tmp_path: Path) -> None:
    import onnx
    from service_doubles import build_double_model

    from contract import ModelError, OnnxModel, SessionThreads

    cases = {
        "no_metadata.onnx": build_double_model(metadata={}),
        "float_input.onnx": build_double_model(input_dtype=onnx.TensorProto.FLOAT),
        "wrong_size.onnx": build_double_model(metadata={"fishloc.input_size": "320"}),
    }
    for name, model in cases.items():
        onnx.save(model, str(tmp_path / name))
        with pytest.raises(ModelError, match=name):
            OnnxModel(tmp_path / name, SessionThreads(1))


def test_fishloc_serve_end_to_end(tmp_path: Path, double_model_path: Path,
                                  demo_camera: FisheyeCamera) -> None:
    """`fishloc serve` as users run it: start, answer a frame, stop on SIGTERM with exit code 0."""
    import signal

    http_port, grpc_port = free_port(), free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "serve", "--model", str(double_model_path), "--http-port",
         str(http_port), "--grpc-port", str(grpc_port), "--database", str(tmp_path / "cameras.db")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        url = f"http://127.0.0.1:{http_port}"
        wait_until_ready(url, process)
        truth = person_frame(demo_camera, (0.9, -1.3), (1024, 1024), disk_radius_px=20)
        answer = httpx.post(f"{url}/v1/cameras/demo/detect", content=encode(truth.bgr), headers=JPEG)
        assert answer.status_code == 200
        assert answer.json()["detections"][0]["position_m"] == pytest.approx([0.9, -1.3], abs=0.005)
    finally:
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr
    assert '"message": "stopped"' in stderr and "POST /v1/cameras/demo/detect 200" in stderr


def test_pipeline_log_lines_carry_the_request_id(tmp_path: Path, double_model_path: Path,
                                                 demo_camera: FisheyeCamera) -> None:
    """The pipeline runs in a worker thread; its log lines still name the request they serve."""
    import json
    import os
    import signal

    http_port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "serve", "--model", str(double_model_path), "--http-port",
         str(http_port), "--grpc-port", "-1", "--database", str(tmp_path / "cameras.db")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env=os.environ | {"FISHLOC_LOG_LEVEL": "debug", "FISHLOC_LOG_JSON": "true"},
    )
    try:
        url = f"http://127.0.0.1:{http_port}"
        wait_until_ready(url, process)
        truth = person_frame(demo_camera, (0.9, -1.3), (1024, 1024), disk_radius_px=20)
        answer = httpx.post(f"{url}/v1/cameras/demo/detect", content=encode(truth.bgr),
                            headers=JPEG | {"X-Request-ID": "trace-7"}, params={"frame_id": "f-7"})
        assert answer.status_code == 200
    finally:
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=60)
    lines = [json.loads(line) for line in stderr.splitlines() if line.startswith("{")]
    frame_lines = [line for line in lines if line["logger"] == "service.pipeline"]
    assert [(line["frame_id"], line.get("request_id")) for line in frame_lines] == [("f-7", "trace-7")]
    access = [line for line in lines if line["logger"] == "fishloc.access" and line["method"] == "POST"]
    assert [line["request_id"] for line in access] == ["trace-7"]
