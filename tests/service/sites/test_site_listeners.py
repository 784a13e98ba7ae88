"""Occupancy listeners (what outputs attach to): the one-process hub and a `fishloc sites` worker call
them the same way, with each occupancy update after the frame that made it."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import redis.asyncio as aioredis
from service_live_server import LiveServer
from service_sites import SITE, put_site_cameras, walk

from benchmarks.redis_process import RedisProcess
from fisheye import FisheyeCamera
from service.cameras import CameraRegistry
from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.sites import bus
from service.sites.store import SiteStore
from service.sites.worker import SitesWorker, WorkerConfig
from sites import SiteObservation
from sites.snapshot import observation_to_json


@pytest.fixture
def server(settings_for: Callable[..., Settings]) -> Iterator[LiveServer]:
    with LiveServer(settings_for()) as live:
        yield live


def test_the_one_process_hub_calls_its_listeners_after_every_frame(server: LiveServer,
                                                                   demo_camera: FisheyeCamera) -> None:
    updates: list[dict[str, Any]] = []
    threads: set[str] = set()

    def listener(update: dict[str, Any]) -> None:
        updates.append(update)
        threads.add(threading.current_thread().name)

    stop = server.state.sites.listen(listener)
    with httpx.Client(base_url=server.url, timeout=30) as client:
        put_site_cameras(client, demo_camera)
        walk(client, demo_camera, start=(-1.0, 0.0), velocity=(1.0, 0.0), steps=4)
        stop()
        walk(client, demo_camera, start=(-1.0, 0.0), velocity=(1.0, 0.0), steps=2, t0=2e9)
    assert len(updates) == 8 and all(u["site"] == SITE for u in updates)
    assert updates[-1]["count"] == 1 and all(name.startswith("fishloc-infer") for name in threads)


def test_a_worker_calls_its_listeners_with_each_update_it_publishes(tmp_path: Path) -> None:
    folder = tmp_path / "redis"
    folder.mkdir()
    registry = CameraRegistry(str(tmp_path / "registry.db"))
    with RedisProcess(folder) as server:
        asyncio.run(_worker_run(server.url, SiteStore(registry)))
    registry.close()


async def _worker_run(url: str, store: SiteStore) -> None:
    client = aioredis.Redis.from_url(url)
    worker = SitesWorker(client, store, ServiceMetrics(), WorkerConfig(block_ms=20))
    updates: list[dict[str, Any]] = []
    worker.listen(updates.append)
    stop = asyncio.Event()
    running = asyncio.create_task(worker.run(stop))
    try:
        while len(worker.partitions) < bus.PARTITIONS:
            await asyncio.sleep(0.05)
        stream = bus.stream_key(bus.partition_of("hall"))
        for k in range(5):
            observation = SiteObservation.of("cam-a", 1.7e9 + 0.2 * k, [[0.2 * k, 0.0]])
            fields = {"kind": "obs", "site": "hall", "obs": observation_to_json(observation)}
            await client.xadd(stream, fields)
        async with asyncio.timeout(30):
            while len(updates) < 5:
                await asyncio.sleep(0.02)
        assert [u["time"] for u in updates] == [1.7e9 + 0.2 * k for k in range(5)]
        assert updates[-1]["count"] == 1 and updates[-1]["people"][0]["track_id"] == "hall:1"
        assert await client.hget(bus.OCCUPANCY, "hall") is not None
    finally:
        stop.set()
        await running
    assert worker.partitions == []  # a stopping worker hands every partition over
    # A successor loads the snapshot: the camera that left ends the site, as it would have there.
    successor = SitesWorker(client, store, ServiceMetrics(), WorkerConfig(block_ms=20))
    stop = asyncio.Event()
    running = asyncio.create_task(successor.run(stop))
    try:
        async with asyncio.timeout(30):
            while len(successor.partitions) < bus.PARTITIONS:
                await asyncio.sleep(0.05)
            await client.xadd(stream, {"kind": "camera", "camera": "cam-a", "site": ""})
            while await client.hget(bus.OCCUPANCY, "hall") is not None:
                await asyncio.sleep(0.02)
    finally:
        stop.set()
        await running
        await client.aclose()
