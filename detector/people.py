"""Each annotated person's outcome in an evaluation (found, found below the threshold, boxed loosely,
or missed) and each false positive's kind (a duplicate, a loose box, background), with where they
are and what the best-overlapping box looked like.

AP says how many people a model finds; this says which ones it does not and why, and what its
false positives are, so a design can be aimed at them (the rim's small people, seated people boxed
as if they stood, crowds), as TIDE breaks COCO's errors down. Matching is the metrics' own
(`detector.metrics`): file boxes where the frame has them, greedy at IoU 0.5 by score, among the
same top detections AP counts; detections on crowd boxes count neither way.
"""

from __future__ import annotations

import csv
import math
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
# a false positive (at or above the threshold, matched to nobody at IoU 0.5) that overlaps ...
DUPLICATE = "duplicate"  # ... at IoU ≥ 0.5 a person a higher-scoring detection took
LOOSE = "loose"  # ... a person at IoU 0.3–0.5 (a badly fitted box; the person may be a loose_box)
BACKGROUND = "background"  # ... nobody at IoU 0.3
FALSE_POSITIVES = (DUPLICATE, LOOSE, BACKGROUND)
LOOSE_IOU = 0.3
# rings of the image circle's radius the summary counts by: below the lens, the middle, the rim
RINGS = {"nadir": (0.0, NADIR_FRACTION), "middle": (NADIR_FRACTION, 0.7), "rim": (0.7, np.inf)}
# sizes of people and of false positives' boxes the summary counts by (`size_px`): under 48 px,
# the rim's people of a 1 MP frame, whom a view too small for them loses
SIZES = {"small": (0.0, 48.0), "medium": (48.0, 96.0), "large": (96.0, np.inf)}


@dataclass(frozen=True)
class PersonOutcome:
    """One annotated person: `frame` (the frame's name), `person` (its index there), `outcome` (one
    of OUTCOMES), the box centre's radius in px and as a fraction of the image circle's
    (`radius_fraction`, NaN without a camera), the centre itself (`x_px`, `y_px`, frame px, to find
    them in the frame), `distance_m` from the nadir (NaN when unknown), the
    radius-aligned box `along_px` × `across_px` (along the ray, across it), and the detection of
    highest IoU with them among those AP counts: `best_iou`, its `best_score`, its box
    `det_along_px` × `det_across_px` (NaN when the frame has no detection)."""

    frame: str
    person: int
    outcome: str
    radius_px: float
    radius_fraction: float
    x_px: float
    y_px: float
    distance_m: float
    along_px: float
    across_px: float
    best_iou: float
    best_score: float
    det_along_px: float
    det_across_px: float


@dataclass(frozen=True)
class FalsePositive:
    """One detection at or above the threshold that matches nobody: `frame`, its `rank` by score in
    the frame, `kind` (one of FALSE_POSITIVES), `score`, the box centre's radius in px and as a
    fraction of the image circle's, the centre itself (`x_px`, `y_px`, frame px), its box `along_px`
    × `across_px`, and its highest IoU with any person (`best_iou`)."""

    frame: str
    rank: int
    kind: str
    score: float
    radius_px: float
    radius_fraction: float
    x_px: float
    y_px: float
    along_px: float
    across_px: float
    best_iou: float


def _radii(frame: EvalFrame, boxes: np.ndarray) -> tuple[np.ndarray, float]:
    """(N,) px from the principal point of `boxes`' centres, and the image circle's radius (NaN
    without a camera)."""
    offset = boxes[:, :2] - np.asarray(frame.principal_point, dtype=np.float64)
    circle_px = frame.camera.image_circle_radius_px() if frame.camera is not None else np.nan
    return np.hypot(offset[:, 0], offset[:, 1]), circle_px


def frame_breakdown(frame: EvalFrame, name: str, min_score: float | None = None
                    ) -> tuple[list[PersonOutcome], list[FalsePositive]]:
    """The outcome of each person of `frame` and each of its false positives, at `min_score` (None:
    the frame's own threshold), from one matching."""
    match = prepare_match(frame)
    matched = greedy_match(match.iou, 0.5)
    scores = frame.det_scores[match.order]
    boxes = frame.det_boxes[match.order]
    above = scores >= frame_threshold(frame, min_score)
    found = np.zeros(len(frame.gt_boxes), dtype=bool)
    found[matched[above & (matched >= 0)]] = True
    return (_outcomes(frame, name, match.iou, found, scores, boxes),
            _false_positives(frame, name, match.iou, above & (matched < 0) & ~match.ignored(matched, 0.5),
                             scores, boxes))


def _outcomes(frame: EvalFrame, name: str, iou: np.ndarray, found: np.ndarray, scores: np.ndarray,
              boxes: np.ndarray) -> list[PersonOutcome]:
    """Each person's outcome from the (D, G) `iou` of the score-sorted detections (`scores`,
    `boxes`) with the people and whether each was `found` (G,)."""
    radius_px, circle_px = _radii(frame, frame.gt_boxes)
    rows = []
    for g in range(len(frame.gt_boxes)):
        best = int(np.argmax(iou[:, g])) if len(iou) else -1
        best_iou = float(iou[best, g]) if best >= 0 else 0.0
        if found[g]:
            outcome = FOUND
        elif best_iou >= 0.5:
            outcome = LOW_SCORE
        elif best_iou >= LOOSE_IOU:
            outcome = LOOSE_BOX
        else:
            outcome = MISSED
        det = boxes[best] if best >= 0 else np.full(4, np.nan)
        rows.append(PersonOutcome(
            frame=name, person=g, outcome=outcome, radius_px=float(radius_px[g]),
            radius_fraction=float(radius_px[g] / circle_px), x_px=float(frame.gt_boxes[g, 0]),
            y_px=float(frame.gt_boxes[g, 1]), distance_m=float(frame.gt_distances_m[g]),
            along_px=float(frame.gt_boxes[g, 3]), across_px=float(frame.gt_boxes[g, 2]),
            best_iou=best_iou, best_score=float(scores[best]) if best >= 0 else float("nan"),
            det_along_px=float(det[3]), det_across_px=float(det[2])))
    return rows


def _false_positives(frame: EvalFrame, name: str, iou: np.ndarray, false: np.ndarray, scores: np.ndarray,
                     boxes: np.ndarray) -> list[FalsePositive]:
    """Each `false` (D,) detection of the score-sorted ones (`scores`, `boxes`), its kind from its
    row of the (D, G) `iou`."""
    radius_px, circle_px = _radii(frame, boxes)
    rows = []
    for d in np.flatnonzero(false):
        best_iou = float(iou[d].max()) if iou.shape[1] else 0.0
        if best_iou >= 0.5:  # unmatched at 0.5, so every person it overlaps so was taken before it
            kind = DUPLICATE
        elif best_iou >= LOOSE_IOU:
            kind = LOOSE
        else:
            kind = BACKGROUND
        rows.append(FalsePositive(
            frame=name, rank=int(d), kind=kind, score=float(scores[d]), radius_px=float(radius_px[d]),
            radius_fraction=float(radius_px[d] / circle_px), x_px=float(boxes[d, 0]), y_px=float(boxes[d, 1]),
            along_px=float(boxes[d, 3]),
            across_px=float(boxes[d, 2]), best_iou=best_iou))
    return rows


def breakdown(frames: Sequence[EvalFrame], names: Sequence[str], min_score: float | None = None
              ) -> tuple[list[PersonOutcome], list[FalsePositive]]:
    """Every person's outcome and every false positive of every frame (`names` parallel to
    `frames`)."""
    outcomes: list[PersonOutcome] = []
    errors: list[FalsePositive] = []
    for frame, name in zip(frames, names, strict=True):
        people, wrong = frame_breakdown(frame, name, min_score)
        outcomes += people
        errors += wrong
    return outcomes, errors


def size_px(row: PersonOutcome | FalsePositive) -> float:
    """A person's or a false positive's size in frame px: the square root of its box's along x across."""
    return math.sqrt(row.along_px * row.across_px)


def summarise_outcomes(rows: Sequence[PersonOutcome], errors: Sequence[FalsePositive] = ()
                       ) -> dict[str, dict[str, int]]:
    """Counts of each outcome and each kind of false positive: overall (`all`), by ring of the
    image circle (`ring:nadir`, ... of RINGS; frames without a camera in none), by size
    (`size:small`, ... of SIZES, `size_px`) and by frame (`frame:NAME`)."""
    groups: dict[str, tuple[list[PersonOutcome], list[FalsePositive]]] = {"all": (list(rows), list(errors))}
    for ring, (low, high) in RINGS.items():
        groups[f"ring:{ring}"] = ([r for r in rows if low <= r.radius_fraction < high],
                                  [e for e in errors if low <= e.radius_fraction < high])
    for size, (low, high) in SIZES.items():
        groups[f"size:{size}"] = ([r for r in rows if low <= size_px(r) < high],
                                  [e for e in errors if low <= size_px(e) < high])
    for name in dict.fromkeys([r.frame for r in rows] + [e.frame for e in errors]):
        groups[f"frame:{name}"] = ([r for r in rows if r.frame == name],
                                   [e for e in errors if e.frame == name])
    summary = {}
    for key, (people, wrong) in groups.items():
        outcomes, kinds = Counter(r.outcome for r in people), Counter(e.kind for e in wrong)
        summary[key] = {"people": len(people), **{o: outcomes.get(o, 0) for o in OUTCOMES},
                        "false_positives": len(wrong), **{k: kinds.get(k, 0) for k in FALSE_POSITIVES}}
    return summary


def write_rows_csv(rows: Sequence[PersonOutcome] | Sequence[FalsePositive], path: str | Path,
                   row_type: type[PersonOutcome] | type[FalsePositive]) -> None:
    """One line per row of `row_type` (its fields as columns; floats to 4 decimals, NaN empty); the
    header alone when there are none."""
    fields = list(row_type.__dataclass_fields__)
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
