"""A site's tracker: frames of its cameras in, in any order within a window, tracks and figures out.

`SiteTracker.update(observation)` folds one camera frame into the site's tracks and answers the track
each detection joined. Its clock is the frames' capture_time alone. A frame older than the newest
one seen is *late*: within `reorder_window_s` the tracks are rebuilt from the state before its time
with it and every later frame replayed in capture_time order (so the result is the one an in-order
arrival would have given); older than that, it is dropped and counted. A snapshot of the state is
kept before each frame of the window, so a replay costs only the frames after the late one.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sites.counting import zone_counts
from sites.fusion import FusionState, TrackerConfig
from sites.layout import SiteLayout
from sites.observation import FrameOutcome, SiteObservation
from sites.track import Track


@dataclass
class _Step:
    """A frame of the window and the state just before it."""

    time: float
    observation: SiteObservation
    before: FusionState


@dataclass
class FrameCounts:
    """Frames a site's tracker took in order, took late (replayed) and dropped for being too late."""

    used: int = 0
    used_late: int = 0
    dropped_late: int = 0


@dataclass
class SiteTracker:
    """The fused, tracked people of one site (see the module docstring)."""

    site_id: str
    config: TrackerConfig = field(default_factory=TrackerConfig)
    layout: SiteLayout = field(default_factory=SiteLayout)
    frames: FrameCounts = field(default_factory=FrameCounts)

    def __post_init__(self) -> None:
        self._state = FusionState(self.config)
        self._state.set_layout(self.layout)
        self._window: list[_Step] = []

    @property
    def time(self) -> float | None:
        """The newest capture time folded in (None before the first frame)."""
        return self._state.time

    @property
    def tracks(self) -> list[Track]:
        """Every live track, tentative ones included (read-only use)."""
        return self._state.tracks

    @property
    def ended(self) -> int:
        """Confirmed tracks ended so far (timed out, or their only camera left the site)."""
        return self._state.ended

    def track_id(self, track: Track | None) -> str | None:
        if track is None or track.number is None:
            return None
        return f"{self.site_id}:{track.number}"

    # ----- frames

    def update(self, observation: SiteObservation) -> FrameOutcome:
        """Fold one camera frame in; the confirmed track each of its detections joined."""
        t = observation.capture_time
        now = self._state.time
        if now is not None and t < now - self.config.reorder_window_s:
            self.frames.dropped_late += 1
            return FrameOutcome.dropped(len(observation))
        if now is None or t >= now:
            self._remember(observation, self._state.copy())
            joined = self._state.step(observation)
            self._forget_before(self._state.time)
            self.frames.used += 1
            return FrameOutcome(tuple(self.track_id(track) for track in joined), "used")
        return self._replay_with(observation)

    def _remember(self, observation: SiteObservation, before: FusionState) -> None:
        self._window.append(_Step(observation.capture_time, observation, before))

    def _forget_before(self, now: float | None) -> None:
        if now is None:
            return
        times = [step.time for step in self._window]
        keep_from = bisect.bisect_left(times, now - self.config.reorder_window_s)
        keep_from = max(keep_from, len(self._window) - self.config.max_buffered_frames)
        del self._window[:keep_from]

    def _replay_with(self, late: SiteObservation) -> FrameOutcome:
        """Rebuild the state with a late frame put in its capture_time place."""
        times = [step.time for step in self._window]
        at = bisect.bisect_right(times, late.capture_time)
        if at >= len(self._window):  # nothing of the window is newer: cannot happen for a late frame
            at = len(self._window) - 1
        later = self._window[at:]
        self._state = self._window[at].before.copy() if later else self._state
        del self._window[at:]
        self._remember(late, self._state.copy())
        joined = self._state.step(late)
        for step in later:
            self._remember(step.observation, self._state.copy())
            self._state.step(step.observation)
        self.frames.used_late += 1
        return FrameOutcome(tuple(self.track_id(track) for track in joined), "used_late")

    # ----- outside changes (applied to the state and to every snapshot of the window)

    def set_layout(self, layout: SiteLayout) -> None:
        """New zones and lines; tallies of lines that stay are kept, new ones start at zero."""
        self.layout = layout
        for state in [self._state, *(step.before for step in self._window)]:
            state.set_layout(layout)

    def remove_camera(self, camera_id: str) -> int:
        """A camera left the site (moved or deleted): tracks only it saw end now, its frames of the
        window are forgotten. The number of confirmed tracks ended."""
        self._window = [step for step in self._window if step.observation.camera_id != camera_id]
        for step in self._window:
            step.before.remove_camera(camera_id)
        return self._state.remove_camera(camera_id)

    # ----- answers

    def occupancy(self, t: float | None = None) -> dict[str, Any]:
        """The site's people now (DESIGN.md's occupancy answer): confirmed tracks, positions predicted
        to `t` (default: the newest capture time; never earlier), people per zone, line tallies."""
        now = self._state.time
        at = now if t is None or now is None else max(t, now)
        people = []
        positions = []
        for track in sorted(self._state.tracks, key=lambda tr: tr.number or 0):
            # A confirmed track coasting longer than `report_coast_s` is kept alive to re-join its
            # person, but no longer reported: they have most likely left.
            unseen_s = 0.0 if now is None else now - track.last_seen
            if track.number is None or unseen_s > self.config.report_coast_s:
                continue
            ahead = 0.0 if at is None or now is None else at - now
            position = track.position_m + ahead * track.velocity_mps
            positions.append(position)
            people.append({
                "track_id": self.track_id(track),
                "position_m": [round(float(v), 3) for v in position],
                "velocity_mps": [round(float(v), 3) for v in track.velocity_mps],
                "cameras": track.cameras_now(self.config.seen_window_s),
                "first_seen": track.first_seen,
                "last_seen": track.last_seen,
                "dwell_s": {zone: round(seconds, 3) for zone, seconds in sorted(track.dwell_s.items())},
            })
        counts = zone_counts(self.layout, np.array(positions).reshape(-1, 2))
        return {
            "site": self.site_id,
            "time": at,
            "count": len(people),
            "people": people,
            "zones": {zone: {"count": n} for zone, n in sorted(counts.items())},
            "lines": {line: tally.to_dict() for line, tally in sorted(self._state.counts.lines.items())},
        }

    def line_totals(self) -> dict[str, tuple[int, int]]:
        """(in, out) per line."""
        return {k: (v.crossed_in, v.crossed_out) for k, v in self._state.counts.lines.items()}
