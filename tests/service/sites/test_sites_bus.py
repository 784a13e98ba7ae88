"""Sites across replicas, for real: redis-server, `fishloc serve --sites-bus` replicas and `fishloc
sites` workers as processes on loopback ports, a rendered two-camera sequence played through them.

The figures (MOTA, IDF1, duplicates, line counts) and the reported tracks of every step equal the
one-process run of the same frames, though each camera's frames go to another replica, the occupancy
is read from either, and the worker tracking the site is killed with SIGKILL halfway. Redis stopped
for 10 s: detection answers every frame, site reads answer 503, and the site resumes after.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import grpc
import httpx
import pytest
from bus_processes import (
    FishlocProcess,
    RedisProcess,
    Replica,
    Worker,
    lease_owners,
    wait_for_leases,
)
from service_processes import REPO_ROOT
from service_sites import SITE, put_site_cameras, walk
from site_sequences import render_sequence, shipped_model_server
from test_site_events import _sse_events

from evaluation.sequence_data import Sequence, read_sequence
from evaluation.track_playback import ServerClient, install, play_through_server
from evaluation.track_scoring import Reported, score_sequence
from fisheye import FisheyeCamera
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.sites import bus

STEPS = 24
TRACKED = ("mota", "idf1")


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Sequence:
    return read_sequence(render_sequence(tmp_path_factory.mktemp("bus-sequence"), STEPS, seed=26))


@pytest.fixture(scope="module")
def one_process(sequence: Sequence, tmp_path_factory: pytest.TempPathFactory) -> Reported:
    """The sequence through one `fishloc serve` with no bus: the figures to match."""
    with shipped_model_server(tmp_path_factory.mktemp("bus-one-process")) as live:
        client = ServerClient(live.url)
        try:
            return play_through_server(client, sequence)
        finally:
            client.close()


@pytest.fixture
def redis_server(tmp_path: Path) -> Iterator[RedisProcess]:
    folder = tmp_path / "redis"
    folder.mkdir()
    with RedisProcess(folder) as server:
        yield server


def _people_ids(reported: Reported) -> list[list[str]]:
    return [sorted(people) for people in reported.people]


def _metric(url: str, name: str) -> float:
    total = 0.0
    for line in httpx.get(f"{url}/metrics").text.splitlines():
        if line.startswith(name) and not line.startswith("#"):
            total += float(line.rsplit(" ", 1)[1])
    return total


def test_two_replicas_and_two_workers_track_as_one_process_through_a_kill(
        sequence: Sequence, one_process: Reported, redis_server: RedisProcess, tmp_path: Path) -> None:
    database = tmp_path / "registry.db"
    workers = [Worker(redis_server.url, database) for _ in range(2)]
    # A long wait: every detect call answers with its track ids, across the takeover too.
    replicas = [Replica(redis_server.url, database, wait_s=10) for _ in range(2)]
    clients: list[ServerClient] = []
    redis = redis_server.client()
    try:
        for process in [*workers, *replicas]:
            process.start()
        clients = [ServerClient(replica.url) for replica in replicas]
        wait_for_leases(redis, workers=2)
        cameras = sorted(camera["id"] for camera in sequence.cameras)
        partition = bus.partition_of(sequence.site_id)
        killed: list[Worker] = []

        def kill_the_site_worker_halfway() -> None:
            if len(killed) == 0 and len(reported_steps) == STEPS // 2:
                owner = lease_owners(redis)[partition]
                victim = next(worker for worker in workers if worker.worker_id == owner)
                victim.kill()
                killed.append(victim)
            reported_steps.append(None)

        reported_steps: list[None] = []
        reported = play_through_server(
            clients[0], sequence, on_step=kill_the_site_worker_halfway,
            frames_to=lambda camera_id: clients[cameras.index(camera_id)],
            read_from=lambda index: clients[index % 2])
        survivor = next(worker for worker in workers if worker not in killed)
        assert killed and lease_owners(redis) == [survivor.worker_id] * bus.PARTITIONS
        assert f"partition {partition} taken over" in survivor.log
        # The same tracks at every step, the same ids before and after the kill: nothing lost, no
        # id changed, no crossing counted twice.
        assert _people_ids(reported) == _people_ids(one_process)
        figures, expected = score_sequence(sequence, reported), score_sequence(sequence, one_process)
        for name in TRACKED:
            assert figures[name] == pytest.approx(expected[name], abs=0.01)
        assert figures["duplicates"] == expected["duplicates"]
        assert reported.lines_after == one_process.lines_after
        assert figures["lines"] == expected["lines"]
        assert sum(v["in"] + v["out"] for v in reported.lines_after.values()) >= 1
        # Either replica reads the same site.
        path = f"/v1/sites/{sequence.site_id}/occupancy"
        occupancy = [client.request("GET", path)[1] for client in clients]
        assert occupancy[0] == occupancy[1] and occupancy[0]["time"] == sequence.steps[-1].capture_time
    finally:
        for client in clients:
            client.close()
        for process in [*replicas, *workers]:
            if process.process is not None and process.process.poll() is None:
                process.stop()
        redis.close()


def _detect(client: httpx.Client, sequence: Sequence, index: int) -> list[dict[str, Any]]:
    answers = []
    for frame in sequence.steps[index].frames:
        response = client.post(f"/v1/cameras/{frame.camera_id}/detect",
                               params={"capture_time": repr(sequence.steps[index].capture_time)},
                               content=frame.path.read_bytes(), headers={"Content-Type": "image/jpeg"})
        assert response.status_code == 200, response.text
        answers.append(response.json())
    return answers


def _detect_grpc(port: int, sequence: Sequence, index: int, later_s: float = 0.0) -> list[pb.DetectResponse]:
    """The frames of step `index`, taken `later_s` after it, through the replica's unary Detect."""
    step = sequence.steps[index]
    with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
        stub = pb_grpc.LocalizerStub(channel)
        requests = []
        for frame in step.frames:
            request = pb.DetectRequest(camera_id=frame.camera_id, image=frame.path.read_bytes())
            request.capture_time.FromNanoseconds(round((step.capture_time + later_s) * 1e9))
            requests.append(request)
        return [stub.Detect(request, timeout=30) for request in requests]


def test_detection_answers_while_redis_is_down_and_the_site_resumes(
        sequence: Sequence, redis_server: RedisProcess, tmp_path: Path) -> None:
    database = tmp_path / "registry.db"
    worker = Worker(redis_server.url, database)
    replica = Replica(redis_server.url, database, wait_s=5, grpc=True)
    site = f"/v1/sites/{sequence.site_id}"
    try:
        worker.start()
        replica.start()
        with httpx.Client(base_url=replica.url, timeout=30) as client:
            wait_for_leases(redis_server.client(), workers=1)
            installer = ServerClient(replica.url)
            install(installer, sequence)
            installer.close()
            third = STEPS // 3
            for index in range(third):
                answers = _detect(client, sequence, index)
            assert any(d["track_id"] for a in answers for d in a["detections"])
            redis_server.stop()
            stopped_at = time.monotonic()
            index = third
            # Frames keep coming for 10 s: every one answered, with positions and no track ids.
            while time.monotonic() - stopped_at < 10 or index < 2 * third:
                for answer in _detect(client, sequence, min(index, 2 * third - 1)):
                    assert answer["site_note"] == "not tracked: the sites bus is unreachable"
                    assert answer["detections"] and all(d["track_id"] is None for d in answer["detections"])
                    assert all(d["site_position_m"] is not None for d in answer["detections"])
                index += 1
            # gRPC answers say so too.
            for response in _detect_grpc(replica.grpc_port, sequence, 2 * third - 1):
                assert response.status == pb.DetectResponse.Status.OK and response.detections
                assert response.site_note == "not tracked: the sites bus is unreachable"
                assert not any(detection.HasField("track_id") for detection in response.detections)
            down = client.get(f"{site}/occupancy")
            assert down.status_code == 503 and down.json()["error"]["code"] == "sites_unavailable"
            assert "unreachable" in down.json()["error"]["message"]
            ready = client.get("/readyz")
            assert ready.status_code == 200 and ready.json()["sites_bus"].startswith("unreachable")
            assert _metric(replica.url, "fishloc_site_observations_undelivered_total") >= 2 * third
            redis_server.start()
            deadline = time.monotonic() + 60
            while client.get("/readyz").json()["sites_bus"] != "ok":
                assert time.monotonic() < deadline, "the replica did not find Redis again"
                time.sleep(0.2)
            # The site resumes: frames tracked again, the occupancy at the newest frame.
            for index in range(2 * third, STEPS):
                answers = _detect(client, sequence, index)
            assert all("site_note" not in answer for answer in answers)
            assert any(d["track_id"] for a in answers for d in a["detections"])
            occupancy = client.get(f"{site}/occupancy")
            assert occupancy.status_code == 200
            assert occupancy.json()["time"] == sequence.steps[-1].capture_time
            assert occupancy.json()["count"] > 0
            # And over gRPC, the last frames again half a second later: tracked, no note.
            tracked = _detect_grpc(replica.grpc_port, sequence, STEPS - 1, later_s=0.5)
            assert all(response.site_note == "" for response in tracked)
            assert any(item.HasField("track_id") for response in tracked for item in response.detections)
    finally:
        for process in (replica, worker):
            if process.process is not None:
                process.stop()


@pytest.mark.parametrize(("url", "said"), [("http://127.0.0.1:1/0", "must be a redis://"),
                                         ("redis://127.0.0.1:1/0", "does not answer")])
@pytest.mark.parametrize("role", [Replica, Worker])
def test_a_bad_or_unreachable_bus_is_a_one_line_error(role: type[FishlocProcess], url: str, said: str,
                                                      tmp_path: Path) -> None:
    process = (Replica(url, tmp_path / "registry.db", wait_s=1) if role is Replica
               else Worker(url, tmp_path / "registry.db"))
    done = subprocess.run([sys.executable, "-m", "service.cli", *process.args], capture_output=True,
                          text=True, timeout=120, env={**os.environ, **process.env}, cwd=REPO_ROOT)
    assert done.returncode == 2, done.stderr[-2000:]
    errors = [line for line in done.stderr.splitlines() if line.startswith("fishloc ")]
    assert len(errors) == 1 and said in errors[0], done.stderr[-2000:]


def test_writes_through_one_replica_reach_the_other_and_the_workers(
        redis_server: RedisProcess, double_model_path: Path, demo_camera: FisheyeCamera,
        tmp_path: Path) -> None:
    """Cameras, zones and lines written through one replica rule what the other replica's frames do;
    an event stream on the other replica hears every update and the site's end."""
    database = tmp_path / "registry.db"
    worker = Worker(redis_server.url, database)
    replicas = [Replica(redis_server.url, database, wait_s=5, model=double_model_path) for _ in range(2)]
    try:
        for process in [worker, *replicas]:
            process.start()
        with httpx.Client(base_url=replicas[0].url, timeout=30) as writer, \
                httpx.Client(base_url=replicas[1].url, timeout=30) as other:
            wait_for_leases(redis_server.client(), workers=1)
            put_site_cameras(writer, demo_camera)
            events: list[tuple[str, dict[str, Any]]] = []
            connected = threading.Event()
            reader = threading.Thread(target=_sse_events, args=(f"{replicas[1].url}/v1/sites/{SITE}/events",
                                                                events, connected), daemon=True)
            reader.start()
            assert connected.wait(30)
            assert other.put(f"/v1/sites/{SITE}/zones/west", json={
                "polygon_m": [[-5, -5], [0, -5], [0, 5], [-5, 5]]}).status_code in (200, 201)
            assert other.put(f"/v1/sites/{SITE}/lines/door",
                             json={"from_m": [0, -3], "to_m": [0, 3]}).status_code in (200, 201)
            ids = walk(writer, demo_camera, start=(-1.5, 0.0), velocity=(1.0, 0.0), steps=15)
            assert ids[-1] is not None and len({i for i in ids if i is not None}) == 1
            occupancy = other.get(f"/v1/sites/{SITE}/occupancy").json()  # crossed from the line's left
            assert occupancy["count"] == 1 and set(occupancy["zones"]) == {"west"}
            assert occupancy["lines"]["door"] == {"in": 1, "out": 0}
            for camera_id in ("cam-a", "cam-b"):  # the site loses its cameras: it ends
                assert writer.delete(f"/v1/cameras/{camera_id}").status_code == 204
            reader.join(30)
            assert not reader.is_alive() and events[-1] == ("end", {"site": SITE})
            updates = [data for name, data in events if name == "occupancy"]
            assert len(updates) >= 15 and updates[-1]["lines"]["door"] == {"in": 1, "out": 0}
            assert other.get(f"/v1/sites/{SITE}/occupancy").status_code == 404
    finally:
        for process in [*replicas, worker]:
            if process.process is not None:
                process.stop()
