"""A site tracker's whole state as plain JSON values, and back: what a tracking worker snapshots.

`tracker_to_state(tracker)` holds the tracks (Kalman state, life, cameras, dwell, line anchors and
pending crossings, history), the line tallies, the id counter and the reordering window, so
`tracker_from_state` rebuilds a tracker that answers every later frame exactly as the original
would: floats go through JSON as their shortest repr, which reads back to the same float64. The
window is kept as its frames and the state before the first of them; the state before each later
one is what stepping through the ones before it gives (the tracker keeps it so), so it is rebuilt
rather than stored: a snapshot is two states and some frames, not one state per frame. The layout
is not part of it (it lives in the registry); the caller hands the current one in.
`observation_to_json` / `observation_from_json` carry one frame.
"""

from __future__ import annotations

import json
from collections import deque
from typing import Any

import numpy as np

from sites.counting import LineTally, SiteCounts
from sites.fusion import FusionState, TrackerConfig
from sites.layout import SiteLayout
from sites.observation import SiteObservation
from sites.track import HISTORY_LENGTH, Track
from sites.tracker import FrameCounts, SiteTracker, _Step

STATE_VERSION = 2


def observation_to_dict(observation: SiteObservation) -> dict[str, Any]:
    return {"camera_id": observation.camera_id, "capture_time": observation.capture_time,
            "positions_m": observation.positions_m.tolist(), "distance_m": observation.distance_m.tolist(),
            "scores": observation.scores.tolist()}


def observation_from_dict(value: dict[str, Any]) -> SiteObservation:
    return SiteObservation(str(value["camera_id"]), float(value["capture_time"]),
                           np.array(value["positions_m"], dtype=np.float64).reshape(-1, 2),
                           np.array(value["distance_m"], dtype=np.float64),
                           np.array(value["scores"], dtype=np.float64))


def observation_to_json(observation: SiteObservation) -> str:
    return json.dumps(observation_to_dict(observation), separators=(",", ":"))


def observation_from_json(text: str | bytes) -> SiteObservation:
    return observation_from_dict(json.loads(text))


def _track_to_dict(track: Track) -> dict[str, Any]:
    return {"x": track.x.tolist(), "P": track.P.tolist(), "first_seen": track.first_seen,
            "last_seen": track.last_seen, "number": track.number, "hits": track.hits,
            "cameras_seen": track.cameras_seen, "dwell_s": track.dwell_s,
            "line_anchors": {k: [side, xy.tolist()] for k, (side, xy) in track.line_anchors.items()},
            "pending_crossings": [list(c) for c in track.pending_crossings],
            "history": [list(h) for h in track.history]}


def _track_from_dict(value: dict[str, Any]) -> Track:
    return Track(
        x=np.array(value["x"], dtype=np.float64), P=np.array(value["P"], dtype=np.float64),
        first_seen=float(value["first_seen"]), last_seen=float(value["last_seen"]), number=value["number"],
        hits=int(value["hits"]), cameras_seen={str(k): float(v) for k, v in value["cameras_seen"].items()},
        dwell_s={str(k): float(v) for k, v in value["dwell_s"].items()},
        line_anchors={str(k): (int(side), np.array(xy, dtype=np.float64))
                      for k, (side, xy) in value["line_anchors"].items()},
        pending_crossings=[(str(line), int(sign)) for line, sign in value["pending_crossings"]],
        history=deque((tuple(h) for h in value["history"]), maxlen=HISTORY_LENGTH),
    )


def _fusion_to_dict(state: FusionState) -> dict[str, Any]:
    return {"tracks": [_track_to_dict(t) for t in state.tracks], "time": state.time,
            "next_number": state.next_number, "ended": state.ended,
            "lines": {k: [v.crossed_in, v.crossed_out] for k, v in state.counts.lines.items()}}


def _fusion_from_dict(value: dict[str, Any], config: TrackerConfig, layout: SiteLayout) -> FusionState:
    counts = SiteCounts({str(k): LineTally(int(i), int(o)) for k, (i, o) in value["lines"].items()})
    state = FusionState(config, SiteLayout(), [_track_from_dict(t) for t in value["tracks"]], value["time"],
                        int(value["next_number"]), counts, int(value["ended"]))
    state.set_layout(layout)  # keeps the tallies of lines that stay, as a layout change does
    return state


def tracker_to_state(tracker: SiteTracker) -> dict[str, Any]:
    """The tracker's state (JSON-ready; see the module docstring)."""
    return {"version": STATE_VERSION, "site_id": tracker.site_id,
            "frames": [tracker.frames.used, tracker.frames.used_late, tracker.frames.dropped_late],
            "state": _fusion_to_dict(tracker._state),
            "window_base": _fusion_to_dict(tracker._window[0].before) if tracker._window else None,
            "window": [observation_to_dict(step.observation) for step in tracker._window]}


def tracker_from_state(value: dict[str, Any], config: TrackerConfig, layout: SiteLayout) -> SiteTracker:
    """A tracker rebuilt from `tracker_to_state`'s answer, under `config` and the current `layout`
    (ValueError for a state of another version)."""
    if value.get("version") != STATE_VERSION:
        raise ValueError(f"a tracker state of version {value.get('version')!r}, expected {STATE_VERSION}")
    used, used_late, dropped_late = (int(n) for n in value["frames"])
    tracker = SiteTracker(str(value["site_id"]), config, layout, FrameCounts(used, used_late, dropped_late))
    tracker._state = _fusion_from_dict(value["state"], config, layout)
    tracker._window = []
    if value["window"]:
        stepped = _fusion_from_dict(value["window_base"], config, layout)
        for item in value["window"]:
            observation = observation_from_dict(item)
            tracker._window.append(_Step(observation.capture_time, observation, stepped.copy()))
            stepped.step(observation)
    return tracker
