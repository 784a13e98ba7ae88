"""What happened on a site between two occupancy updates: the one place events are derived.

The trackers answer occupancy (DESIGN.md's dict: people, zone counts, line tallies); the outputs want
events. `EventDeriver.derive` compares each update of a site with the one before it: a line tally
that grew gives one `line_crossing` per crossing, a track found in a zone it was not in before gives
`zone_enter` (and the other way `zone_leave`). Zone thresholds are the subscriber's own
(`threshold_crossings`), from the zone counts before and after. The first update of a site is the
baseline: it gives no events, so a tracker restored from a snapshot is not counted twice.
"""

from __future__ import annotations

import threading
import uuid
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sites import SiteLayout

Occupancy = dict[str, Any]


def new_event_id() -> str:
    return uuid.uuid4().hex


@dataclass(frozen=True)
class SiteUpdate:
    """One occupancy update of a site with what changed since the one before."""

    site: str
    time: float
    occupancy: Occupancy
    zones_before: dict[str, int]
    events: tuple[dict[str, Any], ...] = ()

    @property
    def zones(self) -> dict[str, int]:
        return {zone: int(value["count"]) for zone, value in self.occupancy.get("zones", {}).items()}

    @property
    def lines(self) -> dict[str, dict[str, int]]:
        return {line: dict(tally) for line, tally in self.occupancy.get("lines", {}).items()}

    def of_type(self, *types: str) -> list[dict[str, Any]]:
        return [event for event in self.events if event["type"] in types]


@dataclass
class _Seen:
    lines: dict[str, dict[str, int]]
    zones: dict[str, int]
    members: dict[str, set[str]] = field(default_factory=dict)


def zone_members(layout: SiteLayout, occupancy: Occupancy) -> dict[str, set[str]]:
    """The track ids inside each zone of the layout."""
    people = occupancy.get("people", [])
    if not people:
        return {zone: set() for zone in layout.zones}
    xy = np.array([person["position_m"] for person in people], dtype=np.float64).reshape(-1, 2)
    ids = [str(person["track_id"]) for person in people]
    return {zone_id: {ids[i] for i in np.flatnonzero(zone.contains_xy(xy))}
            for zone_id, zone in layout.zones.items()}


class EventDeriver:
    """Per site, the last update seen, to tell what the next one changed (thread-safe)."""

    def __init__(self) -> None:
        self._seen: dict[str, _Seen] = {}
        self._lock = threading.Lock()

    def derive(self, site_id: str, occupancy: Occupancy, layout: SiteLayout) -> SiteUpdate:
        time = float(occupancy.get("time") or 0.0)
        lines = {line: {"in": int(t["in"]), "out": int(t["out"])}
                 for line, t in occupancy.get("lines", {}).items()}
        zones = {zone: int(value["count"]) for zone, value in occupancy.get("zones", {}).items()}
        members = zone_members(layout, occupancy)
        with self._lock:
            before = self._seen.get(site_id)
            self._seen[site_id] = _Seen(lines, zones, members)
        if before is None:
            return SiteUpdate(site_id, time, occupancy, zones)
        events: list[dict[str, Any]] = []
        for line, tally in lines.items():
            old = before.lines.get(line, {"in": 0, "out": 0})
            for direction in ("in", "out"):
                # A tally that shrank was rebuilt (a late frame replayed, a line written anew): no event.
                for _ in range(max(tally[direction] - old[direction], 0)):
                    events.append({"id": new_event_id(), "type": "line_crossing", "site": site_id,
                                   "time": time, "line": line, "direction": direction,
                                   "totals": dict(tally)})
        for zone, inside in members.items():
            was = before.members.get(zone, set())
            for kind, tracks in (("zone_enter", inside - was), ("zone_leave", was - inside)):
                for track_id in sorted(tracks):
                    events.append({"id": new_event_id(), "type": kind, "site": site_id, "time": time,
                                   "zone": zone, "track_id": track_id, "count": zones.get(zone, 0)})
        return SiteUpdate(site_id, time, occupancy, before.zones, tuple(events))

    def forget(self, site_id: str) -> None:
        with self._lock:
            self._seen.pop(site_id, None)


def threshold_crossings(update: SiteUpdate, thresholds: dict[str, int]) -> list[dict[str, Any]]:
    """`zone_threshold` events of an update for per-zone thresholds: `up` when a zone's count reaches
    its threshold from below, `down` when it falls below it."""
    events = []
    now = update.zones
    for zone, threshold in sorted(thresholds.items()):
        before, after = update.zones_before.get(zone, 0), now.get(zone, 0)
        direction = ("up" if before < threshold <= after else
                     "down" if after < threshold <= before else None)
        if direction is not None:
            events.append({"id": new_event_id(), "type": "zone_threshold", "site": update.site,
                           "time": update.time, "zone": zone, "threshold": threshold,
                           "direction": direction, "count": after})
    return events


def summary_event(update: SiteUpdate) -> dict[str, Any]:
    """A `summary` event: the site's people, zone counts and line totals at the update."""
    return {"id": new_event_id(), "type": "summary", "site": update.site, "time": update.time,
            "count": int(update.occupancy.get("count", 0)), "zones": update.zones, "lines": update.lines}
