"""The reference gateway end to end: a folder and a short video file streamed to a real server,
the cameras of a site on one stream, and reconnecting to a server that comes up late."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer, free_port
from service_sites import MIN_SCORE, POSES, frame_of, put_site_cameras

from fisheye import FisheyeCamera
from service.core.config import Settings
from service.gateway.client import Gateway, GatewayConfig
from service.gateway.frame_sources import FolderSource, SourceFrame, open_source

SPOTS = [(1.0, 0.5), (-1.5, 2.0), (0.3, -2.2), (2.5, 1.0), (-0.8, -0.9)]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, double_model_path: object) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("gateway")
    settings = Settings(model=double_model_path, database=str(folder / "cameras.db"), http_port=0,
                        grpc_port=0, host="127.0.0.1", threads=1)
    with LiveServer(settings) as live:
        yield live


def grpc_target(server: LiveServer) -> str:
    assert server.service is not None
    return f"127.0.0.1:{server.service.grpc_port}"


def gateway_cli(server: LiveServer, source: Path, *extra: str) -> tuple[list[dict[str, Any]], dict[str, int]]:
    done = subprocess.run(
        [sys.executable, "-m", "service.cli", "gateway", "--server", grpc_target(server), "--camera", "demo",
         "--source", str(source), *extra],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    counts = json.loads(done.stderr.strip().splitlines()[-1])
    return lines, counts


def check_positions(lines: list[dict[str, Any]], truth: dict[str, tuple[float, float]]) -> int:
    checked = 0
    for line in lines:
        if line["status"] == "OK" and line["frame_id"] in truth:
            position = line["detections"][0]["position_m"]
            np.testing.assert_allclose(position, truth[line["frame_id"]], atol=0.01)
            checked += 1
    return checked



def gateway_thread(gateway: Gateway) -> tuple[threading.Thread, dict[str, Any]]:
    """A thread (not started) that runs the gateway; `outcome` gets its "counts" or its "error"."""
    outcome: dict[str, Any] = {}

    def run_gateway() -> None:
        try:
            outcome["counts"] = asyncio.run(gateway.run())
        except BaseException as error:  # reported to the test thread
            outcome["error"] = error

    return threading.Thread(target=run_gateway), outcome

def test_gateway_streams_a_folder(server: LiveServer, demo_camera: FisheyeCamera, tmp_path: Path) -> None:
    truth: dict[str, tuple[float, float]] = {}
    for index, spot in enumerate(SPOTS):
        name = f"{index:03d}.{'png' if index == 2 else 'jpg'}"
        frame = person_frame(demo_camera, spot, (1024, 1024), disk_radius_px=20)
        (tmp_path / name).write_bytes(encode(frame.bgr, ".png" if index == 2 else ".jpg"))
        truth[name] = spot
    (tmp_path / "005.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    (tmp_path / "notes.txt").write_text("not an image")
    lines, counts = gateway_cli(server, tmp_path, "--fps", "50")
    assert counts["sent"] == 6 == counts["answered"] + counts["dropped"] and counts["lost"] == 0
    assert [line["frame_id"] for line in lines] == [f"{i:03d}.{'png' if i == 2 else 'jpg'}" for i in range(6)]
    assert all(line["camera_id"] == "demo" for line in lines)
    bad = lines[-1]
    assert bad["status"] in ("ERROR", "DROPPED") and counts["errors"] == (bad["status"] == "ERROR")
    assert check_positions(lines, truth) == counts["answered"] - counts["errors"] >= 1


def test_gateway_streams_a_video_file(server: LiveServer, demo_camera: FisheyeCamera, tmp_path: Path) -> None:
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (512, 512))
    assert writer.isOpened()
    truth: dict[str, tuple[float, float]] = {}
    for index in range(8):
        spot = SPOTS[index % len(SPOTS)]
        writer.write(person_frame(demo_camera, spot, (512, 512), disk_radius_px=12).bgr)
        truth[str(index)] = spot
    writer.release()
    lines, counts = gateway_cli(server, video, "--fps", "0")
    assert counts["sent"] == 8 == counts["answered"] + counts["dropped"] == len(lines)
    assert [line["frame_id"] for line in lines] == [str(i) for i in range(8)]
    assert counts["errors"] == 0 and check_positions(lines, truth) == counts["answered"] >= 1


def test_gateway_reconnects_to_a_server_that_starts_late(settings_for: Callable[..., Settings],
                                                         demo_camera: FisheyeCamera, tmp_path: Path) -> None:
    for index, spot in enumerate(SPOTS[:3]):
        frame = person_frame(demo_camera, spot, (512, 512), disk_radius_px=12)
        (tmp_path / f"{index}.jpg").write_bytes(encode(frame.bgr))
    port = free_port()
    lines: list[str] = []
    config = GatewayConfig(server=f"127.0.0.1:{port}", camera_id="demo", fps=0, max_backoff_s=0.5,
                           max_reconnects=200)
    gateway = Gateway(config, FolderSource(tmp_path), lines.append)
    thread, outcome = gateway_thread(gateway)
    thread.start()
    deadline = time.monotonic() + 30
    while gateway.counts.reconnects < 1 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert gateway.counts.reconnects >= 1  # nothing listens yet
    with LiveServer(settings_for(grpc_port=port)):
        thread.join(60)
    assert "error" not in outcome, outcome.get("error")
    counts = outcome["counts"]
    assert counts.sent == counts.answered + counts.dropped + counts.lost
    assert counts.answered >= 1 and len(lines) == counts.answered + counts.dropped


class PausingFolder(FolderSource):
    """A folder whose frames stop coming after `pause_after` of them, until `resume` is set."""

    def __init__(self, folder: Path, pause_after: int) -> None:
        super().__init__(folder)
        self.pause_after = pause_after
        self.paused = threading.Event()
        self.resume = threading.Event()

    def frames(self) -> Iterator[SourceFrame]:
        for index, frame in enumerate(super().frames()):
            if index == self.pause_after:
                self.paused.set()
                self.resume.wait(60)  # a bound, not an assertion
            yield frame


def _wait_for(condition: Callable[[], bool], timeout_s: float = 30) -> bool:
    deadline = time.monotonic() + timeout_s  # a bound, not an assertion
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.02)
    return condition()


def test_gateway_goes_on_after_the_server_restarts_mid_stream(settings_for: Callable[..., Settings],
                                                              demo_camera: FisheyeCamera,
                                                              tmp_path: Path) -> None:
    for index in range(10):
        frame = person_frame(demo_camera, SPOTS[index % len(SPOTS)], (512, 512), disk_radius_px=12)
        (tmp_path / f"{index:02d}.jpg").write_bytes(encode(frame.bgr))
    port = free_port()
    lines: list[dict[str, Any]] = []
    config = GatewayConfig(server=f"127.0.0.1:{port}", camera_id="demo", fps=0, max_backoff_s=0.5,
                           max_reconnects=200)
    source = PausingFolder(tmp_path, pause_after=4)
    gateway = Gateway(config, source, lambda line: lines.append(json.loads(line)))
    thread, outcome = gateway_thread(gateway)
    first = LiveServer(settings_for(grpc_port=port)).start()
    try:
        thread.start()
        answered = _wait_for(lambda: source.paused.is_set() and len(lines) == 4)
    finally:
        first.stop()  # mid-stream: the gateway's stream is open, its source has more frames
    source.resume.set()
    assert answered and gateway.counts.reconnects == 0
    assert _wait_for(lambda: gateway.counts.reconnects >= 1 or not thread.is_alive())
    with LiveServer(settings_for(grpc_port=port)):  # the same port, the same registry
        thread.join(60)
    assert not thread.is_alive() and "error" not in outcome, outcome.get("error")
    counts = outcome["counts"]
    assert counts.sent == 10 == counts.answered + counts.dropped + counts.lost
    assert counts.reconnects >= 1 and len(lines) == counts.answered + counts.dropped
    before = [line["frame_id"] for line in lines[:4]]
    after = [line["frame_id"] for line in lines[4:] if line["status"] == "OK"]
    assert before == ["00.jpg", "01.jpg", "02.jpg", "03.jpg"] and after  # the new server answered
    assert all(line["frame_id"] >= "04.jpg" for line in lines[4:])


def test_open_source_kinds(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="neither"):
        open_source(str(tmp_path / "missing.mp4"))
    with pytest.raises(ValueError, match="no images"):
        open_source(str(tmp_path))


def test_gateway_streams_the_cameras_of_a_site_on_one_stream(server: LiveServer, demo_camera: FisheyeCamera,
                                                             tmp_path: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=30) as client:
        put_site_cameras(client, demo_camera, site="gateway-site")
    for camera_id in POSES:
        folder = tmp_path / camera_id
        folder.mkdir()
        for index in range(8):  # one person standing where both cameras see them
            (folder / f"{index:03d}.jpg").write_bytes(frame_of(demo_camera, camera_id, (0.0, 0.5)))
    done = subprocess.run(
        [sys.executable, "-m", "service.cli", "gateway", "--server", grpc_target(server),
         "--camera", "cam-a", "--source", str(tmp_path / "cam-a"), "--camera", "cam-b",
         "--source", str(tmp_path / "cam-b"), "--fps", "10", "--min-score", str(MIN_SCORE)],
        capture_output=True, text=True, timeout=120, check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    counts = json.loads(done.stderr.strip().splitlines()[-1])
    assert counts["sent"] == 16 == counts["answered"] + counts["dropped"] and counts["errors"] == 0
    tracked = {(line["camera_id"], line["detections"][0]["track_id"]) for line in lines
               if line["status"] == "OK" and line["detections"][0]["track_id"] is not None}
    assert tracked == {("cam-a", "gateway-site:1"), ("cam-b", "gateway-site:1")}
    assert all("capture_time" in line for line in lines)
    with httpx.Client(base_url=server.url, timeout=30) as client:
        assert client.get("/v1/sites/gateway-site/occupancy").json()["count"] == 1
