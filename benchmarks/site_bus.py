"""What the sites bus costs and carries: a `fishloc sites` worker's throughput, and the latency it adds.

    python -m benchmarks.site_bus [--sites 8] [--seconds 30] [--frames 100] [--json OUT]

Everything runs for real on loopback: a `redis-server` of its own, a `fishloc sites` worker and two
`fishloc serve` processes of the shipped model (one thread each), one with `--sites-bus`, one without.

1. Worker throughput: `--sites` sites of 4 cameras and 20 walkers each (`benchmarks.site_fusion`'s
   scene, 10 fps) are published to the partition streams as fast as a pipeline can, while the worker
   reads; observations/s is what it applied from the first entry sent until every site's published
   occupancy stands at its last frame (the worker is the bottleneck: publishing is many times
   faster), with the worker's own CPU time beside it.
2. Added detect latency: the same sample frame of a site's camera is posted `--frames` times to each
   server, alternately (so both see the same machine), and timed at the client: p50/p95 with the
   bus against without, and the difference. A bus answer waits for the worker's track ids.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import redis

from benchmarks.checkout import checkout_env, source_root
from benchmarks.redis_process import RedisProcess
from benchmarks.server_process import ServerProcess, free_port
from benchmarks.site_fusion import Scene, observations
from benchmarks.stats import summarize
from fisheye import FisheyeCamera, camera_to_dict, load_camera
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH
from service.sites import bus
from sites.snapshot import observation_to_json

SAMPLE_FRAME = Path(__file__).resolve().parent.parent / "samples" / "000001.jpg"
SITE = "bench"


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process so far (/proc/PID/stat)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _caught_up(client: redis.Redis, last_time: dict[str, float]) -> bool:
    """Whether the published occupancy of every site stands at its last frame."""
    published = client.hmget(bus.OCCUPANCY, list(last_time))
    return all(raw is not None and json.loads(raw)["time"] == last_time[site]
               for site, raw in zip(last_time, published, strict=True))


def _wait_for_leases(client: redis.Redis, timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while None in client.mget([bus.lease_key(p) for p in range(bus.PARTITIONS)]):
        if time.monotonic() > deadline:
            raise TimeoutError("the worker did not take the partitions")
        time.sleep(0.1)


class WorkerProcess:
    """`fishloc sites --bus URL` with its metrics on a free port."""

    def __init__(self, bus_url: str, database: Path) -> None:
        self.metrics_port = free_port()
        self.command = [sys.executable, "-m", "service.cli", "sites", "--bus", bus_url, "--database",
                        str(database), "--metrics-port", str(self.metrics_port), "--log-level", "warning"]
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def metrics_url(self) -> str:
        return f"http://127.0.0.1:{self.metrics_port}/metrics"

    def start(self) -> WorkerProcess:
        self.process = subprocess.Popen(self.command, env=checkout_env({}), cwd=source_root(),
                                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return self

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(30)


def worker_throughput(client: redis.Redis, worker: WorkerProcess, sites: int,
                      seconds: float) -> dict[str, Any]:
    scene = Scene(people=20, cameras=4, seconds=seconds, fps=10.0)
    frames = observations(scene)
    entries = [(f"{SITE}-{k}", observation_to_json(frame)) for frame in frames for k in range(sites)]
    assert worker.process is not None
    cpu_before = _cpu_s(worker.process.pid)
    last_time = {site_id: frames[-1].capture_time for site_id, _ in entries}
    started = time.perf_counter()
    for begin in range(0, len(entries), 1000):
        pipe = client.pipeline(transaction=False)
        for site_id, observation in entries[begin:begin + 1000]:
            stream = bus.stream_key(bus.partition_of(site_id))
            pipe.xadd(stream, {"kind": "obs", "site": site_id, "obs": observation})
        pipe.execute()
    published_s = time.perf_counter() - started
    while not _caught_up(client, last_time):
        time.sleep(0.02)
    elapsed_s = time.perf_counter() - started
    cpu_s = _cpu_s(worker.process.pid) - cpu_before
    people = sum(len(frame) for frame in frames) * sites
    return {
        "sites": sites, "cameras_per_site": scene.cameras, "walkers_per_site": scene.people, "fps": scene.fps,
        "observations": len(entries), "people_per_observation": round(people / len(entries), 2),
        "published_per_s": round(len(entries) / published_s, 1),
        "observations_per_s": round(len(entries) / elapsed_s, 1),
        "worker_cpu_s": round(cpu_s, 3),
        "observations_per_cpu_s": round(len(entries) / cpu_s, 1) if cpu_s > 0 else None,
        "camera_frames_per_s_at_10_fps": round(len(entries) / elapsed_s / scene.fps, 1),
    }


def _post(client: httpx.Client, frame: bytes, capture_time: float) -> tuple[float, dict[str, Any]]:
    started = time.perf_counter()
    answer = client.post("/v1/cameras/cam-1/detect", params={"capture_time": repr(capture_time)},
                         content=frame, headers={"Content-Type": "image/jpeg"})
    elapsed_ms = (time.perf_counter() - started) * 1e3
    answer.raise_for_status()
    return elapsed_ms, answer.json()


def added_latency(bus_url: str, frames: int) -> dict[str, Any]:
    camera = FisheyeCamera.model_validate({**camera_to_dict(load_camera(DEMO_CAMERA_PATH)), "site": SITE,
                                           "site_pose": {"x_m": 0.0, "y_m": 0.0, "yaw_deg": 0.0}})
    frame = SAMPLE_FRAME.read_bytes()
    servers = {"without_bus": ServerProcess(DEFAULT_MODEL_PATH, camera, ["cam-1"], threads=1, grpc=False),
               "with_bus": ServerProcess(DEFAULT_MODEL_PATH, camera, ["cam-1"], threads=1, grpc=False,
                                         extra_env={"FISHLOC_SITES_BUS": bus_url})}
    timings: dict[str, list[float]] = {name: [] for name in servers}
    untracked = 0
    try:
        clients = {name: httpx.Client(base_url=server.start().url, timeout=60)
                   for name, server in servers.items()}
        for index in range(-5, frames):  # five warm-up frames each
            for name, client in clients.items():
                elapsed_ms, answer = _post(client, frame, 1.8e9 + index * 0.2)
                if index >= 0:
                    timings[name].append(elapsed_ms)
                    untracked += name == "with_bus" and "site_note" in answer
        for client in clients.values():
            client.close()
    finally:
        for server in servers.values():
            server.stop()
    summaries = {name: summarize(values).as_dict() for name, values in timings.items()}
    return {
        "frame": SAMPLE_FRAME.name, "frames": frames, **summaries,
        "added_ms": {q: round(summaries["with_bus"][q] - summaries["without_bus"][q], 3)
                     for q in ("p50", "p95")},
        "answered_without_track_ids": untracked,
    }


def run(sites: int, seconds: float, frames: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="fishloc-bench-bus-") as folder:
        (Path(folder) / "redis").mkdir()
        with RedisProcess(Path(folder) / "redis") as server:
            client = server.client()
            worker = WorkerProcess(server.url, Path(folder) / "registry.db").start()
            try:
                _wait_for_leases(client)
                report = {"redis_url": server.url, "cpus": os.cpu_count(),
                          "worker": worker_throughput(client, worker, sites, seconds),
                          "detect_latency_ms": added_latency(server.url, frames)}
            finally:
                worker.stop()
                client.close()
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sites", type=int, default=8, help="sites published at once to the worker")
    parser.add_argument("--seconds", type=float, default=30.0, help="seconds of each site's scene")
    parser.add_argument("--frames", type=int, default=100, help="detect calls timed per server")
    parser.add_argument("--json", default=None, help="write the report here too")
    args = parser.parse_args(argv)
    text = json.dumps(run(args.sites, args.seconds, args.frames), indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
