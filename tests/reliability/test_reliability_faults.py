"""Faults: the server killed with SIGKILL while the registry is being written, model files that
cannot be served, and readiness while the model warms up."""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from reliability_cases import SCENARIO
from reliability_samples import Samples
from reliability_support import LiveServer, ServeProcess, serve_args

from fisheye import FisheyeCamera, camera_to_dict
from service.core.config import Settings
from service.pipeline import Pipeline

pytest_plugins = ["reliability_fixtures"]

ACKS_BEFORE_KILL = 40
MAX_WRITES = 5000


def test_kill_9_while_writing_keeps_every_acknowledged_camera(double_model_path: Path, tmp_path: Path,
                                                              demo_camera: FisheyeCamera) -> None:
    database = tmp_path / "cameras.db"
    base = camera_to_dict(demo_camera)
    acked: dict[str, float] = {}       # new cameras, one per write: id -> altitude
    replaced: list[float] = []         # altitudes of camera `same` acknowledged, in order
    enough = threading.Event()
    server = ServeProcess(serve_args(double_model_path, database)).start()
    server.wait_ready()

    def writer() -> None:
        with httpx.Client(base_url=server.url, timeout=10) as client:
            for i in range(MAX_WRITES):
                altitude = round(1.0 + i * 0.001, 6)
                try:
                    camera_id = f"c{i}" if i % 2 else "same"
                    record = base | {"id": camera_id, "altitude_m": altitude}
                    answer = client.put(f"/v1/cameras/{camera_id}", json=record)
                except httpx.HTTPError:
                    return  # the server is gone
                assert answer.status_code in (200, 201), answer.text
                if i % 2:
                    acked[f"c{i}"] = altitude
                else:
                    replaced.append(altitude)
                if len(acked) >= ACKS_BEFORE_KILL:
                    enough.set()
        enough.set()

    thread = threading.Thread(target=writer)
    thread.start()
    assert enough.wait(120)
    server.kill()  # SIGKILL while the writer is still sending PUTs
    thread.join(60)
    assert len(acked) >= ACKS_BEFORE_KILL and len(acked) < MAX_WRITES // 2  # killed mid-loop

    with sqlite3.connect(database) as connection:
        assert connection.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    with ServeProcess(serve_args(double_model_path, database)) as again:
        again.wait_ready()
        stored = {c["id"]: c for c in httpx.get(f"{again.url}/v1/cameras").json()["cameras"]}
        for camera_id, altitude in acked.items():
            assert stored[camera_id] == base | {"id": camera_id, "altitude_m": altitude}
        # `same` holds the last acknowledged altitude, or the one whose PUT was cut off by the kill.
        cut_off = round(replaced[-1] + 0.002, 6)
        assert stored["same"]["altitude_m"] in (replaced[-1], cut_off)
        # Beyond the acknowledged ones, at most the one write in flight at the kill was kept.
        extra = set(stored) - set(acked) - {"same", "demo"}
        assert len(extra) <= 1
        frame = Samples(demo_camera).good_jpeg
        detect = httpx.post(f"{again.url}/v1/cameras/c1/detect", content=frame,
                            headers={"content-type": "image/jpeg"})
        assert detect.status_code == SCENARIO["kill_9_registry"].status


def _bad_models(folder: Path, good: Path) -> dict[str, tuple[Path, str]]:
    data = good.read_bytes()
    (folder / "truncated.onnx").write_bytes(data[: len(data) // 2])
    (folder / "empty.onnx").write_bytes(b"")
    (folder / "text.onnx").write_bytes(b"this is not a model\n" * 20)
    (folder / "a-folder.onnx").mkdir()
    return {
        "missing": (folder / "missing.onnx", "does not exist"),
        "truncated": (folder / "truncated.onnx", "not a loadable ONNX model"),
        "empty": (folder / "empty.onnx", "not a loadable ONNX model"),
        "not_onnx": (folder / "text.onnx", "not a loadable ONNX model"),
        "directory": (folder / "a-folder.onnx", "does not exist"),
    }


@pytest.mark.parametrize("kind", ["missing", "truncated", "empty", "not_onnx", "directory"])
def test_a_model_that_cannot_be_served_stops_start_up(double_model_path: Path, tmp_path: Path,
                                                      kind: str) -> None:
    model, message = _bad_models(tmp_path, double_model_path)[kind]
    server = ServeProcess(serve_args(model, tmp_path / "db.sqlite"))
    with pytest.raises(RuntimeError, match="did not start"):
        server.start()
    assert server.stop() == SCENARIO["bad_model"].status
    assert f"cannot load the model: {model}" in server.log or f"model file {model}" in server.log
    assert message in server.log and "Traceback" not in server.log


def test_not_ready_until_the_model_is_warm(settings_for: Callable[..., Settings], demo_camera: FisheyeCamera,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Warm-up held back by a gate (a model as slow to warm as we like): readiness follows it."""
    gate = threading.Event()
    warm_up = Pipeline.warm_up

    def slow_warm_up(self: Pipeline, runs: int = 2) -> None:
        assert gate.wait(60)
        warm_up(self, runs)

    monkeypatch.setattr(Pipeline, "warm_up", slow_warm_up)
    frame = Samples(demo_camera).good_jpeg
    live = LiveServer(settings_for()).start(wait_ready=False)
    try:
        for _ in range(3):
            ready = httpx.get(f"{live.url}/readyz")
            assert ready.status_code == SCENARIO["warm_up"].status and ready.headers["retry-after"]
            assert ready.json()["error"]["code"] == "not_ready"
            detect = httpx.post(f"{live.url}/v1/cameras/demo/detect", content=frame,
                                headers={"content-type": "image/jpeg"})
            assert detect.status_code == 503 and detect.json()["error"]["code"] == "not_ready"
            assert httpx.get(f"{live.url}/healthz").status_code == 200  # alive all along
            assert "fishloc_ready 0.0" in httpx.get(f"{live.url}/metrics").text
        gate.set()
        live.wait_ready()
        assert httpx.post(f"{live.url}/v1/cameras/demo/detect", content=frame,
                          headers={"content-type": "image/jpeg"}).status_code == 200
        assert "fishloc_ready 1.0" in httpx.get(f"{live.url}/metrics").text
    finally:
        gate.set()
        live.stop()
