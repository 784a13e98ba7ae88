"""A recorded site sequence (`fishloc synth --sequence`'s annotations.json) read for playback.

Frames are grouped into steps by `capture_time` (every camera of a step shares it) and the steps
are put in time order. Each step knows its frames (camera, file, annotated people) and its truth:
who is inside the site and where (`site.tracks`), and which of them some camera shows fairly (an
annotation that is not `iscrowd`); the others are inside but hidden, and count neither for nor
against a tracker.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


class SequenceFormatError(ValueError):
    """The file is not a site sequence (no capture times, track ids or site)."""


@dataclass(frozen=True)
class SequencePerson:
    """A person annotated in one frame: `track_id`, `site_xy_m` (2,), `distance_m` from that
    camera's nadir, and `ignore` (too hidden in this frame to be a fair target)."""

    track_id: int
    site_xy_m: tuple[float, float]
    distance_m: float
    ignore: bool


@dataclass(frozen=True)
class SequenceFrame:
    """One camera's frame of a step: `camera_id`, the JPEG's `path`, its annotated `people`."""

    camera_id: str
    path: Path
    people: list[SequencePerson]


@dataclass(frozen=True)
class SequenceStep:
    """All cameras' frames at one `capture_time`, and the truth then: `present` {track id:
    (x, y)} of everyone inside, `visible` the track ids some camera shows fairly."""

    capture_time: float
    frames: list[SequenceFrame]
    present: dict[int, tuple[float, float]]
    visible: frozenset[int]


@dataclass(frozen=True)
class Sequence:
    """A site sequence: `site_id`, camera records (camera files with `site` and `site_pose`), the
    zone and line bodies of the service's PUTs, and the steps in time order."""

    site_id: str
    cameras: list[dict[str, Any]]
    zones: dict[str, dict[str, Any]]
    lines: dict[str, dict[str, Any]]
    steps: list[SequenceStep] = field(default_factory=list)

    def zone_polygons(self) -> dict[str, FloatArray]:
        return {name: np.asarray(body["polygon_m"], dtype=np.float64) for name, body in self.zones.items()}

    def line_ends(self) -> dict[str, tuple[FloatArray, FloatArray]]:
        return {name: (np.asarray(body["from_m"], dtype=np.float64),
                       np.asarray(body["to_m"], dtype=np.float64))
                for name, body in self.lines.items()}

    def track_paths(self) -> dict[int, list[tuple[int, tuple[float, float]]]]:
        """Each track's (step index, position) while inside, in step order."""
        paths: dict[int, list[tuple[int, tuple[float, float]]]] = defaultdict(list)
        for index, step in enumerate(self.steps):
            for track_id, xy in step.present.items():
                paths[track_id].append((index, xy))
        return dict(paths)


def read_sequence(path: str | Path) -> Sequence:
    """Read a site sequence's annotations.json (file names relative to its folder)."""
    path = Path(path)
    document = json.loads(path.read_text(encoding="utf-8"))
    site = document.get("site")
    images = document.get("images") or []
    if not isinstance(site, dict) or not images or any("capture_time" not in i for i in images):
        raise SequenceFormatError(f"{path}: not a site sequence (needs `site`, images with `capture_time`)")
    by_image: dict[int, list[dict[str, Any]]] = defaultdict(list)
    for record in document.get("annotations") or []:
        if "track_id" not in record or "site_location_m" not in record:
            raise SequenceFormatError(f"{path}: annotation {record.get('id')} lacks track_id/site_location_m")
        by_image[int(record["image_id"])].append(record)
    cameras: dict[str, dict[str, Any]] = {}
    frames_at: dict[float, list[SequenceFrame]] = defaultdict(list)
    for image in images:
        camera = image["camera"]
        if camera.get("site") != site["id"] or "site_pose" not in camera:
            raise SequenceFormatError(f"{path}: image {image['id']}'s camera is not in site {site['id']}")
        cameras.setdefault(camera["id"], camera)
        people = [SequencePerson(int(a["track_id"]), (float(a["site_location_m"][0]),
                                                      float(a["site_location_m"][1])),
                                 float(a.get("distance_m", 0.0)), bool(a.get("iscrowd", 0)))
                  for a in by_image[int(image["id"])]]
        frame = SequenceFrame(camera["id"], path.parent / image["file_name"], people)
        frames_at[float(image["capture_time"])].append(frame)
    present_at: dict[int, dict[int, tuple[float, float]]] = defaultdict(dict)
    for track in site.get("tracks") or []:
        for step, xy in zip(track["steps"], track["positions_m"], strict=True):
            present_at[int(step)][int(track["track_id"])] = (float(xy[0]), float(xy[1]))
    steps = []
    for index, time in enumerate(sorted(frames_at)):
        frames = sorted(frames_at[time], key=lambda f: f.camera_id)
        visible = frozenset(p.track_id for f in frames for p in f.people if not p.ignore)
        present = present_at.get(index) or {p.track_id: p.site_xy_m for f in frames for p in f.people}
        steps.append(SequenceStep(time, frames, present, visible))
    return Sequence(str(site["id"]), list(cameras.values()), dict(site.get("zones") or {}),
                    dict(site.get("lines") or {}), steps)
