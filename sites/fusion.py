"""The step function of a site's tracks: one camera frame at one capture time in, tracks out.

Frames of all the site's cameras go through one `FusionState` in capture_time order (the tracker's
reordering window sees to the order). A step predicts every track to the frame's time, assigns the
frame's people to tracks (Hungarian assignment, `sites.assignment`, on the Mahalanobis distance of
each position to each track, gated), updates the matched tracks, starts tentative tracks for the
rest, and ends tracks unseen for too long. Overlapping views merge because the second camera's
frame of the same instant meets tracks the first camera's frame has just updated: a person seen by
two cameras feeds one track twice, and the gate accounts for each position's uncertainty, which grows with the
distance from the camera's nadir (`sigma_base_m + sigma_per_m · distance`).

A real detector's frame is cleaned up first: its detections of one person are merged on the floor
(`sites.floor_merge`), and only confident ones (`high_score`) may start a track, weaker ones only
extend a confirmed one (ByteTrack's two stages). A line crossing made while a track is tentative
waits on it and counts when it is confirmed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sites.assignment import linear_sum_assignment
from sites.counting import SiteCounts
from sites.floor_merge import merge_on_floor
from sites.layout import SiteLayout
from sites.observation import SiteObservation
from sites.track import KalmanStep, Track, process_noise, transition

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
_UNASSIGNABLE = 1e9


@dataclass(frozen=True)
class TrackerConfig:
    """Tuning of a site's fusion and tracking (times in capture-time seconds, lengths in metres)."""

    reorder_window_s: float = 0.5     # a frame up to this much older than the site's time is still used
    min_hits: int = 2                 # distinct capture times seen before a track is confirmed
    max_coast_s: float = 2.0          # a confirmed track unseen this long ends (hand-over gaps are shorter)
    tentative_timeout_s: float = 0.5  # a tentative track unseen this long is forgotten
    sigma_base_m: float = 0.10        # position noise at the nadir...
    sigma_per_m: float = 0.04         # ...growing by this much per metre from it
    accel_var: float = 4.0            # (m/s²)² of the white-noise acceleration of a walker
    speed_var: float = 1.0            # (m/s)² of a new track's unknown velocity
    gate_chi2: float = 13.8           # Mahalanobis² gate (99.9 % of a 2-D Gaussian)
    max_gate_m: float = 2.5           # and never farther than this
    merge_radius_m: float = 0.5       # an unmatched person this near a track another camera fed now is it
    line_margin_m: float = 0.2        # a line counts a track once it stands this far on the other side...
    line_hold_s: float = 0.3          # ...and is still there this much later (or ends there)
    seen_window_s: float = 0.5        # cameras that saw a track this recently are "its" cameras
    max_buffered_frames: int = 4096   # bound on the frames kept for replay within the window
    high_score: float = 0.8           # a detection this confident may start a track and update any...
    low_score: float = 0.3            # ...one this confident only extends a confirmed track (below: unused)
    floor_merge_base_m: float = 0.3   # one frame's detections this near on the floor are one person...
    floor_merge_per_m: float = 0.1    # ...the radius growing by this much per metre from the nadir
    report_coast_s: float = 0.5       # occupancy reports a confirmed track unseen at most this long

    def __post_init__(self) -> None:
        if self.min_hits < 1:
            raise ValueError("min_hits must be at least 1")
        positive = {name: getattr(self, name) for name in (
            "max_coast_s", "tentative_timeout_s", "sigma_base_m", "accel_var", "speed_var", "gate_chi2",
            "max_gate_m", "seen_window_s")}
        bad = {name: value for name, value in positive.items() if not value > 0}
        if bad or self.reorder_window_s < 0 or self.sigma_per_m < 0 or self.merge_radius_m < 0:
            raise ValueError(f"TrackerConfig values must be positive: {bad or 'window, slope, radius'}")
        if not 0 <= self.low_score <= self.high_score <= 1:
            raise ValueError("TrackerConfig needs 0 <= low_score <= high_score <= 1")
        if (self.floor_merge_base_m < 0 or self.floor_merge_per_m < 0 or self.report_coast_s < 0
                or self.line_hold_s < 0):
            raise ValueError("TrackerConfig floor merge radii, report_coast_s and line_hold_s must be >= 0")

    def noise_m2(self, distance_m: FloatArray) -> FloatArray:
        """(N,) position variances (m²) of detections at `distance_m` (N,) from their camera's nadir."""
        sigma = self.sigma_base_m + self.sigma_per_m * distance_m
        return sigma * sigma


@dataclass
class FusionState:
    """The tracks of one site and its figures at `time` (the latest capture time stepped to)."""

    config: TrackerConfig
    layout: SiteLayout = field(default_factory=SiteLayout)
    tracks: list[Track] = field(default_factory=list)
    time: float | None = None
    next_number: int = 1
    counts: SiteCounts = field(default_factory=SiteCounts)
    ended: int = 0
    kalman: KalmanStep = field(default_factory=KalmanStep, repr=False)

    def copy(self) -> FusionState:
        return FusionState(self.config, self.layout, [track.copy() for track in self.tracks], self.time,
                           self.next_number, self.counts.copy(), self.ended)

    # ----- one step

    def advance(self, t: float) -> None:
        """Predict every track to `t` (≥ time) and end the ones unseen for too long."""
        if self.time is not None and t > self.time:
            dt = t - self.time
            self.kalman.motion(transition(dt), process_noise(dt, self.config.accel_var))
            for track in self.tracks:
                track.predict(self.kalman)
        self.time = t if self.time is None else max(self.time, t)
        kept = []
        for track in self.tracks:
            limit = self.config.max_coast_s if track.confirmed else self.config.tentative_timeout_s
            if t - track.last_seen <= limit:
                kept.append(track)
            elif track.confirmed:
                self.counts.settle(self.layout, track)
                self.ended += 1
        self.tracks = kept

    def _costs(self, tracks: list[Track], z_m: FloatArray, noise_m2: FloatArray) -> FloatArray:
        """(T, M) gated squared Mahalanobis distances of M positions to T tracks."""
        position = np.stack([track.position_m for track in tracks])  # (T, 2)
        P = np.stack([track.P[:2, :2] for track in tracks])          # (T, 2, 2)
        dx = z_m[None, :, 0] - position[:, None, 0]                       # (T, M)
        dy = z_m[None, :, 1] - position[:, None, 1]
        # Innovation covariance S = P + R per pair, inverted in closed form (2 x 2).
        a = P[:, None, 0, 0] + noise_m2[None, :]
        b = P[:, None, 0, 1]
        c = P[:, None, 1, 0]
        d = P[:, None, 1, 1] + noise_m2[None, :]
        d2 = (d * dx * dx - (b + c) * dx * dy + a * dy * dy) / (a * d - b * c)
        near = (d2 <= self.config.gate_chi2) & (np.hypot(dx, dy) <= self.config.max_gate_m)
        return np.where(near, d2, _UNASSIGNABLE)

    def step(self, observation: SiteObservation) -> list[Track | None]:
        """Fold one frame (capture_time ≥ time) into the tracks; the track each detection joined.

        The frame's detections of one person are merged on the floor first (`sites.floor_merge`).
        Then, as ByteTrack does, confident detections (`high_score`) are assigned to every track
        and the unassigned ones start tentative tracks; weaker ones (`low_score`) are then assigned
        to the confirmed tracks left over, and never start one."""
        t = observation.capture_time
        self.advance(t)
        config = self.config
        joined: list[Track | None] = [None] * len(observation)
        rows = np.flatnonzero(observation.valid & (observation.scores >= config.low_score))
        if len(rows) == 0:
            return joined
        kept_for = merge_on_floor(observation.positions_m[rows], observation.distance_m[rows],
                                  observation.scores[rows], config.floor_merge_base_m,
                                  config.floor_merge_per_m, config.high_score)
        merged_rows, stands_for = rows, rows[kept_for]  # each row and the row kept for it
        rows = rows[np.unique(kept_for)]
        z_m = observation.positions_m[rows]
        noise = config.noise_m2(observation.distance_m[rows])
        high = observation.scores[rows] >= config.high_score
        pairs = self._assign(np.arange(len(self.tracks)), np.flatnonzero(high), z_m, noise)
        left = sorted(set(range(len(self.tracks))) - {ti for ti, _ in pairs})
        left_confirmed = np.array([ti for ti in left if self.tracks[ti].confirmed], dtype=np.int64)
        pairs += self._assign(left_confirmed, np.flatnonzero(~high), z_m, noise)
        moved: list[Track] = []
        before_m: list[FloatArray] = []
        before_t: list[float] = []
        taken: set[int] = set()
        for ti, di in pairs:
            track = self.tracks[ti]
            # The move counted is from where the track was last seen, not from its prediction.
            moved.append(track)
            before_m.append(track.last_position_m)
            before_t.append(track.last_seen)
            track.update(self.kalman, z_m[di], float(noise[di]), t, observation.camera_id)
            self._confirm_if_due(track)
            joined[rows[di]] = track
            taken.add(di)
        self.counts.account(self.layout, moved, np.array(before_m).reshape(-1, 2), np.array(before_t),
                            config.line_margin_m, config.line_hold_s)
        for di in np.flatnonzero(high).tolist():
            if di in taken or self._seen_by_another(z_m[di], t, observation.camera_id):
                continue
            track = Track.start(z_m[di], float(noise[di]), config.speed_var, t, observation.camera_id)
            self._confirm_if_due(track)
            self.tracks.append(track)
            joined[rows[di]] = track
        for row, kept_row in zip(merged_rows, stands_for, strict=True):
            joined[row] = joined[kept_row]
        return joined

    def _assign(self, track_index: IntArray, det_index: IntArray, z_m: FloatArray,
                noise_m2: FloatArray) -> list[tuple[int, int]]:
        """Hungarian assignment of detections `det_index` to tracks `track_index` within the gate:
        the (track, detection) index pairs."""
        if len(track_index) == 0 or len(det_index) == 0:
            return []
        costs = self._costs([self.tracks[i] for i in track_index], z_m[det_index], noise_m2[det_index])
        # A track with no detection in its gate, or a detection in no track's, can only be paired
        # outside the gate: leaving them out changes no pair within it and keeps the problem small.
        gated = costs < _UNASSIGNABLE
        live_tracks, live_detections = np.flatnonzero(gated.any(axis=1)), np.flatnonzero(gated.any(axis=0))
        ti, di = linear_sum_assignment(costs[np.ix_(live_tracks, live_detections)])
        ti, di = live_tracks[ti], live_detections[di]
        matched = costs[ti, di] < _UNASSIGNABLE
        return [(int(track_index[a]), int(det_index[b]))
                for a, b in zip(ti[matched], di[matched], strict=True)]

    def _confirm_if_due(self, track: Track) -> None:
        """Confirm a track seen often enough: it gets its number, and the line crossings of its
        tentative past count now."""
        if not track.confirmed and track.hits >= self.config.min_hits:
            track.number, self.next_number = self.next_number, self.next_number + 1
            self.counts.count_pending(track)

    def _seen_by_another(self, xy_m: FloatArray, t: float, camera_id: str) -> bool:
        """Whether another camera fed a track at `t` this near `xy_m`: the same person in an
        overlapping view that the gate kept apart, not a new one."""
        for track in self.tracks:
            fed_now = any(c != camera_id and s == t for c, s in track.cameras_seen.items())
            if fed_now and float(np.hypot(*(track.position_m - xy_m))) <= self.config.merge_radius_m:
                return True
        return False

    # ----- outside changes

    def set_layout(self, layout: SiteLayout) -> None:
        self.layout = layout
        self.counts.follow(layout)
        for track in self.tracks:
            track.dwell_s = {zone: s for zone, s in track.dwell_s.items() if zone in layout.zones}
            track.line_anchors = {line: a for line, a in track.line_anchors.items() if line in layout.lines}

    def remove_camera(self, camera_id: str) -> int:
        """Forget a camera that left the site: tracks only it saw lately end now; the number ended."""
        kept, ended = [], 0
        for track in self.tracks:
            if track.cameras_now(self.config.seen_window_s) == [camera_id]:
                if track.confirmed:
                    self.counts.settle(self.layout, track)
                ended += track.confirmed
                continue
            track.cameras_seen.pop(camera_id, None)
            kept.append(track)
        self.tracks = kept
        self.ended += ended
        return ended
