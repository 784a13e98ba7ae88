"""A model's operating point: its score threshold and rotated-NMS IoU, chosen together on
validation renders.

The network runs once per frame; every NMS IoU of `NMS_GRID` then post-processes the same raw
outputs exactly as the service does (`contract.select_detections`), and each gets its best-F1
threshold at IoU 0.5. The point of highest F1 is the model's `fishloc.default_min_score` and
`fishloc.nms_iou`. Real check frames never choose it (README, "Detector").

Why both: one person's cells give overlapping boxes, and a box only a little off its neighbours
(IoU 0.3–0.6 with the kept one) survives an NMS at 0.6 as a second detection at a high score;
that is where the 0.3.0 model's false positives on real frames came from (three of its three at
IoU 0.48–0.49 against a person already found). A lower NMS IoU removes them, which lets the
threshold come down and recall up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from detector.metrics import EvalFrame, compute_metrics, pr_curve

NMS_GRID = (0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65)
THRESHOLD_RANGE = (0.1, 0.9)  # a chosen threshold is clamped into it
NO_DETECTIONS_THRESHOLD = 0.3


@dataclass(frozen=True)
class SweptPoint:
    """One NMS IoU of a sweep with its best-F1 threshold, and what they score there."""

    nms_iou: float
    min_score: float
    f1: float
    precision: float
    recall: float
    ap50: float


def best_f1_threshold(frames: Sequence[EvalFrame]) -> float:
    """The score threshold of best F1 at IoU 0.5 (clamped to `THRESHOLD_RANGE`)."""
    precision, recall, scores = pr_curve(frames)
    if len(scores) == 0:
        return NO_DETECTIONS_THRESHOLD
    f1 = 2 * precision * recall / np.maximum(precision + recall, 1e-9)
    return float(np.clip(scores[int(np.argmax(f1))], *THRESHOLD_RANGE))


def sweep(frames_at: Any, grid: Sequence[float] = NMS_GRID) -> list[tuple[SweptPoint, list[EvalFrame]]]:
    """`frames_at(nms_iou)` -> EvalFrames for each IoU of `grid` -> each one's best-F1 point."""
    points = []
    for nms_iou in grid:
        evaluated = frames_at(nms_iou)
        threshold = best_f1_threshold(evaluated)
        metrics = compute_metrics(evaluated, threshold)
        precision, recall = metrics["precision"], metrics["recall"]
        f1 = 2 * precision * recall / max(precision + recall, 1e-9)
        points.append((SweptPoint(nms_iou, round(threshold, 3), f1, precision, recall, metrics["AP50"]),
                       evaluated))
    return points


def choose(points: Sequence[SweptPoint]) -> int:
    """The index of the point of highest F1 (the first of the grid on a tie)."""
    return int(np.argmax([point.f1 for point in points]))


def describe(points: Sequence[SweptPoint]) -> list[dict[str, Any]]:
    return [{k: round(v, 4) for k, v in asdict(p).items()} for p in points]
