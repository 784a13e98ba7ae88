"""The site hub of a detection replica behind a sites bus (`fishloc serve --sites-bus redis://…`).

The replica runs no tracker. Each frame of a site's camera is published to its site's partition
stream (`service.sites.bus`) with a request id and this replica's reply stream; a `fishloc sites`
worker applies it and answers the frame's track ids there. `forward` waits for that answer at most
`wait_s`, then answers the detections with `track_id: null` and a `site_note` saying why: detection
never waits on tracking for long, and never fails because of it.

Reads come from what the workers publish: `read` takes the site's occupancy from the `occupancy`
hash (written before the worker answers a frame, so a client that got a detect answer reads a state
that holds its frame, through any replica); watchers hear the `occupancy` channel. Camera and layout
writes through this replica are change notices in the partition streams, so the workers apply them
in order with the frames.

When Redis does not answer: detection goes on (positions, `track_id: null`, the undelivered frames
counted in `fishloc_site_observations_undelivered_total`), reads answer SitesUnavailableError (503),
`problem()` says why (`/readyz` shows it); everything resumes by itself when Redis is back.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import time
import uuid
from collections.abc import Callable
from typing import Any

import redis.exceptions

from fisheye import FisheyeCamera
from service.core.metrics import ServiceMetrics
from service.result import DetectionResult
from service.sites import bus
from service.sites.hub import Watcher
from service.sites.interface import Listeners, Occupancy, OccupancyListener, SitesUnavailableError
from service.sites.store import SiteStore
from sites import SiteObservation, SiteTracker
from sites.snapshot import observation_to_json

log = logging.getLogger(__name__)

BUS_ERRORS = (redis.exceptions.RedisError, OSError, TimeoutError)
STREAM_MAXLEN = 200_000  # a bound on a partition that no worker reads (workers trim what they snapshot)
RETRY_S = 0.5


class BusSiteHub:
    """Sites of a replica: frames out to the bus, occupancy in from it (see the module docstring)."""

    def __init__(self, url: str, store: SiteStore, metrics: ServiceMetrics, wait_s: float = 0.5,
                 partitions: int = bus.PARTITIONS) -> None:
        bus.check_url(url)
        self.url = url
        self.store = store
        self.metrics = metrics
        self.wait_s = wait_s
        self.partitions = partitions
        self.replica_id = uuid.uuid4().hex[:12]
        self._reply_key = bus.reply_key(self.replica_id)
        self._redis: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._waiting: dict[str, asyncio.Future[list[str | None]]] = {}
        self._watchers: dict[str, set[Watcher]] = {}
        self._listeners = Listeners()
        self._tasks: list[asyncio.Task[None]] = []
        self._problem: str | None = None
        self._closed = False

    # ----- life

    async def start(self) -> None:
        self._redis = await bus.connect(self.url)
        self._loop = asyncio.get_running_loop()
        self._tasks = [asyncio.create_task(self._read_replies()), asyncio.create_task(self._hear_updates()),
                       asyncio.create_task(self._watch_health())]
        log.info("sites bus %s: replica %s publishes site observations", bus.shown_url(self.url),
                 self.replica_id)

    async def stop(self) -> None:
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if self._redis is not None:
            await self._redis.aclose()

    def attach(self, runner: Any) -> None:
        runner.site_forwarding = self.forward

    def problem(self) -> str | None:
        return self._problem

    def _failed(self, error: BaseException) -> None:
        reason = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        if self._problem is None:
            log.warning("sites bus %s unreachable: %s", bus.shown_url(self.url), reason)
        self._problem = reason

    def _answered(self) -> None:
        if self._problem is not None:
            log.info("sites bus %s reachable again", bus.shown_url(self.url))
        self._problem = None

    # ----- frames

    async def forward(self, camera: FisheyeCamera, result: DetectionResult,
                      capture_time: float) -> DetectionResult:
        """Publish a frame of a site's camera and wait (at most `wait_s`) for its track ids."""
        positions = result.detections.site_position_m
        if camera.site is None or positions is None:
            return result
        observation = SiteObservation(camera.id, capture_time, positions, result.detections.distance_m,
                                      result.detections.scores)
        request_id = uuid.uuid4().hex
        answer: asyncio.Future[list[str | None]] = asyncio.get_running_loop().create_future()
        self._waiting[request_id] = answer
        started = time.monotonic()
        site = self.metrics.site_label(camera.site)
        try:
            fields = {"kind": "obs", "site": camera.site, "obs": observation_to_json(observation),
                      "reply": self._reply_key, "rid": request_id}
            stream = bus.stream_key(bus.partition_of(camera.site, self.partitions))
            await asyncio.wait_for(self._redis.xadd(stream, fields, maxlen=STREAM_MAXLEN, approximate=True),
                                   self.wait_s)
            self._answered()
        except BUS_ERRORS as error:
            self._waiting.pop(request_id, None)
            self._failed(error)
            self.metrics.site_observations_undelivered.labels(site=site).inc()
            return dataclasses.replace(result, site_note="not tracked: the sites bus is unreachable")
        try:
            left_s = max(self.wait_s - (time.monotonic() - started), 0.0)
            track_ids = await asyncio.wait_for(answer, left_s)
        except TimeoutError:
            self.metrics.site_answers_late.labels(site=site).inc()
            note = f"not tracked yet: no tracker answered within {self.wait_s:g} s (the frame is queued)"
            return dataclasses.replace(result, site_note=note)
        finally:
            self._waiting.pop(request_id, None)
        if len(track_ids) != len(result.detections):  # cannot happen unless versions disagree
            return dataclasses.replace(result, site_note="not tracked: the tracker's answer did not match")
        return dataclasses.replace(result, track_ids=tuple(track_ids))

    async def _read_replies(self) -> None:
        last = "0-0"
        while True:
            try:
                batches = await self._redis.xread({self._reply_key: last}, count=256, block=1000)
            except BUS_ERRORS as error:
                self._failed(error)
                await asyncio.sleep(RETRY_S)
                continue
            for _key, entries in batches or []:
                for entry_id, fields in entries:
                    last = entry_id
                    waiting = self._waiting.get(fields.get(b"rid", b"").decode())
                    if waiting is not None and not waiting.done():
                        waiting.set_result(json.loads(fields[b"ids"]))

    # ----- reads and watchers

    async def read(self, site_id: str) -> Occupancy:
        try:
            raw = await asyncio.wait_for(self._redis.hget(bus.OCCUPANCY, site_id), 2.0)
            self._answered()
        except BUS_ERRORS as error:
            self._failed(error)
            message = f"the sites bus is unreachable ({self._problem}); retry later"
            raise SitesUnavailableError(message) from None
        if raw is not None:
            occupancy: Occupancy = json.loads(raw)
            return occupancy
        # No worker has applied a frame of the site yet: an empty site with its zones and lines.
        layout = await asyncio.to_thread(self.store.layout, site_id)
        return SiteTracker(site_id, layout=layout).occupancy()

    async def subscribe(self, site_id: str) -> Watcher:
        watcher = Watcher(asyncio.get_running_loop())
        self._watchers.setdefault(site_id, set()).add(watcher)  # before the read: no update falls between
        try:
            watcher.offer(await self.read(site_id))
        except SitesUnavailableError:
            self.unwatch(site_id, watcher)
            raise
        if self._closed:
            watcher.offer(None)
        return watcher

    def unwatch(self, site_id: str, watcher: Watcher) -> None:
        self._watchers.get(site_id, set()).discard(watcher)

    def listen(self, listener: OccupancyListener) -> Callable[[], None]:
        return self._listeners.add(listener)

    def close(self) -> None:
        self._closed = True
        for watchers in self._watchers.values():
            for watcher in list(watchers):
                watcher.offer_threadsafe(None)
        self._watchers.clear()

    async def _hear_updates(self) -> None:
        while True:
            pubsub = self._redis.pubsub()
            try:
                await pubsub.subscribe(bus.OCCUPANCY)
                while True:
                    message = await pubsub.get_message(ignore_subscribe_messages=True, timeout=1.0)
                    if message is not None:
                        self._deliver(json.loads(message["data"]))
            except BUS_ERRORS as error:
                self._failed(error)
                await asyncio.sleep(RETRY_S)
            finally:
                with contextlib.suppress(*BUS_ERRORS):
                    await pubsub.aclose()

    def _deliver(self, update: Occupancy) -> None:
        site_id = str(update.get("site"))
        closed = update.get("closed") is True
        for watcher in list(self._watchers.get(site_id, ())):
            watcher.offer(None if closed else update)
        if closed:
            self._watchers.pop(site_id, None)
        else:
            self._listeners.notify(update)

    async def _watch_health(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            try:
                await asyncio.wait_for(self._redis.ping(), 2.0)
                self._answered()
            except BUS_ERRORS as error:
                self._failed(error)

    # ----- registry changes (called from a worker thread of the front ends)

    def camera_changed(self, camera_id: str, camera: FisheyeCamera | None) -> None:
        """A camera was written or deleted: a notice in every partition (its old site's worker ends
        the tracks only it saw)."""
        site = "" if camera is None or camera.site is None else camera.site
        fields = {"kind": "camera", "camera": camera_id, "site": site}
        self._notify_workers([bus.stream_key(p) for p in range(self.partitions)], fields)

    def layout_changed(self, site_id: str) -> None:
        stream = bus.stream_key(bus.partition_of(site_id, self.partitions))
        self._notify_workers([stream], {"kind": "layout", "site": site_id})

    def _notify_workers(self, streams: list[str], fields: dict[str, str]) -> None:
        async def send() -> None:
            async with self._redis.pipeline(transaction=False) as pipe:
                for stream in streams:
                    pipe.xadd(stream, fields, maxlen=STREAM_MAXLEN, approximate=True)
                await pipe.execute()

        if self._loop is None:
            return
        try:
            asyncio.run_coroutine_threadsafe(send(), self._loop).result(timeout=2.0)
        except (*BUS_ERRORS, TimeoutError) as error:
            # The workers still re-read zones and lines every second from the shared registry.
            self._failed(error)
            log.warning("change notice %s not delivered to the sites bus: %s", fields, error)
