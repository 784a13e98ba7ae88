"""The sites of one service process: each site's tracker, fed by every frame of its cameras, and the
clients watching it (SSE and gRPC `WatchSite`).

`SiteHub.track` runs on the inference thread right after the pipeline, so a frame is part of its
site's state by the time its detect call returns. Each site has its own lock; frames of different
sites never wait for each other. Watchers get occupancy updates through bounded per-client queues
that drop their oldest update when full: a slow client loses updates, it never slows detection.

A camera that moves to another site, or is deleted, leaves its old site: the tracks only it saw end
(`SiteTracker.remove_camera`), and a site that no camera names any more closes its watchers' streams.
Every occupancy update also goes to the hub's listeners (`listen`; the outputs attach there,
`service.outputs.attach`), after the frame that made it and when a camera leaves a site.
Zones and lines are read from the registry's database when a site's tracker starts, when they are
written through this process, and at most `layout_refresh_s` after a write through another process.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import threading
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

from fisheye import FisheyeCamera
from service.core.metrics import ServiceMetrics
from service.result import DetectionResult
from service.sites.interface import Listeners, Occupancy, OccupancyListener
from service.sites.store import SiteStore
from sites import SiteLayout, SiteObservation, SiteTracker, TrackerConfig

log = logging.getLogger(__name__)

WATCH_QUEUE_SIZE = 16


class Watcher:
    """One client's bounded queue of occupancy updates (None: the site closed)."""

    def __init__(self, loop: asyncio.AbstractEventLoop, size: int = WATCH_QUEUE_SIZE) -> None:
        self.loop = loop
        self.queue: asyncio.Queue[Occupancy | None] = asyncio.Queue(maxsize=size)
        self.dropped = 0

    def offer(self, update: Occupancy | None) -> None:
        """Queue an update (on the watcher's loop), dropping the oldest one when full."""
        if self.queue.full():
            self.queue.get_nowait()
            self.dropped += 1
        self.queue.put_nowait(update)

    def offer_threadsafe(self, update: Occupancy | None) -> None:
        with contextlib.suppress(RuntimeError):  # the client's loop has closed
            self.loop.call_soon_threadsafe(self.offer, update)

    async def updates(self) -> AsyncIterator[Occupancy]:
        while (update := await self.queue.get()) is not None:
            yield update


@dataclasses.dataclass
class _Site:
    tracker: SiteTracker
    lock: threading.Lock
    layout_key: str
    layout_read_at: float
    cameras: set[str] = dataclasses.field(default_factory=set)
    watchers: set[Watcher] = dataclasses.field(default_factory=set)
    last: Occupancy | None = None


def layout_key(layout: SiteLayout) -> str:
    """The layout as a string that changes exactly when its zones or lines do."""
    return json.dumps({"zones": {k: v.to_dict() for k, v in layout.zones.items()},
                       "lines": {k: v.to_dict() for k, v in layout.lines.items()}}, sort_keys=True)


class SiteHub:
    """Trackers and watchers of every site this process has seen."""

    def __init__(self, store: SiteStore, metrics: ServiceMetrics, config: TrackerConfig | None = None,
                 layout_refresh_s: float = 1.0) -> None:
        self.store = store
        self.metrics = metrics
        self.config = config or TrackerConfig()
        self.layout_refresh_s = layout_refresh_s
        self._sites: dict[str, _Site] = {}
        self._camera_site: dict[str, str] = {}
        self._lock = threading.Lock()  # guards the two maps, never held while tracking
        self._closed = False
        self._listeners = Listeners()

    # ----- the hub interface (`service.sites.interface.Sites`)

    async def start(self) -> None:
        pass

    async def stop(self) -> None:
        pass

    def attach(self, runner: Any) -> None:
        runner.site_tracking = self.track  # on the inference thread, right after the pipeline

    async def read(self, site_id: str) -> Occupancy:
        return await asyncio.to_thread(self.occupancy, site_id)

    async def subscribe(self, site_id: str) -> Watcher:
        return await asyncio.to_thread(self.watch, site_id, asyncio.get_running_loop())

    def listen(self, listener: OccupancyListener) -> Callable[[], None]:
        return self._listeners.add(listener)

    def problem(self) -> str | None:
        return None

    # ----- frames

    def track(self, camera: FisheyeCamera, result: DetectionResult, capture_time: float) -> DetectionResult:
        """Fold a frame's detections into its camera's site; the result with each detection's track id
        (unchanged for a camera without a site)."""
        self._follow_camera(camera.id, camera.site)
        site_id = camera.site
        positions = result.detections.site_position_m
        if site_id is None or positions is None:
            return result
        site = self._site(site_id)
        observation = SiteObservation(camera.id, capture_time, positions, result.detections.distance_m,
                                      result.detections.scores)
        with site.lock:
            self._refresh_layout(site_id, site)
            started = time.perf_counter()
            site.cameras.add(camera.id)
            before = site.tracker.line_totals()
            outcome = site.tracker.update(observation)
            occupancy = site.tracker.occupancy() if outcome.use != "dropped_late" else site.last
            site.last = occupancy
            watchers = list(site.watchers)
            self.metrics.observe_site(site_id, outcome.use, before, site.tracker.line_totals(), occupancy,
                                      time.perf_counter() - started)
        if outcome.use != "dropped_late" and occupancy is not None:
            for watcher in watchers:
                watcher.offer_threadsafe(occupancy)
            self._listeners.notify(occupancy)
        return dataclasses.replace(result, track_ids=outcome.track_ids)

    # ----- reads and watchers

    def occupancy(self, site_id: str) -> Occupancy:
        """The site's occupancy now (an empty one before its first frame in this process)."""
        site = self._site(site_id)
        with site.lock:
            self._refresh_layout(site_id, site)
            if site.last is None or site.last.get("time") is None:
                site.last = site.tracker.occupancy()
            return site.last

    def watch(self, site_id: str, loop: asyncio.AbstractEventLoop) -> Watcher:
        """A watcher of the site's updates, holding its occupancy now as the first update."""
        watcher = Watcher(loop)
        watcher.offer(self.occupancy(site_id))
        site = self._site(site_id)
        with site.lock:  # close() sets _closed before it takes each site's lock to end its watchers
            if self._closed:  # the service is stopping: the stream ends after the occupancy now
                watcher.offer(None)
            else:
                site.watchers.add(watcher)
        return watcher

    def unwatch(self, site_id: str, watcher: Watcher) -> None:
        with self._lock:
            site = self._sites.get(site_id)
        if site is not None:
            with site.lock:
                site.watchers.discard(watcher)

    # ----- registry changes

    def camera_changed(self, camera_id: str, camera: FisheyeCamera | None) -> None:
        """A camera was written or deleted (None): it leaves its old site if that changed."""
        self._follow_camera(camera_id, None if camera is None else camera.site)

    def layout_changed(self, site_id: str) -> None:
        """Zones or lines of a site were written: read them again before the next frame."""
        with self._lock:
            site = self._sites.get(site_id)
        if site is not None:
            with site.lock:
                site.layout_read_at = -float("inf")
                site.last = None

    def close(self) -> None:
        """End every watcher's stream (the service is stopping)."""
        with self._lock:
            self._closed = True
            sites = list(self._sites.values())
        for site in sites:
            with site.lock:
                watchers, site.watchers = list(site.watchers), set()
            for watcher in watchers:
                watcher.offer_threadsafe(None)

    # ----- internals

    def _site(self, site_id: str) -> _Site:
        with self._lock:
            site = self._sites.get(site_id)
        if site is not None:
            return site
        layout = self.store.layout(site_id)
        created = _Site(SiteTracker(site_id, self.config, layout), threading.Lock(), layout_key(layout),
                        time.monotonic())
        with self._lock:
            return self._sites.setdefault(site_id, created)

    def _refresh_layout(self, site_id: str, site: _Site) -> None:
        """Re-read the site's zones and lines once `layout_refresh_s` has passed (caller holds the lock)."""
        now = time.monotonic()
        if now - site.layout_read_at < self.layout_refresh_s:
            return
        layout = self.store.layout(site_id)
        site.layout_read_at = now
        key = layout_key(layout)
        if key != site.layout_key:
            site.layout_key = key
            site.tracker.set_layout(layout)
            self.metrics.follow_layout(site_id, layout)
            site.last = None

    def _follow_camera(self, camera_id: str, site_id: str | None) -> None:
        with self._lock:
            old = self._camera_site.get(camera_id)
            if old == site_id:
                return
            if site_id is None:
                self._camera_site.pop(camera_id, None)
            else:
                self._camera_site[camera_id] = site_id
            left = self._sites.get(old) if old is not None else None
        if left is None or old is None:
            return
        with left.lock:
            ended = left.tracker.remove_camera(camera_id)
            left.cameras.discard(camera_id)
            left.last = left.tracker.occupancy()
            watchers = list(left.watchers)
            self._listeners.notify(left.last)  # the ended tracks leave the outputs' counts too
        log.info("camera %s left site %s: %d tracks ended", camera_id, old, ended,
                 extra={"camera_id": camera_id})
        if old not in self.store.site_cameras():
            self._close_site(old)
            return
        for watcher in watchers:
            watcher.offer_threadsafe(left.last)

    def _close_site(self, site_id: str) -> None:
        """No camera names the site any more: forget its tracks and end its watchers' streams."""
        with self._lock:
            site = self._sites.pop(site_id, None)
        if site is None:
            return
        with site.lock:
            watchers, site.watchers = list(site.watchers), set()
        for watcher in watchers:
            watcher.offer_threadsafe(None)
        self.metrics.forget_site(site_id)

