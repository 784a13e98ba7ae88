"""Zones and counting lines of sites in a PostgreSQL registry, shared by two processes' stores."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from fisheye import camera_from_dict, camera_to_dict, load_camera
from models import DEMO_CAMERA_PATH
from service.cameras import CameraRegistry
from service.sites.store import SiteNotFoundError, SiteStore
from sites import CountingLine, Zone


def _camera(camera_id: str, site: str) -> dict[str, Any]:
    return {**camera_to_dict(load_camera(DEMO_CAMERA_PATH)), "id": camera_id, "site": site}


@pytest.fixture
def stores(postgres_url: str) -> Iterator[tuple[SiteStore, SiteStore]]:
    first, second = CameraRegistry(postgres_url), CameraRegistry(postgres_url)
    yield SiteStore(first), SiteStore(second)
    first.close()
    second.close()


def test_zones_and_lines_live_in_postgresql(stores: tuple[SiteStore, SiteStore]) -> None:
    writer, reader = stores
    square = Zone("entrance", np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]))
    with pytest.raises(SiteNotFoundError):
        writer.put_zone("hall", square)
    writer.registry.put(camera_from_dict(_camera("cam-1", "hall")))
    assert writer.put_zone("hall", square) is True
    assert writer.put_zone("hall", square) is False
    assert writer.put_line("hall", CountingLine("door", np.array([0.0, 0.0]), np.array([0.0, 3.0])))
    layout = reader.layout("hall")
    assert list(layout.zones) == ["entrance"] and list(layout.lines) == ["door"]
    np.testing.assert_allclose(layout.zones["entrance"].polygon_m, square.polygon_m)
    assert [camera.id for camera in reader.get("hall").cameras] == ["cam-1"]
    assert reader.delete_zone("hall", "entrance") and not writer.delete_zone("hall", "entrance")
    assert list(writer.layout("hall").zones) == []
    writer.registry.delete("cam-1")
    with pytest.raises(SiteNotFoundError):
        reader.get("hall")
