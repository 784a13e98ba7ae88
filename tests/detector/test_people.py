from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from detector.metrics import EvalFrame
from detector.people import (
    FOUND,
    LOOSE_BOX,
    LOW_SCORE,
    MISSED,
    frame_outcomes,
    person_outcomes,
    summarise_outcomes,
    write_outcomes_csv,
)
from fisheye import camera_from_dict

# An ideal equidistant lens, 100 px per radian (image circle 157 px), principal point at the centre.
CAMERA = camera_from_dict({"id": "hand", "altitude_m": 3.0, "image_size": [400, 400],
                           "principal_point": [199.5, 199.5], "focal_px": [100.0, 100.0], "kb": [1.0]})
PP = CAMERA.principal_point
ABOVE = [199.5, 99.5, 20.0, 40.0]  # 100 px above the principal point: the middle ring
RIGHT = [339.5, 199.5, 20.0, 40.0]  # 140 px right: the rim
BELOW = [199.5, 209.5, 20.0, 40.0]  # 10 px below: under the lens
LEFT = [99.5, 199.5, 20.0, 40.0]


def _frame(gt: list[list[float]], dets: list[list[float]], scores: list[float],
           min_score: float | None = 0.5) -> EvalFrame:
    gt_boxes = np.array(gt, dtype=float).reshape(-1, 4)
    return EvalFrame(gt_boxes, np.full((len(gt_boxes), 2), np.nan), np.full(len(gt_boxes), np.nan),
                     np.array(dets, dtype=float).reshape(-1, 4), np.array(scores, dtype=float), PP, CAMERA,
                     min_score=min_score)


def _longer(box: list[float], factor: float) -> list[float]:
    """The same box, `factor` times as long along the ray: IoU 1 / factor with it."""
    return [box[0], box[1], box[2], box[3] * factor]


def test_each_outcome_by_hand() -> None:
    frame = _frame([ABOVE, RIGHT, BELOW, LEFT],
                   [ABOVE, RIGHT, _longer(BELOW, 2.5)], [0.9, 0.3, 0.8])
    rows = frame_outcomes(frame, "f")
    # ABOVE matched above the threshold; RIGHT only by a detection below it; BELOW's box is
    # 2.5× too long (IoU 0.4); nothing is near LEFT.
    assert [r.outcome for r in rows] == [FOUND, LOW_SCORE, LOOSE_BOX, MISSED]
    assert [r.person for r in rows] == [0, 1, 2, 3] and {r.frame for r in rows} == {"f"}
    assert rows[2].best_iou == pytest.approx(0.4, abs=1e-6)
    assert rows[2].best_score == pytest.approx(0.8) and rows[2].det_along_px == pytest.approx(100.0)
    assert rows[1].radius_px == pytest.approx(140.0)
    assert rows[1].radius_fraction == pytest.approx(140.0 / CAMERA.image_circle_radius_px())
    assert (rows[0].along_px, rows[0].across_px) == (40.0, 20.0)
    assert rows[3].best_iou == 0.0
    # the threshold given overrides the frame's own: at 0.2, RIGHT is found too
    assert frame_outcomes(frame, "f", min_score=0.2)[1].outcome == FOUND


def test_a_detection_counts_for_one_person_only() -> None:
    """Two people in one place and one detection: the one it matches is found; the other, which it
    overlaps as well, is reported as overlapped by a detection below the threshold (the
    detection's score is what it is), never found twice."""
    rows = frame_outcomes(_frame([ABOVE, ABOVE], [ABOVE], [0.9]), "f")
    assert sorted(r.outcome for r in rows) == [FOUND, LOW_SCORE]


def test_frames_without_people_or_detections() -> None:
    assert frame_outcomes(_frame([], [ABOVE], [0.9]), "f") == []
    rows = frame_outcomes(_frame([ABOVE], [], []), "f")
    assert [r.outcome for r in rows] == [MISSED]
    assert rows[0].best_iou == 0.0 and math.isnan(rows[0].best_score) and math.isnan(rows[0].det_along_px)


def test_summary_by_ring_and_frame_and_the_csv(tmp_path: Path) -> None:
    frames = [_frame([ABOVE, RIGHT, BELOW], [ABOVE, _longer(RIGHT, 2.5)], [0.9, 0.9]),
              _frame([LEFT], [], [])]
    rows = person_outcomes(frames, ["a", "b"])
    summary = summarise_outcomes(rows)
    assert summary["all"] == {"people": 4, FOUND: 1, LOW_SCORE: 0, LOOSE_BOX: 1, MISSED: 2}
    assert summary["ring:nadir"] == {"people": 1, FOUND: 0, LOW_SCORE: 0, LOOSE_BOX: 0, MISSED: 1}
    assert summary["ring:middle"]["people"] == 2 and summary["ring:rim"][LOOSE_BOX] == 1
    assert summary["frame:a"]["people"] == 3 and summary["frame:b"] == {
        "people": 1, FOUND: 0, LOW_SCORE: 0, LOOSE_BOX: 0, MISSED: 1}
    path = tmp_path / "people.csv"
    write_outcomes_csv(rows, path)
    read = list(csv.DictReader(path.read_text().splitlines()))
    assert [r["outcome"] for r in read] == [r.outcome for r in rows]
    assert read[0]["frame"] == "a" and float(read[0]["best_iou"]) == 1.0
    assert read[3]["best_score"] == "" and read[3]["distance_m"] == ""  # NaN: empty
    with pytest.raises(ValueError):
        person_outcomes(frames, ["a"])


def test_fishloc_eval_writes_each_persons_outcome(tmp_path: Path) -> None:
    """`fishloc eval --people` writes a row per annotated person of a real file and the counts
    into the JSON, which add up to the people the metrics count."""
    from models import DEFAULT_MODEL_PATH
    from service.cli import main

    cv2.imwrite(str(tmp_path / "empty.png"), np.full((400, 400, 3), 90, np.uint8))
    data = tmp_path / "cepdof.json"
    data.write_text(json.dumps({
        "images": [{"id": "e", "file_name": "empty.png", "width": 400, "height": 400}],
        "annotations": [{"id": k, "image_id": "e", "category_id": 1,
                         "bbox": [120.0 + 40 * k, 120.0, 20.0, 50.0, 0.0]} for k in range(3)],
    }))
    out, people = tmp_path / "metrics.json", tmp_path / "people.csv"
    assert main(["eval", "--model", str(DEFAULT_MODEL_PATH), "--data", str(data), "--json", str(out),
                 "--people", str(people)]) == 0
    metrics = json.loads(out.read_text())
    counts = metrics["people"]["all"]
    assert counts["people"] == metrics["num_gt"] == 3
    assert sum(counts[o] for o in (FOUND, LOW_SCORE, LOOSE_BOX, MISSED)) == 3
    assert counts[FOUND] == round(metrics["recall"] * 3)  # nobody stands in a grey frame
    rows = list(csv.DictReader(people.read_text().splitlines()))
    assert [(r["frame"], r["person"]) for r in rows] == [("e", "0"), ("e", "1"), ("e", "2")]
