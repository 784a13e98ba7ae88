"""Zone and line figures of a site: people per zone now, dwell per track and zone, line crossings.

Tracks report their moves (where they were before an update and where they are after it); a move
that crosses a counting line counts `in` or `out` (the sign convention of `sites.layout`), and the
time between two updates inside a zone adds to the track's dwell there. A tentative track's crossings
wait on it (`Track.pending_crossings`) and count when it is confirmed: a person who walks through a
door before the tracker is sure of them is counted once confirmed, noise that never is, never.

Crossings have hysteresis in space and time: a track counts once it stands `margin_m` clear on the
other side of a line and is still clear on that side `hold_s` later (or ends there), so a person who
lingers on a door line, their position jittering across it, counts once or not at all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sites.layout import SiteLayout, side_of
from sites.track import Track

FloatArray = NDArray[np.float64]


@dataclass
class LineTally:
    """`in` and `out` crossings of one line."""

    crossed_in: int = 0
    crossed_out: int = 0

    def to_dict(self) -> dict[str, int]:
        return {"in": self.crossed_in, "out": self.crossed_out}


@dataclass
class SiteCounts:
    """Crossing tallies per line of the layout (kept across layout changes for lines that stay)."""

    lines: dict[str, LineTally] = field(default_factory=dict)

    def follow(self, layout: SiteLayout) -> None:
        """Keep tallies of the layout's lines only; new lines start at zero."""
        self.lines = {line_id: self.lines.get(line_id, LineTally()) for line_id in layout.lines}

    def count_pending(self, track: Track) -> None:
        """Count the crossings a just-confirmed track made while tentative."""
        for line_id, sign in track.pending_crossings:
            if line_id in self.lines:
                self.lines[line_id].crossed_in += sign > 0
                self.lines[line_id].crossed_out += sign < 0
        track.pending_crossings = []

    def account(self, layout: SiteLayout, tracks: list[Track], before_m: FloatArray,
                before_t: FloatArray, margin_m: float, hold_s: float = 0.0) -> None:
        """Count the moves of `tracks` (just updated; a tentative one's crossings wait on it) from
        `before_m` (M, 2) m at `before_t` (M,) s to their current positions: crossings per line, dwell
        per zone (the hysteresis of the module docstring: `margin_m` clear, for `hold_s`)."""
        if not tracks:
            return
        after_m = np.stack([track.last_position_m for track in tracks])
        for line_id, line in layout.lines.items():
            length = float(np.hypot(*(line.to_m - line.from_m)))
            distance = side_of(line.from_m, line.to_m, after_m) / length
            distance_before = side_of(line.from_m, line.to_m, before_m) / length
            # A track's first anchor is where it stood clear of the line first, even when its next
            # position falls within the margin (a track started just before the line).
            for index in np.flatnonzero(np.abs(distance_before) >= margin_m):
                if line_id not in tracks[index].line_anchors:
                    tracks[index].line_anchors[line_id] = (int(np.sign(distance_before[index])),
                                                           before_m[index])
            for index in np.flatnonzero(np.abs(distance) >= margin_m):
                track, side = tracks[index], int(np.sign(distance[index]))
                anchor = track.line_anchors.setdefault(line_id, (side, after_m[index]))
                if anchor[0] == side:  # still (or back) on its side: an excursion that did not hold
                    track.line_anchors[line_id] = (side, after_m[index])
                    track.line_leaving.pop(line_id, None)
                    continue
                since = track.line_leaving.setdefault(line_id, track.last_seen)
                if track.last_seen - since >= hold_s:
                    self._cross(layout, track, line_id, side, after_m[index])
        for zone_id, zone in layout.zones.items():
            was_inside = zone.contains_xy(before_m)
            is_inside = zone.contains_xy(after_m)
            for index in np.flatnonzero(was_inside & is_inside):
                track = tracks[index]
                elapsed = track.last_seen - float(before_t[index])
                track.dwell_s[zone_id] = track.dwell_s.get(zone_id, 0.0) + max(elapsed, 0.0)
            for index in np.flatnonzero(is_inside & ~was_inside):
                tracks[index].dwell_s.setdefault(zone_id, 0.0)

    def settle(self, layout: SiteLayout, track: Track) -> None:
        """A confirmed track ends: the crossings it was holding (clear on the other side) count."""
        for line_id in list(track.line_leaving):
            anchor = track.line_anchors.get(line_id)
            if anchor is not None and line_id in layout.lines:
                self._cross(layout, track, line_id, -anchor[0], track.last_position_m)
        track.line_leaving = {}

    def _cross(self, layout: SiteLayout, track: Track, line_id: str, side: int, at_m: FloatArray) -> None:
        """The track, clear on `side` of the line at `at_m`, has crossed it (if the way from its anchor
        meets the segment): counted now, or pending while the track is tentative."""
        anchor_m = track.line_anchors[line_id][1]
        track.line_anchors[line_id] = (side, at_m)
        track.line_leaving.pop(line_id, None)
        sign = int(layout.lines[line_id].crossings(anchor_m[None, :], at_m[None, :])[0])
        if not sign:
            return
        if not track.confirmed:
            track.pending_crossings.append((line_id, sign))
            return
        tally = self.lines.setdefault(line_id, LineTally())
        tally.crossed_in += sign > 0
        tally.crossed_out += sign < 0

    def copy(self) -> SiteCounts:
        return SiteCounts({k: LineTally(v.crossed_in, v.crossed_out) for k, v in self.lines.items()})


def zone_counts(layout: SiteLayout, positions_m: FloatArray) -> dict[str, int]:
    """People per zone for positions (N, 2) m."""
    return {zone_id: int(zone.contains_xy(positions_m).sum()) for zone_id, zone in layout.zones.items()}
