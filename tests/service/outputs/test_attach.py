"""The outputs attached to a tracker's listeners: each update reaches the dispatcher with its layout."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from service.cameras import CameraRegistry
from service.outputs.attach import LayoutCache, attach_outputs
from service.sites.interface import Listeners, OccupancyListener
from service.sites.store import SiteStore
from sites import SiteLayout


class _Store:
    """A site store whose layouts are counted as they are read (`SiteStore.layout` alone)."""

    def __init__(self) -> None:
        self.reads = 0
        self.closed: set[str] = set()

    def layout(self, site_id: str) -> SiteLayout:
        from service.sites.store import SiteNotFoundError

        if site_id in self.closed:
            raise SiteNotFoundError(site_id)
        self.reads += 1
        return SiteLayout.of([], [])


class _Source:
    def __init__(self) -> None:
        self.listeners = Listeners()

    def listen(self, listener: OccupancyListener) -> Callable[[], None]:
        return self.listeners.add(listener)


class _Dispatcher:
    def __init__(self) -> None:
        self.offered: list[tuple[str, dict[str, Any], SiteLayout]] = []

    def offer(self, site_id: str, occupancy: dict[str, Any], layout: SiteLayout) -> None:
        self.offered.append((site_id, occupancy, layout))


def test_layouts_are_read_again_only_after_the_refresh() -> None:
    now = [0.0]
    store = _Store()
    cache = LayoutCache(store, refresh_s=1.0, clock=lambda: now[0])  # type: ignore[arg-type]
    cache.get("hall")
    now[0] = 0.5
    cache.get("hall")
    assert store.reads == 1
    now[0] = 1.6
    cache.get("hall")
    assert store.reads == 2


def test_every_update_reaches_the_dispatcher_until_stopped() -> None:
    store, source, dispatcher = _Store(), _Source(), _Dispatcher()
    stop = attach_outputs(dispatcher, source, store)  # type: ignore[arg-type]
    source.listeners.notify({"site": "hall", "count": 1})
    store.closed.add("gone")
    source.listeners.notify({"site": "gone", "count": 0})  # the site closed with it: nothing to count
    stop()
    source.listeners.notify({"site": "hall", "count": 2})
    assert [(site, update["count"]) for site, update, _ in dispatcher.offered] == [("hall", 1)]


def test_a_real_store_gives_the_zones_written_to_it(tmp_path: Path) -> None:
    registry = CameraRegistry(str(tmp_path / "registry.db"))
    try:
        cache = LayoutCache(SiteStore(registry))
        assert cache.get("nowhere").zones == {}  # a site with no zones has an empty layout
    finally:
        registry.close()
