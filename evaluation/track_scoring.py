"""Scores of a site's reported tracks against a sequence's truth, in the floor plane.

Per step the reported people (`occupancy.people`) are matched to the people some camera shows
fairly by `motmetrics` (CLEAR-MOT and identity metrics) on the site-frame distance, gated at
`gate_m` (0.75 m). A reported person whose nearest true person is inside the site but hidden from
every camera (and within the gate) is left out of that step: it is neither right nor wrong.

- `duplicates`: reported people that match no true person while lying within the gate of a true
  person another reported person does match: one person reported twice, typically where two
  cameras overlap and their positions were not fused. `duplicate_rate` = duplicates / reported.
- Zone counts: per step the reported `zones[z].count` against the true people inside the zone's
  polygon (everyone inside the site, seen or not); mean absolute error per zone.
- Line counts: the reported `lines[l]` (`in`, `out`) after the last step, less those before the
  first, against the crossings of the true paths from step to step, by DESIGN.md's convention (from
  the line's left to its right, looking from `from_m` to `to_m` with y up, is `in`).
- `detections` (played through a server): what the detector fed the tracker, frame by frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from evaluation.sequence_data import Sequence

FloatArray = NDArray[np.float64]

GATE_M = 0.75


@dataclass
class Reported:
    """What the site reported after each step: `people` (track id -> (x, y)), zone counts and the
    site's `times` per step, and the line tallies before the first step and after the last."""

    times: list[float | None] = field(default_factory=list)
    # Each frame's detections as the service answered them: (step index, camera id, site positions).
    detections: list[tuple[int, str, list[tuple[float, float]]]] = field(default_factory=list)
    people: list[dict[str, tuple[float, float]]] = field(default_factory=list)
    zone_counts: list[dict[str, int]] = field(default_factory=list)
    lines_before: dict[str, dict[str, int]] = field(default_factory=dict)
    lines_after: dict[str, dict[str, int]] = field(default_factory=dict)

    def add(self, occupancy: dict[str, Any]) -> None:
        """Record the occupancy answer (DESIGN.md's shape) read after a step."""
        self.times.append(occupancy.get("time"))
        self.people.append({str(p["track_id"]): (float(p["position_m"][0]), float(p["position_m"][1]))
                            for p in occupancy.get("people", []) if p.get("position_m") is not None})
        self.zone_counts.append({z: int(v["count"]) for z, v in (occupancy.get("zones") or {}).items()})
        self.lines_after = {name: {"in": int(v["in"]), "out": int(v["out"])}
                            for name, v in (occupancy.get("lines") or {}).items()}


def inside_polygon(points_m: FloatArray, polygon_m: FloatArray) -> NDArray[np.bool_]:
    """(N, 2) points, (K, 2) polygon -> (N,) True inside (even-odd rule)."""
    x, y = points_m[:, 0:1], points_m[:, 1:2]
    xa, ya = polygon_m[:, 0], polygon_m[:, 1]
    xb, yb = np.roll(xa, -1), np.roll(ya, -1)
    straddles = (ya > y) != (yb > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = xa + (y - ya) * (xb - xa) / (yb - ya)
    return np.asarray((straddles & (x < cross_x)).sum(axis=1) % 2 == 1)


def line_crossings(before_m: FloatArray, after_m: FloatArray, from_m: FloatArray, to_m: FloatArray
                   ) -> NDArray[np.int64]:
    """(N,) +1 where the move before -> after (each (N, 2)) crosses the line from its left to its
    right (`in`), -1 the other way (`out`), 0 where it does not cross."""
    direction = to_m - from_m

    def side(p: FloatArray) -> FloatArray:
        return direction[0] * (p[:, 1] - from_m[1]) - direction[1] * (p[:, 0] - from_m[0])

    s0, s1 = side(before_m), side(after_m)
    move = after_m - before_m

    def move_side(p: FloatArray) -> FloatArray:
        return move[:, 0] * (p[1] - before_m[:, 1]) - move[:, 1] * (p[0] - before_m[:, 0])

    crosses = (s0 * s1 < 0) & (move_side(from_m) * move_side(to_m) <= 0)
    return np.where(crosses, np.where(s0 > 0, 1, -1), 0).astype(np.int64)


def true_line_counts(sequence: Sequence) -> dict[str, dict[str, int]]:
    """`in` and `out` crossings of every line by the true paths, step to step."""
    out = {name: {"in": 0, "out": 0} for name in sequence.lines}
    for path in sequence.track_paths().values():
        if len(path) < 2:
            continue
        steps = np.array([s for s, _ in path])
        xy = np.array([p for _, p in path])
        consecutive = np.flatnonzero(np.diff(steps) == 1)
        for name, (a, b) in sequence.line_ends().items():
            signs = line_crossings(xy[consecutive], xy[consecutive + 1], a, b)
            out[name]["in"] += int((signs > 0).sum())
            out[name]["out"] += int((signs < 0).sum())
    return out


def _relative(reported: int, truth: int) -> float | None:
    return None if truth == 0 else (reported - truth) / truth


def score_lines(sequence: Sequence, reported: Reported) -> dict[str, Any]:
    truth = true_line_counts(sequence)
    lines: dict[str, Any] = {}
    errors = []
    for name, counts in truth.items():
        after = reported.lines_after.get(name, {"in": 0, "out": 0})
        before = reported.lines_before.get(name, {"in": 0, "out": 0})
        entry: dict[str, Any] = {}
        for direction in ("in", "out"):
            got = after[direction] - before[direction]
            error = _relative(got, counts[direction])
            entry[direction] = {"true": counts[direction], "reported": got, "relative_error": error}
            if error is not None:
                errors.append(abs(error))
        lines[name] = entry
    total_true = sum(c["in"] + c["out"] for c in truth.values())
    total_got = sum(e[d]["reported"] for e in lines.values() for d in ("in", "out"))
    return {"lines": lines, "line_error_max": max(errors) if errors else None,
            "line_error_total": _relative(total_got, total_true)}


def score_zones(sequence: Sequence, reported: Reported) -> dict[str, Any]:
    polygons = sequence.zone_polygons()
    zones: dict[str, Any] = {}
    for name, polygon in polygons.items():
        truth, got = [], []
        for step, counts in zip(sequence.steps, reported.zone_counts, strict=True):
            xy = np.array(list(step.present.values()), dtype=np.float64).reshape(-1, 2)
            truth.append(int(inside_polygon(xy, polygon).sum()))
            got.append(counts.get(name, 0))
        t, g = np.array(truth, dtype=np.float64), np.array(got, dtype=np.float64)
        zones[name] = {"count_mae": float(np.abs(g - t).mean()) if len(t) else None,
                       "mean_true": float(t.mean()) if len(t) else None,
                       "mean_reported": float(g.mean()) if len(g) else None}
    maes = [z["count_mae"] for z in zones.values() if z["count_mae"] is not None]
    return {"zones": zones, "zone_count_mae": float(np.mean(maes)) if maes else None}


def score_tracks(sequence: Sequence, reported: Reported, gate_m: float = GATE_M) -> dict[str, Any]:
    """MOTA, IDF1, ID switches, MOTP (m), precision, recall and duplicates (module docstring)."""
    import motmetrics as mm  # evaluation only: the service never imports it

    if len(reported.people) != len(sequence.steps):
        raise ValueError(f"{len(reported.people)} occupancy answers for {len(sequence.steps)} steps")
    accumulator = mm.MOTAccumulator(auto_id=True)
    numbers: dict[str, int] = {}  # motmetrics takes numeric ids
    frames = []
    reported_total = 0
    for step, people in zip(sequence.steps, reported.people, strict=True):
        truth_ids = sorted(step.visible & step.present.keys())
        truth_xy = np.array([step.present[t] for t in truth_ids], dtype=np.float64).reshape(-1, 2)
        hidden_xy = np.array([xy for t, xy in step.present.items() if t not in step.visible]).reshape(-1, 2)
        hyp_names = sorted(people)
        hyp_xy = np.array([people[h] for h in hyp_names], dtype=np.float64).reshape(-1, 2)
        keep = _not_hidden(hyp_xy, truth_xy, hidden_xy, gate_m)
        hyp_ids = [numbers.setdefault(h, len(numbers) + 1) for h, k in zip(hyp_names, keep, strict=True) if k]
        hyp_xy = hyp_xy[keep]
        reported_total += len(hyp_ids)
        distances = mm.distances.norm2squared_matrix(truth_xy, hyp_xy, max_d2=gate_m ** 2)
        frame = accumulator.update(truth_ids, hyp_ids, distances)
        frames.append((frame, truth_ids, truth_xy, hyp_ids, hyp_xy))
    events = accumulator.mot_events
    duplicates = sum(_duplicates(events, *frame, gate_m) for frame in frames)
    host = mm.metrics.create()
    names = ["mota", "idf1", "idp", "idr", "num_switches", "motp", "precision", "recall",
             "num_false_positives", "num_misses", "num_objects", "num_predictions", "num_unique_objects",
             "mostly_tracked", "mostly_lost", "num_fragmentations"]
    summary = host.compute(accumulator, metrics=names, name="sequence").iloc[0]
    value = {name: float(summary[name]) for name in names}
    return {
        "gate_m": gate_m,
        "mota": value["mota"], "idf1": value["idf1"], "idp": value["idp"], "idr": value["idr"],
        "id_switches": int(value["num_switches"]),
        "motp_m": float(np.sqrt(value["motp"])) if np.isfinite(value["motp"]) else None,
        "precision": value["precision"], "recall": value["recall"],
        "false_positives": int(value["num_false_positives"]), "misses": int(value["num_misses"]),
        "true_people_steps": int(value["num_objects"]), "reported_people_steps": reported_total,
        "true_tracks": int(value["num_unique_objects"]), "mostly_tracked": int(value["mostly_tracked"]),
        "mostly_lost": int(value["mostly_lost"]), "fragmentations": int(value["num_fragmentations"]),
        "duplicates": duplicates,
        "duplicate_rate": duplicates / reported_total if reported_total else 0.0,
    }


def _not_hidden(hyp_xy: FloatArray, truth_xy: FloatArray, hidden_xy: FloatArray, gate_m: float
                ) -> NDArray[np.bool_]:
    """(H,) False for reported people nearer a hidden true person (within the gate) than any seen one."""
    if not len(hidden_xy) or not len(hyp_xy):
        return np.ones(len(hyp_xy), bool)
    to_hidden = np.linalg.norm(hyp_xy[:, None] - hidden_xy[None], axis=2).min(axis=1)
    to_seen = (np.linalg.norm(hyp_xy[:, None] - truth_xy[None], axis=2).min(axis=1) if len(truth_xy)
               else np.full(len(hyp_xy), np.inf))
    return np.asarray(~((to_hidden <= gate_m) & (to_hidden < to_seen)))


def _duplicates(events: Any, frame: int, truth_ids: list[int], truth_xy: FloatArray, hyp_ids: list[int],
                hyp_xy: FloatArray, gate_m: float) -> int:
    """Unmatched reported people of `frame` within the gate of a matched true person."""
    if not len(hyp_ids) or not len(truth_ids) or frame not in events.index.get_level_values(0):
        return 0
    mine = events.loc[frame]
    matched_truth = {int(o) for o in mine[mine.Type.isin(["MATCH", "SWITCH"])].OId}
    false_ids = {int(h) for h in mine[mine.Type == "FP"].HId}
    taken = np.array([xy for t, xy in zip(truth_ids, truth_xy, strict=True)
                      if t in matched_truth]).reshape(-1, 2)
    if not len(taken):
        return 0
    return sum(1 for h, xy in zip(hyp_ids, hyp_xy, strict=True)
               if h in false_ids and np.linalg.norm(taken - xy, axis=1).min() <= gate_m)


def score_detections(sequence: Sequence, reported: Reported, gate_m: float = GATE_M
                     ) -> dict[str, Any] | None:
    """What the detector fed the tracker, frame by frame (None when it was not recorded): each
    frame's detections matched one to one to the people it shows fairly (within the gate), the
    unmatched ones near such a person (a second detection of one person) or elsewhere, and how far
    apart the cameras of one step place the same person."""
    from scipy.optimize import linear_sum_assignment  # evaluation only, like motmetrics

    if not reported.detections:
        return None
    frames = {(k, f.camera_id): f for k, step in enumerate(sequence.steps) for f in step.frames}
    matched = missed = near = elsewhere = 0
    placed: dict[tuple[int, int], list[FloatArray]] = {}
    for step, camera_id, positions in reported.detections:
        people = [p for p in frames[(step, camera_id)].people if not p.ignore]
        found = np.array(positions, dtype=np.float64).reshape(-1, 2)
        truth = np.array([p.site_xy_m for p in people], dtype=np.float64).reshape(-1, 2)
        gaps = np.linalg.norm(found[:, None] - truth[None], axis=2)
        rows, cols = linear_sum_assignment(np.where(gaps <= gate_m, gaps, 1e6)) if gaps.size else ([], [])
        pairs = [(r, c) for r, c in zip(rows, cols, strict=True) if gaps[r, c] <= gate_m]
        matched += len(pairs)
        missed += len(truth) - len(pairs)
        used = {r for r, _ in pairs}
        for r in range(len(found)):
            if r not in used:
                near_someone = bool(len(truth)) and float(gaps[r].min()) <= gate_m
                near, elsewhere = near + near_someone, elsewhere + (not near_someone)
        for r, c in pairs:
            placed.setdefault((step, people[c].track_id), []).append(found[r])
    spread = [float(np.linalg.norm(np.ptp(np.array(p), axis=0))) for p in placed.values() if len(p) > 1]
    count = len(reported.detections)
    return {
        "frames": count,
        "precision": matched / max(matched + near + elsewhere, 1),
        "recall": matched / max(matched + missed, 1),
        "extra_near_a_person_per_frame": near / count, "elsewhere_per_frame": elsewhere / count,
        "camera_spread_m": None if not spread else {
            "p50": float(np.percentile(spread, 50)), "p90": float(np.percentile(spread, 90)),
            "max": float(np.max(spread)), "people_steps": len(spread)},
    }


def score_sequence(sequence: Sequence, reported: Reported, gate_m: float = GATE_M) -> dict[str, Any]:
    """Every figure of the module docstring, and `detections` (`score_detections`)."""
    return {**score_tracks(sequence, reported, gate_m), **score_zones(sequence, reported),
            **score_lines(sequence, reported), "detections": score_detections(sequence, reported, gate_m)}
