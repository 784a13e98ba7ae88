"""The outputs attached to whatever runs the trackers: a site hub of one process, or a `fishloc
sites` worker behind a bus. Both call their listeners with each occupancy update
(`service.sites.interface`); the dispatcher also needs the site's zones and lines, read from the
registry and re-read at most every `refresh_s` (as the trackers themselves follow a write made
elsewhere)."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Protocol

from service.outputs.sink import Dispatcher
from service.sites.interface import Occupancy, OccupancyListener
from service.sites.store import SiteNotFoundError, SiteStore
from sites import SiteLayout

log = logging.getLogger(__name__)


class Listenable(Protocol):
    def listen(self, listener: OccupancyListener) -> Callable[[], None]: ...


class LayoutCache:
    """Each site's layout from `store`, read again once `refresh_s` has passed since the last read."""

    def __init__(self, store: SiteStore, refresh_s: float = 1.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.store = store
        self.refresh_s = refresh_s
        self.clock = clock
        self._layouts: dict[str, tuple[float, SiteLayout]] = {}
        self._lock = threading.Lock()

    def get(self, site_id: str) -> SiteLayout:
        """The site's layout (SiteNotFoundError when no camera names the site any more)."""
        now = self.clock()
        with self._lock:
            cached = self._layouts.get(site_id)
        if cached is not None and now - cached[0] < self.refresh_s:
            return cached[1]
        layout = self.store.layout(site_id)
        with self._lock:
            self._layouts[site_id] = (now, layout)
        return layout


def attach_outputs(dispatcher: Dispatcher, source: Listenable, store: SiteStore) -> Callable[[], None]:
    """Feed `dispatcher` every occupancy update of `source`; answers the function that stops it."""
    layouts = LayoutCache(store)

    def listener(update: Occupancy) -> None:
        site_id = str(update.get("site"))
        try:
            layout = layouts.get(site_id)
        except SiteNotFoundError:
            return  # the site closed with this update: nothing is left to count
        dispatcher.offer(site_id, update, layout)

    return source.listen(listener)
