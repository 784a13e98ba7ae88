"""Sites in the registry's database: which cameras name each site, its zones and counting lines.

A site exists while a camera names it (camera file `site`); zones and lines are rows of their own
tables beside the cameras (`service.cameras`), validated by `sites.layout` before they are written.
A site's zones and lines outlive its cameras: a camera that names the site again finds them.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import Table, delete, insert, select, update
from sqlalchemy.exc import IntegrityError

from fisheye import FisheyeCamera
from service.cameras import CameraRegistry, site_lines_table, site_zones_table
from sites import CountingLine, LayoutError, SiteLayout, Zone

MAX_ZONES_PER_SITE = 64  # bounds the Prometheus labels of a site as well
MAX_LINES_PER_SITE = 64


class SiteNotFoundError(LookupError):
    """No camera names this site."""


@dataclass(frozen=True)
class SiteRecord:
    """A site as the registry holds it: its cameras (by id) and its layout."""

    id: str
    cameras: list[FisheyeCamera]
    layout: SiteLayout


class SiteStore:
    """Zones and lines of sites in the camera registry's database."""

    def __init__(self, registry: CameraRegistry) -> None:
        self.registry = registry
        self.engine = registry.engine

    # ----- sites

    def site_cameras(self) -> dict[str, list[FisheyeCamera]]:
        """Each site named by a camera, with its cameras (by id)."""
        sites: dict[str, list[FisheyeCamera]] = {}
        for camera in self.registry.all():
            if camera.site is not None:
                sites.setdefault(camera.site, []).append(camera)
        return dict(sorted(sites.items()))

    def get(self, site_id: str) -> SiteRecord:
        cameras = self.site_cameras().get(site_id)
        if cameras is None:
            raise SiteNotFoundError(site_id)
        return SiteRecord(site_id, cameras, self.layout(site_id))

    def require(self, site_id: str) -> None:
        if site_id not in self.site_cameras():
            raise SiteNotFoundError(site_id)

    def layout(self, site_id: str) -> SiteLayout:
        """The zones and lines stored for a site (empty when none)."""
        zones = [Zone(zone_id, record["polygon_m"])
                 for zone_id, record in self._rows(site_zones_table, site_id)]
        lines = [CountingLine(line_id, record["from_m"], record["to_m"])
                 for line_id, record in self._rows(site_lines_table, site_id)]
        return SiteLayout.of(zones, lines)

    def layouts(self, site_ids: Iterable[str]) -> dict[str, SiteLayout]:
        return {site_id: self.layout(site_id) for site_id in site_ids}

    # ----- zones and lines

    def put_zone(self, site_id: str, zone: Zone) -> bool:
        """Store a zone of an existing site; True when it is new."""
        return self._put(site_zones_table, site_id, zone.id, zone.to_dict(), MAX_ZONES_PER_SITE, "zones")

    def put_line(self, site_id: str, line: CountingLine) -> bool:
        """Store a counting line of an existing site; True when it is new."""
        return self._put(site_lines_table, site_id, line.id, line.to_dict(), MAX_LINES_PER_SITE, "lines")

    def delete_zone(self, site_id: str, zone_id: str) -> bool:
        return self._delete(site_zones_table, site_id, zone_id)

    def delete_line(self, site_id: str, line_id: str) -> bool:
        return self._delete(site_lines_table, site_id, line_id)

    # ----- rows

    def _rows(self, table: Table, site_id: str) -> list[tuple[str, dict[str, Any]]]:
        with self.engine.connect() as connection:
            query = select(table.c.id, table.c.record).where(table.c.site == site_id).order_by(table.c.id)
            rows = connection.execute(query).all()
        return [(str(row[0]), json.loads(str(row[1]))) for row in rows]

    def _put(self, table: Table, site_id: str, item_id: str, record: dict[str, Any], limit: int,
             what: str) -> bool:
        self.require(site_id)
        text = json.dumps(record, sort_keys=True)
        key = (table.c.site == site_id) & (table.c.id == item_id)
        with self.engine.begin() as connection:
            if connection.execute(update(table).where(key).values(record=text)).rowcount:
                return False
            count = len(connection.execute(select(table.c.id).where(table.c.site == site_id)).all())
            if count >= limit:
                raise LayoutError(f"site {site_id!r} has {count} {what} already; at most {limit}")
        try:
            with self.engine.begin() as connection:
                connection.execute(insert(table).values(site=site_id, id=item_id, record=text))
            return True
        except IntegrityError:  # another writer inserted it between our update and insert
            return self._put(table, site_id, item_id, record, limit, what)

    def _delete(self, table: Table, site_id: str, item_id: str) -> bool:
        self.require(site_id)
        with self.engine.begin() as connection:
            key = (table.c.site == site_id) & (table.c.id == item_id)
            return bool(connection.execute(delete(table).where(key)).rowcount)
