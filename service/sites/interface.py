"""What the front ends and the outputs see of a site hub, one process or many.

Two hubs stand behind it: `SiteHub` (`service.sites.hub`, the one-process default: the trackers live
in this process) and `BusSiteHub` (`service.sites.bus_hub`, `fishloc serve --sites-bus`: observations
go to Redis, a `fishloc sites` worker tracks them, every replica reads what the workers publish).

Occupancy updates, for outputs (MQTT, webhooks, history): `listen(listener)` calls `listener(update)`
with each site's occupancy answer after every frame that changed it, and answers a function that
stops the calls. `SiteHub` and the `fishloc sites` worker (`service.sites.worker.SitesWorker.listen`)
call it the same way: on the thread that applied the frame, right after it, so a listener must be
quick and must not block (hand the update to a queue or `loop.call_soon_threadsafe`). Attach the
outputs where the trackers run: in the one process, or in the `sites` worker (a replica behind a bus
hears every update too, over Redis, but so does every other replica).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, Protocol

from fisheye import FisheyeCamera

log = logging.getLogger(__name__)

Occupancy = dict[str, Any]
OccupancyListener = Callable[[Occupancy], None]


class SitesUnavailableError(RuntimeError):
    """Site state cannot be read now (the sites bus is unreachable): answer 503 with the message."""


class Listeners:
    """The listeners of occupancy updates; `notify` calls each, a failing one is logged, not fatal."""

    def __init__(self) -> None:
        self._listeners: list[OccupancyListener] = []

    def add(self, listener: OccupancyListener) -> Callable[[], None]:
        self._listeners.append(listener)

        def remove() -> None:
            if listener in self._listeners:
                self._listeners.remove(listener)

        return remove

    def notify(self, update: Occupancy) -> None:
        for listener in list(self._listeners):
            try:
                listener(update)
            except Exception:  # an output's bug must not stop tracking
                log.exception("an occupancy listener failed")


class Sites(Protocol):
    """A site hub as the REST and gRPC front ends use it."""

    async def start(self) -> None:
        """Connect what the hub needs (BusError when the bus does not answer)."""

    async def stop(self) -> None:
        """Release what `start` took."""

    def attach(self, runner: Any) -> None:
        """Hook into the runner so that every frame of a site's camera reaches its site."""

    async def read(self, site_id: str) -> Occupancy:
        """The site's occupancy now (SitesUnavailableError when it cannot be read)."""

    async def subscribe(self, site_id: str) -> Any:
        """A `Watcher` of the site's updates, its first update the occupancy now."""

    def unwatch(self, site_id: str, watcher: Any) -> None: ...

    def camera_changed(self, camera_id: str, camera: FisheyeCamera | None) -> None: ...

    def layout_changed(self, site_id: str) -> None: ...

    def listen(self, listener: OccupancyListener) -> Callable[[], None]: ...

    def problem(self) -> str | None:
        """Why site state is unavailable now, or None."""

    def close(self) -> None:
        """End every watcher's stream (the service is stopping)."""
