"""Playing a recorded site sequence: through a running server, an in-process one, or the tracker alone.

`play_through_server` installs the sequence's cameras (camera PUTs with `site` and `site_pose`),
zones and lines, then posts every frame in `capture_time` order to
`/v1/cameras/{id}/detect?capture_time=...` and reads `/v1/sites/{site}/occupancy` after each step:
what a client of `fishloc serve` sees. `LocalServer` runs that server in this process (a real
uvicorn on a free loopback port) for `--model`. `play_ground_truth` feeds the annotated positions
(optionally with Gaussian noise) to the site tracker's in-process API instead of the detector:
what the fusion and tracking alone achieve.
"""

from __future__ import annotations

import asyncio
import http.client
import json
import tempfile
import threading
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from evaluation.sequence_data import Sequence
from evaluation.track_scoring import Reported
from service.core.config import Settings
from service.server import Service, build_state

_READY_WITHIN_S = 300.0  # model load and warm-up


class PlaybackError(RuntimeError):
    """The server refused a request of the playback (its status and answer in the message)."""


class ServerClient:
    """A keep-alive HTTP client of one FishLoc server (`http://host:port`)."""

    def __init__(self, url: str, token: str | None = None, timeout_s: float = 60.0) -> None:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"expected an http(s)://host:port URL, got {url!r}")
        connection = http.client.HTTPSConnection if parts.scheme == "https" else http.client.HTTPConnection
        self._connection = connection(parts.hostname, parts.port, timeout=timeout_s)
        self._prefix = parts.path.rstrip("/")
        self._token = token

    def request(self, method: str, path: str, body: bytes | None = None, content_type: str | None = None,
                allow: tuple[int, ...] = ()) -> tuple[int, Any]:
        headers = {"Accept": "application/json"}
        if content_type is not None:
            headers["Content-Type"] = content_type
        if self._token:
            headers["Authorization"] = f"Bearer {self._token}"
        try:
            self._connection.request(method, self._prefix + path, body=body, headers=headers)
            response = self._connection.getresponse()
        except (http.client.HTTPException, OSError):
            self._connection.close()  # the next request reconnects
            raise
        raw = response.read()
        is_json = response.getheader("Content-Type", "").startswith("application/json")
        answer = json.loads(raw) if raw and is_json else raw
        if response.status >= 400 and response.status not in allow:
            raise PlaybackError(f"{method} {path}: {response.status} {answer!r}"[:500])
        return response.status, answer

    def put_json(self, path: str, document: dict[str, Any]) -> None:
        self.request("PUT", path, json.dumps(document).encode(), "application/json")

    def close(self) -> None:
        self._connection.close()


def _quoted(part: str) -> str:
    return urllib.parse.quote(part, safe="")


def install(client: ServerClient, sequence: Sequence) -> None:
    """Put the sequence's cameras afresh (a site with no camera left is gone, and with it its tracks),
    then its zones and lines."""
    for camera in sequence.cameras:
        client.request("DELETE", f"/v1/cameras/{_quoted(camera['id'])}", allow=(404,))
    for camera in sequence.cameras:
        client.put_json(f"/v1/cameras/{_quoted(camera['id'])}", camera)
    site = f"/v1/sites/{_quoted(sequence.site_id)}"
    for name, body in sequence.zones.items():
        client.put_json(f"{site}/zones/{_quoted(name)}", body)
    for name, body in sequence.lines.items():
        client.put_json(f"{site}/lines/{_quoted(name)}", body)


def play_through_server(client: ServerClient, sequence: Sequence, on_step: Callable[[], None] | None = None,
                        min_score: float | None = None, *,
                        frames_to: Callable[[str], ServerClient] | None = None,
                        read_from: Callable[[int], ServerClient] | None = None) -> Reported:
    """Install the sequence, post its frames step by step (with `min_score`, else the model's
    threshold), read the occupancy after each step. All through `client`, unless `frames_to(camera
    id)` names the server of a camera's frames and `read_from(step index)` the one to read from
    (replicas behind a sites bus)."""
    install(client, sequence)
    occupancy_path = f"/v1/sites/{_quoted(sequence.site_id)}/occupancy"
    reported = Reported()
    _, before = client.request("GET", occupancy_path)
    reported.lines_before = {name: {"in": int(v["in"]), "out": int(v["out"])}
                             for name, v in (before.get("lines") or {}).items()}
    for index, step in enumerate(sequence.steps):
        for frame in step.frames:
            parameters = {"capture_time": repr(step.capture_time), "frame_id": str(index)}
            if min_score is not None:
                parameters["min_score"] = repr(min_score)
            query = urllib.parse.urlencode(parameters)
            sender = client if frames_to is None else frames_to(frame.camera_id)
            _, answer = sender.request("POST", f"/v1/cameras/{_quoted(frame.camera_id)}/detect?{query}",
                                       frame.path.read_bytes(), "image/jpeg")
            reported.detections.append((index, frame.camera_id, [
                (float(d["site_position_m"][0]), float(d["site_position_m"][1]))
                for d in answer["detections"] if d.get("site_position_m") is not None]))
        _, occupancy = (client if read_from is None else read_from(index)).request("GET", occupancy_path)
        reported.add(occupancy)
        if on_step is not None:
            on_step()
    return reported


def play_ground_truth(sequence: Sequence, noise_m: float = 0.0, seed: int = 0,
                      on_step: Callable[[], None] | None = None) -> Reported:
    """Feed every frame's fairly visible annotated people (site positions, plus Gaussian noise of
    `noise_m` per axis) to the site tracker's in-process API, in step order."""
    from sites import CountingLine, SiteLayout, SiteObservation, SiteTracker, TrackerConfig, Zone

    layout = SiteLayout.of(
        zones=[Zone(name, body["polygon_m"]) for name, body in sequence.zones.items()],
        lines=[CountingLine(name, body["from_m"], body["to_m"]) for name, body in sequence.lines.items()])
    tracker = SiteTracker(sequence.site_id, TrackerConfig(), layout)
    rng = np.random.default_rng(seed)
    reported = Reported()
    for step in sequence.steps:
        for frame in step.frames:
            people = [p for p in frame.people if not p.ignore]
            xy = np.array([p.site_xy_m for p in people], dtype=np.float64).reshape(-1, 2)
            if noise_m > 0:
                xy = xy + rng.normal(0.0, noise_m, xy.shape)
            distance = np.array([p.distance_m for p in people], dtype=np.float64)
            tracker.update(SiteObservation.of(frame.camera_id, step.capture_time, xy, distance,
                                              np.ones(len(people))))
        reported.add(tracker.occupancy())
        if on_step is not None:
            on_step()
    return reported


class LocalServer:
    """`fishloc serve` of `model` in this process: REST on a free loopback port, a fresh registry in
    a temporary folder, no gRPC, no demo camera. Use as a context manager; `url` while it runs."""

    def __init__(self, model: Path, threads: int | None = None) -> None:
        self._folder = tempfile.TemporaryDirectory(prefix="fishloc-tracks-")
        database = str(Path(self._folder.name) / "cameras.db")
        values: dict[str, Any] = {"model": model, "host": "127.0.0.1", "http_port": 0, "grpc_port": -1,
                                  "demo_camera": False, "database": database}
        if threads is not None:
            values["threads"] = threads
        self.settings = Settings(**values)
        self._thread = threading.Thread(target=self._run, name="fishloc-tracks-server", daemon=True)
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._service: Service | None = None

    @property
    def url(self) -> str:
        assert self._service is not None
        return f"http://127.0.0.1:{self._service.http_port}"

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as error:  # handed to the thread that started the server
            self._error = error
            self._started.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self._service = Service(build_state(self.settings))
        await self._service.start()
        self._started.set()
        await self._stop.wait()
        await self._service.stop()

    def __enter__(self) -> LocalServer:
        self._thread.start()
        self._started.wait()
        if self._error is not None:
            self._folder.cleanup()
            raise self._error
        client = ServerClient(self.url)
        deadline = time.monotonic() + _READY_WITHIN_S
        try:
            while client.request("GET", "/readyz", allow=(503,))[0] != 200:
                if time.monotonic() > deadline:
                    raise PlaybackError(f"the in-process server was not ready within {_READY_WITHIN_S} s")
                time.sleep(0.05)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        finally:
            client.close()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join()
        self._folder.cleanup()
