"""The camera registry on a real PostgreSQL server, as replicas share it (FISHLOC_DATABASE_URL).

In-process: two registries on one database see each other's writes on the next read, deletes and
re-creations included. Across processes: two real `fishloc serve` processes on the same database;
a camera changed through one is served by the other within a few seconds, detections included.
"""

from __future__ import annotations

import importlib.util
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import cv2
import httpx
import numpy as np
import pytest

from fisheye import camera_from_dict, camera_to_dict, load_camera
from models import DEMO_CAMERA_PATH
from service.cameras import CameraRegistry

ROOT = Path(__file__).resolve().parents[2]
CHANGE_DEADLINE_S = 5.0  # "within a few seconds"; the registry reads per frame, so it is the next one


def _camera(camera_id: str, altitude_m: float) -> dict[str, Any]:
    record = camera_to_dict(load_camera(DEMO_CAMERA_PATH))
    return {**record, "id": camera_id, "altitude_m": altitude_m}


@pytest.fixture
def registries(postgres_url: str) -> Iterator[tuple[CameraRegistry, CameraRegistry]]:
    first, second = CameraRegistry(postgres_url), CameraRegistry(postgres_url)
    yield first, second
    first.close()
    second.close()


def test_registry_runs_on_postgresql(registries: tuple[CameraRegistry, CameraRegistry]) -> None:
    registry, _ = registries
    assert registry.url.startswith("postgresql+psycopg://")
    assert registry.ids() == []
    outcome = registry.put(camera_from_dict(_camera("lobby-1", 3.2)))
    assert outcome.created
    assert not registry.put(camera_from_dict(_camera("lobby-1", 3.4))).created
    stored = registry.get("lobby-1")
    assert stored is not None and stored.altitude_m == pytest.approx(3.4)
    assert [camera.id for camera in registry.all()] == ["lobby-1"]
    assert registry.delete("lobby-1")
    assert not registry.delete("lobby-1")
    assert registry.get("lobby-1") is None


def test_a_write_through_one_registry_is_read_by_the_other(
    registries: tuple[CameraRegistry, CameraRegistry],
) -> None:
    writer, reader = registries
    writer.put(camera_from_dict(_camera("gate", 3.0)))
    assert reader.get("gate") is not None and reader.get("gate").altitude_m == pytest.approx(3.0)  # type: ignore[union-attr]
    writer.put(camera_from_dict(_camera("gate", 4.5)))
    assert reader.get("gate").altitude_m == pytest.approx(4.5)  # type: ignore[union-attr]
    writer.delete("gate")
    assert reader.get("gate") is None
    assert reader.ids() == []


def test_a_camera_deleted_and_made_again_is_not_served_stale(
    registries: tuple[CameraRegistry, CameraRegistry],
) -> None:
    writer, reader = registries
    writer.put(camera_from_dict(_camera("dock", 3.0)))
    assert reader.get("dock").altitude_m == pytest.approx(3.0)  # type: ignore[union-attr]  # now cached
    writer.delete("dock")
    writer.put(camera_from_dict(_camera("dock", 5.0)))  # a new row, its history starts again
    assert reader.get("dock").altitude_m == pytest.approx(5.0)  # type: ignore[union-attr]


def _open_registry(url: str, barrier: threading.Barrier, failures: list[BaseException]) -> None:
    barrier.wait()
    try:
        registry = CameraRegistry(url)
        registry.seed_once("seeded:demo", DEMO_CAMERA_PATH)
        registry.close()
    except Exception as error:  # reported by the test, with the others
        failures.append(error)


def test_replicas_starting_together_on_a_new_database_all_open_it(postgres_server: Any) -> None:
    # Every replica of a rollout creates the schema at start; all of them must come up.
    for round_number in range(5):
        url = postgres_server.create_database(f"fishloc_race_{round_number}")
        barrier = threading.Barrier(4)
        failures: list[BaseException] = []
        threads = [threading.Thread(target=_open_registry, args=(url, barrier, failures)) for _ in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert not failures, f"round {round_number}: {failures}"
        check = CameraRegistry(url)
        assert check.ids() == ["demo"]
        check.close()


def test_demo_camera_is_seeded_once_per_database(postgres_url: str) -> None:
    first, second = CameraRegistry(postgres_url), CameraRegistry(postgres_url)
    try:
        assert first.seed_once("seeded:demo", DEMO_CAMERA_PATH)
        assert not second.seed_once("seeded:demo", DEMO_CAMERA_PATH)
        first.delete("demo")
        assert not second.seed_once("seeded:demo", DEMO_CAMERA_PATH)  # a deleted demo stays deleted
        assert second.get("demo") is None
    finally:
        first.close()
        second.close()


# ----- two real `fishloc serve` processes sharing one database


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _service_doubles() -> ModuleType:
    """The service tests' ONNX test double (a graph whose detections are known by construction)."""
    path = ROOT / "tests" / "service" / "service_doubles.py"
    spec = importlib.util.spec_from_file_location("fishloc_service_doubles", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def double_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    onnx = pytest.importorskip("onnx", reason="the test-double model is written with onnx (train extra)")
    path = tmp_path_factory.mktemp("model") / "double.onnx"
    onnx.save(_service_doubles().build_double_model(), str(path))
    return path


class ServeProcess:
    """`python -m service.cli serve` on a free loopback port, configured by FISHLOC_* variables."""

    def __init__(self, database_url: str, model: Path, log: Path) -> None:
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = log
        env = {
            **os.environ,
            "FISHLOC_DATABASE_URL": database_url,
            "FISHLOC_MODEL": str(model),
            "FISHLOC_HOST": "127.0.0.1",
            "FISHLOC_HTTP_PORT": str(self.port),
            "FISHLOC_GRPC_PORT": "-1",
            "FISHLOC_THREADS": "1",
            "FISHLOC_LOG_JSON": "false",
        }
        with log.open("wb") as sink:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "service.cli", "serve"], cwd=ROOT, env=env,
                stdout=sink, stderr=subprocess.STDOUT,
            )

    def wait_ready(self, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"fishloc serve exited {self.process.returncode}:\n{self.log.read_text()}")
            try:
                if httpx.get(f"{self.url}/readyz", timeout=2).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        raise TimeoutError(f"fishloc serve not ready in {timeout_s} s:\n{self.log.read_text()}")

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()


@pytest.fixture
def two_services(postgres_url: str, double_model: Path, tmp_path: Path) -> Iterator[tuple[str, str]]:
    # Started together, as replicas of a rollout are: both create the schema and seed the demo camera.
    services = [ServeProcess(postgres_url, double_model, tmp_path / f"serve-{n}.log") for n in (1, 2)]
    try:
        for service in services:
            service.wait_ready()
        yield services[0].url, services[1].url
    finally:
        for service in services:
            service.stop()


def _frame_with_person() -> bytes:
    """A 1024x1024 frame of the demo camera with one bright blob (what the double detects)."""
    frame = np.zeros((1024, 1024, 3), np.uint8)
    cv2.circle(frame, (700, 360), 24, (255, 255, 255), thickness=-1)
    ok, encoded = cv2.imencode(".png", frame)
    assert ok
    return encoded.tobytes()


def _position(base: str, camera_id: str, frame: bytes) -> list[float]:
    answer = httpx.post(f"{base}/v1/cameras/{camera_id}/detect", content=frame,
                        headers={"Content-Type": "image/png"}, timeout=30)
    assert answer.status_code == 200, answer.text
    best = max(answer.json()["detections"], key=lambda detection: detection["score"])
    return list(best["position_m"])


def _eventually(check: Any, deadline_s: float = CHANGE_DEADLINE_S) -> Any:
    """The first truthy value of `check()` within the deadline (the last value otherwise)."""
    deadline = time.monotonic() + deadline_s
    while True:
        value = check()
        if value or time.monotonic() > deadline:
            return value
        time.sleep(0.1)


def test_two_services_share_the_registry(two_services: tuple[str, str]) -> None:
    first, second = two_services
    assert [c["id"] for c in httpx.get(f"{second}/v1/cameras").json()["cameras"]] == ["demo"]

    created = httpx.put(f"{first}/v1/cameras/lobby", json=_camera("lobby", 3.0), timeout=10)
    assert created.status_code in (200, 201), created.text
    listed = _eventually(
        lambda: "lobby" in {c["id"] for c in httpx.get(f"{second}/v1/cameras").json()["cameras"]}
    )
    assert listed, "a camera added through one service is not listed by the other"


def test_a_recalibration_through_one_service_moves_detections_on_the_other(
    two_services: tuple[str, str],
) -> None:
    first, second = two_services
    frame = _frame_with_person()
    before = _position(second, "demo", frame)

    doubled = {**_camera("demo", 2 * 3.2)}
    assert httpx.put(f"{first}/v1/cameras/demo", json=doubled, timeout=10).status_code == 200
    # Floor positions scale with the lens height: twice as high, twice as far from the nadir
    # (to the answer's rounding).
    expected = [2 * value for value in before]
    after = _eventually(lambda: np.allclose(_position(second, "demo", frame), expected, rtol=0, atol=2e-3))
    assert after, f"the other service still places the person at {_position(second, 'demo', frame)}"

    assert httpx.delete(f"{first}/v1/cameras/demo", timeout=10).status_code == 204
    gone = _eventually(lambda: httpx.get(f"{second}/v1/cameras/demo").status_code == 404)
    assert gone, "a camera deleted through one service is still served by the other"
