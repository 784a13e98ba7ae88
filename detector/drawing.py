"""A frame as the evaluation saw it (`fishloc eval --draw`): who was found, who was not, and why.

Each annotated person's own box is drawn in the colour of their outcome (`detector.people`):
found green, found below the threshold yellow, boxed loosely orange, missed red. Detections at or
above the frame's threshold are blue, or magenta where they match nobody (the false positives of
`--false-positives`), each with its score; those under it, down to `DRAW_MIN_SCORE`, are thin grey
lines, so a person found below the threshold shows the box that would have found them. The
principal point is a white dot. The frame is scaled so its longer side is at most `MAX_SIDE_PX`.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from detector.metrics import EvalFrame, frame_threshold
from detector.people import FOUND, LOOSE_BOX, LOW_SCORE, MISSED, FalsePositive, PersonOutcome
from fisheye.boxes import cxcywh_to_corners

DRAW_MIN_SCORE = 0.1  # detections under the threshold drawn down to this score
MAX_SIDE_PX = 1600

# BGR
OUTCOME_COLOURS = {FOUND: (0, 200, 0), LOW_SCORE: (0, 220, 255), LOOSE_BOX: (0, 140, 255),
                   MISSED: (0, 0, 255)}
DETECTION = (255, 128, 0)
FALSE_POSITIVE = (255, 0, 255)
BELOW = (160, 160, 160)


def person_corners(frame: EvalFrame) -> NDArray[np.float64]:
    """(G, 4, 2) each person's box as the frame is scored against it: the file's own where it has
    them (`gt_corners`), else the radius-aligned box."""
    if frame.gt_corners is not None:
        return np.asarray(frame.gt_corners, dtype=np.float64)
    return cxcywh_to_corners(frame.gt_boxes, frame.principal_point).reshape(-1, 4, 2)


def draw_evaluated(frame_rgb: NDArray[np.uint8], frame: EvalFrame, outcomes: Sequence[PersonOutcome],
                   errors: Sequence[FalsePositive]) -> NDArray[np.uint8]:
    """The frame (H, W, 3) RGB with its people (`outcomes`, in the frame's order) and detections
    drawn -> a BGR image, its longer side at most MAX_SIDE_PX; ValueError where `outcomes` are not
    the frame's people."""
    if len(outcomes) != len(frame.gt_boxes):
        raise ValueError(f"{len(outcomes)} outcomes for a frame of {len(frame.gt_boxes)} people")
    scale = min(1.0, MAX_SIDE_PX / max(frame_rgb.shape[:2]))
    size = (max(1, round(frame_rgb.shape[1] * scale)), max(1, round(frame_rgb.shape[0] * scale)))
    resized = cv2.resize(frame_rgb, size, interpolation=cv2.INTER_AREA)
    image: NDArray[np.uint8] = np.ascontiguousarray(cv2.cvtColor(resized, cv2.COLOR_RGB2BGR), dtype=np.uint8)
    thick = max(1, round(2 * scale / 0.6))

    def polygon(corners: NDArray[np.float64], colour: tuple[int, int, int], width: int) -> None:
        points = np.round((corners + 0.5) * scale - 0.5).astype(np.int32)
        cv2.polylines(image, [points], True, colour, width, lineType=cv2.LINE_AA)

    def label(corners: NDArray[np.float64], text: str, colour: tuple[int, int, int]) -> None:
        x, y = np.round(corners.min(axis=0) * scale).astype(int)
        cv2.putText(image, text, (int(x), max(10, int(y) - 3)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1,
                    cv2.LINE_AA)

    order = np.argsort(-frame.det_scores, kind="stable")  # the ranks of `FalsePositive`
    scores = frame.det_scores[order]
    corners = cxcywh_to_corners(frame.det_boxes[order], frame.principal_point).reshape(-1, 4, 2)
    threshold = frame_threshold(frame, None)
    false = {error.rank for error in errors}
    for rank in reversed(range(len(order))):  # the strongest drawn last, on top
        if scores[rank] < DRAW_MIN_SCORE:
            continue
        above = scores[rank] >= threshold
        colour = (FALSE_POSITIVE if rank in false else DETECTION) if above else BELOW
        polygon(corners[rank], colour, thick if above else 1)
        label(corners[rank], f"{scores[rank]:.2f}", colour)
    for person, box in zip(outcomes, person_corners(frame), strict=True):
        polygon(box, OUTCOME_COLOURS[person.outcome], thick)
    u, v = np.round((np.asarray(frame.principal_point) + 0.5) * scale - 0.5).astype(int)
    cv2.circle(image, (int(u), int(v)), 3, (255, 255, 255), -1)
    legend = [("found", OUTCOME_COLOURS[FOUND]), ("below threshold", OUTCOME_COLOURS[LOW_SCORE]),
              ("loose box", OUTCOME_COLOURS[LOOSE_BOX]), ("missed", OUTCOME_COLOURS[MISSED]),
              (f"detection >= {threshold:.3g}", DETECTION), ("false positive", FALSE_POSITIVE),
              (f"detection < {threshold:.3g}", BELOW)]
    for line, (text, colour) in enumerate(legend):
        cv2.putText(image, text, (8, 16 + 15 * line), cv2.FONT_HERSHEY_SIMPLEX, 0.45, colour, 1, cv2.LINE_AA)
    return image
