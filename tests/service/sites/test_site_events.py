"""Watching a site on a real server: SSE and gRPC `WatchSite` deliver the same updates to several
clients at once, a client that does not read does not slow detection, and streams end cleanly when
the site's cameras leave it."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable, Iterator
from typing import Any

import grpc
import httpx
import pytest
from service_live_server import LiveServer
from service_sites import SITE, T0, detect, frame_of, put_site_cameras, walk

from fisheye import FisheyeCamera
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.config import Settings
from service.grpc.convert import occupancy_from_message
from service.sites.hub import Watcher


@pytest.fixture
def server(settings_for: Callable[..., Settings]) -> Iterator[LiveServer]:
    with LiveServer(settings_for(grpc_port=0, host="127.0.0.1")) as live:
        yield live


def _sse_events(url: str, events: list[tuple[str, dict[str, Any]]], connected: threading.Event) -> None:
    """Read a site's event stream to its end into `events`."""
    with httpx.Client(timeout=60) as client, client.stream("GET", url) as answer:
        assert answer.status_code == 200
        assert answer.headers["content-type"].startswith("text/event-stream")
        name = ""
        for line in answer.iter_lines():
            if line.startswith("event: "):
                name = line.removeprefix("event: ")
            elif line.startswith("data: "):
                events.append((name, json.loads(line.removeprefix("data: "))))
                connected.set()


def _watch(target: str, updates: list[dict[str, Any]], connected: threading.Event) -> grpc.StatusCode:
    with grpc.insecure_channel(target) as channel:
        stream = pb_grpc.LocalizerStub(channel).WatchSite(pb.WatchSiteRequest(site=SITE), timeout=60)
        for message in stream:
            updates.append(occupancy_from_message(message))
            connected.set()
        return stream.code()


def test_two_sse_clients_and_a_grpc_watcher_see_every_update_and_the_end(
        server: LiveServer, demo_camera: FisheyeCamera) -> None:
    client = httpx.Client(base_url=server.url, timeout=30)
    put_site_cameras(client, demo_camera)
    client.put(f"/v1/sites/{SITE}/lines/door", json={"from_m": [0, -3], "to_m": [0, 3]})
    url = f"{server.url}/v1/sites/{SITE}/events"
    streams: list[list[tuple[str, dict[str, Any]]]] = [[], []]
    watched: list[dict[str, Any]] = []
    codes: list[grpc.StatusCode] = []
    ready = [threading.Event() for _ in range(3)]
    threads = [threading.Thread(target=_sse_events, args=(url, streams[i], ready[i])) for i in range(2)]
    target = f"127.0.0.1:{server.service.grpc_port}"  # type: ignore[union-attr]
    threads.append(threading.Thread(target=lambda: codes.append(_watch(target, watched, ready[2]))))
    for thread in threads:
        thread.start()
    assert all(event.wait(30) for event in ready)  # each has its first update: the occupancy now

    walk(client, demo_camera, start=(-2.0, 0.5), velocity=(1.0, 0.0), steps=20)
    final = client.get(f"/v1/sites/{SITE}/occupancy").json()
    assert client.delete("/v1/cameras/cam-a").status_code == 204
    assert client.delete("/v1/cameras/cam-b").status_code == 204  # the site's last camera: streams end
    for thread in threads:
        thread.join(30)
        assert not thread.is_alive()

    for events in streams:
        names = [name for name, _ in events]
        assert names[0] == "occupancy" and names[-1] == "end"
        occupancies = [data for name, data in events if name == "occupancy"]
        assert occupancies[0]["time"] is None  # connected before the first frame
        assert final in occupancies
        times = [data["time"] for data in occupancies[1:41]]
        assert times == sorted(times) and len(times) == 40  # one update per frame, in capture order
    assert codes == [grpc.StatusCode.OK]
    assert final in watched
    # The watchers saw the same updates in the same order.
    assert [data for name, data in streams[0] if name == "occupancy"][:41] == watched[:41]
    client.close()


def test_a_client_that_does_not_read_does_not_slow_detection(
        server: LiveServer, demo_camera: FisheyeCamera) -> None:
    client = httpx.Client(base_url=server.url, timeout=30)
    put_site_cameras(client, demo_camera)
    with httpx.Client(timeout=30) as stalled, stalled.stream("GET", f"{server.url}/v1/sites/{SITE}/events"):
        # Connected and never read: detection goes on, and a reading client keeps up.
        ids = walk(client, demo_camera, start=(-2.0, 0.5), velocity=(0.5, 0.0), steps=30)
        assert ids[-1] == f"{SITE}:1"
        watchers = server.state.sites._sites[SITE].watchers
        assert len(watchers) == 1
        assert all(watcher.queue.qsize() <= watcher.queue.maxsize for watcher in watchers)
        late = detect(client, "cam-a", frame_of(demo_camera, "cam-a", (0.0, 0.5)), T0 + 60)
        assert late.status_code == 200
    client.close()


def test_watching_an_unknown_site_is_not_found(server: LiveServer) -> None:
    target = f"127.0.0.1:{server.service.grpc_port}"  # type: ignore[union-attr]
    with grpc.insecure_channel(target) as channel:
        stub = pb_grpc.LocalizerStub(channel)
        with pytest.raises(grpc.RpcError) as missing:
            list(stub.WatchSite(pb.WatchSiteRequest(site="nowhere"), timeout=10))
        assert missing.value.code() == grpc.StatusCode.NOT_FOUND
        with pytest.raises(grpc.RpcError) as invalid:
            list(stub.WatchSite(pb.WatchSiteRequest(site="no such site"), timeout=10))
        assert invalid.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    answer = httpx.get(f"{server.url}/v1/sites/nowhere/events")
    assert answer.status_code == 404 and answer.json()["error"]["code"] == "site_not_found"


def test_a_watcher_queue_keeps_the_newest_updates() -> None:
    async def scenario() -> tuple[list[float | None], int]:
        watcher = Watcher(asyncio.get_running_loop(), size=4)
        for k in range(10):
            watcher.offer({"time": float(k)})
        watcher.offer(None)  # the end always arrives, after the newest updates
        seen = [update["time"] async for update in watcher.updates()]
        return seen, watcher.dropped

    seen, dropped = asyncio.run(scenario())
    assert seen == [7.0, 8.0, 9.0] and dropped == 7
