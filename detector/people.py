"""Each annotated person's outcome in an evaluation: found, found below the threshold, boxed loosely,
or missed, with where they stand and what the best-overlapping detection looked like.

AP says how many people a model finds; this says which ones it does not and why, so a design can be
aimed at them (the rim's small people, seated people boxed as if they stood, crowds). Matching is
the metrics' own (`detector.metrics`): file boxes where the frame has them, greedy at IoU 0.5 by
score, among the same top detections AP counts.
"""

from __future__ import annotations

import csv
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from detector.metrics import NADIR_FRACTION, EvalFrame, frame_threshold, greedy_match, prepare_match

FOUND = "found"  # matched at IoU 0.5 by a detection at or above the frame's threshold
LOW_SCORE = "low_score"  # a detection below the threshold overlaps them at IoU ≥ 0.5
LOOSE_BOX = "loose_box"  # the best detection overlaps them at IoU 0.3–0.5: found, boxed badly
MISSED = "missed"  # no detection overlaps them at IoU 0.3
OUTCOMES = (FOUND, LOW_SCORE, LOOSE_BOX, MISSED)
LOOSE_IOU = 0.3
# rings of the image circle's radius the summary counts by: below the lens, the middle, the rim
RINGS = {"nadir": (0.0, NADIR_FRACTION), "middle": (NADIR_FRACTION, 0.7), "rim": (0.7, np.inf)}


@dataclass(frozen=True)
class PersonOutcome:
    """One annotated person: `frame` (the frame's name), `person` (its index there), `outcome` (one
    of OUTCOMES), the box centre's radius in px and as a fraction of the image circle's
    (`radius_fraction`, NaN without a camera), `distance_m` from the nadir (NaN when unknown), the
    radius-aligned box `along_px` × `across_px` (along the ray, across it), and the detection of
    highest IoU with them among those AP counts: `best_iou`, its `best_score`, its box
    `det_along_px` × `det_across_px` (NaN when the frame has no detection)."""

    frame: str
    person: int
    outcome: str
    radius_px: float
    radius_fraction: float
    distance_m: float
    along_px: float
    across_px: float
    best_iou: float
    best_score: float
    det_along_px: float
    det_across_px: float


def frame_outcomes(frame: EvalFrame, name: str, min_score: float | None = None) -> list[PersonOutcome]:
    """The outcome of each person of `frame` at `min_score` (None: the frame's own threshold)."""
    match = prepare_match(frame)
    matched = greedy_match(match.iou, 0.5)
    scores = frame.det_scores[match.order]
    above = scores >= frame_threshold(frame, min_score)
    found = np.zeros(len(frame.gt_boxes), dtype=bool)
    found[matched[above & (matched >= 0)]] = True
    offset = frame.gt_boxes[:, :2] - np.asarray(frame.principal_point, dtype=np.float64)
    radius_px = np.hypot(offset[:, 0], offset[:, 1])
    circle_px = frame.camera.image_circle_radius_px() if frame.camera is not None else np.nan
    rows = []
    for g in range(len(frame.gt_boxes)):
        ious = match.iou[:, g]
        best = int(np.argmax(ious)) if len(ious) else -1
        best_iou = float(ious[best]) if best >= 0 else 0.0
        if found[g]:
            outcome = FOUND
        elif best_iou >= 0.5:
            outcome = LOW_SCORE
        elif best_iou >= LOOSE_IOU:
            outcome = LOOSE_BOX
        else:
            outcome = MISSED
        det = frame.det_boxes[match.order[best]] if best >= 0 else np.full(4, np.nan)
        rows.append(PersonOutcome(
            frame=name, person=g, outcome=outcome, radius_px=float(radius_px[g]),
            radius_fraction=float(radius_px[g] / circle_px), distance_m=float(frame.gt_distances_m[g]),
            along_px=float(frame.gt_boxes[g, 3]), across_px=float(frame.gt_boxes[g, 2]),
            best_iou=best_iou, best_score=float(scores[best]) if best >= 0 else float("nan"),
            det_along_px=float(det[3]), det_across_px=float(det[2])))
    return rows


def person_outcomes(frames: Sequence[EvalFrame], names: Sequence[str], min_score: float | None = None
                    ) -> list[PersonOutcome]:
    """Every person of every frame (`names` parallel to `frames`)."""
    return [row for frame, name in zip(frames, names, strict=True)
            for row in frame_outcomes(frame, name, min_score)]


def summarise_outcomes(rows: Sequence[PersonOutcome]) -> dict[str, dict[str, int]]:
    """Counts of each outcome: overall (`all`), by ring of the image circle (RINGS; people of
    frames without a camera in none) and by frame."""
    groups: dict[str, list[PersonOutcome]] = {"all": list(rows)}
    for ring, (low, high) in RINGS.items():
        groups[f"ring:{ring}"] = [r for r in rows if low <= r.radius_fraction < high]
    for name in dict.fromkeys(r.frame for r in rows):
        groups[f"frame:{name}"] = [r for r in rows if r.frame == name]
    summary = {}
    for key, members in groups.items():
        counts = Counter(r.outcome for r in members)
        summary[key] = {"people": len(members), **{o: counts.get(o, 0) for o in OUTCOMES}}
    return summary


def write_outcomes_csv(rows: Sequence[PersonOutcome], path: str | Path) -> None:
    """One line per person, the columns of PersonOutcome (floats to 4 decimals, NaN empty)."""
    fields = list(PersonOutcome.__dataclass_fields__)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(v) for k, v in asdict(row).items()})


def _cell(value: object) -> object:
    if isinstance(value, float):
        return "" if not np.isfinite(value) else round(value, 4)
    return value
