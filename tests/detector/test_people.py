from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from detector.drawing import DETECTION, FALSE_POSITIVE, OUTCOME_COLOURS, draw_evaluated
from detector.metrics import EvalFrame
from detector.people import (
    BACKGROUND,
    DUPLICATE,
    FOUND,
    LOOSE,
    LOOSE_BOX,
    LOW_SCORE,
    MISSED,
    FalsePositive,
    PersonOutcome,
    breakdown,
    frame_breakdown,
    summarise_outcomes,
    write_rows_csv,
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


def frame_outcomes(frame: EvalFrame, name: str, min_score: float | None = None) -> list[PersonOutcome]:
    return frame_breakdown(frame, name, min_score)[0]


def frame_false_positives(frame: EvalFrame, name: str, min_score: float | None = None) -> list[FalsePositive]:
    return frame_breakdown(frame, name, min_score)[1]


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
    assert (rows[1].x_px, rows[1].y_px) == (RIGHT[0], RIGHT[1])  # where to find them in the frame
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


def test_each_kind_of_false_positive_by_hand() -> None:
    # ABOVE found twice (the second a duplicate), RIGHT boxed 2.5× too long (IoU 0.4), a box where
    # nobody stands, and one more where nobody stands below the threshold (not a false positive).
    frame = _frame([ABOVE, RIGHT], [ABOVE, ABOVE, _longer(RIGHT, 2.5), LEFT, BELOW],
                   [0.9, 0.8, 0.7, 0.6, 0.2])
    errors = frame_false_positives(frame, "f")
    assert [(e.kind, e.rank) for e in errors] == [(DUPLICATE, 1), (LOOSE, 2), (BACKGROUND, 3)]
    assert errors[0].best_iou == pytest.approx(1.0) and errors[1].best_iou == pytest.approx(0.4, abs=1e-6)
    assert errors[2].best_iou == 0.0 and errors[2].score == pytest.approx(0.6)
    assert errors[1].along_px == pytest.approx(100.0) and errors[1].radius_px == pytest.approx(140.0)
    assert (errors[2].x_px, errors[2].y_px) == (LEFT[0], LEFT[1])
    # at 0.1 the box below the lens counts too; at 0.95 nothing does
    assert [e.kind for e in frame_false_positives(frame, "f", min_score=0.1)][-1] == BACKGROUND
    assert frame_false_positives(frame, "f", min_score=0.95) == []


def test_a_detection_on_a_crowd_box_is_no_false_positive() -> None:
    frame = EvalFrame(np.zeros((0, 4)), np.zeros((0, 2)), np.zeros(0), np.array([ABOVE]), np.array([0.9]),
                      PP, CAMERA, crowd_boxes=np.array([ABOVE]), min_score=0.5)
    assert frame_false_positives(frame, "f") == []


def test_frames_without_people_or_detections() -> None:
    assert frame_outcomes(_frame([], [ABOVE], [0.9]), "f") == []
    assert [e.kind for e in frame_false_positives(_frame([], [ABOVE], [0.9]), "f")] == [BACKGROUND]
    assert frame_false_positives(_frame([ABOVE], [], []), "f") == []
    rows = frame_outcomes(_frame([ABOVE], [], []), "f")
    assert [r.outcome for r in rows] == [MISSED]
    assert rows[0].best_iou == 0.0 and math.isnan(rows[0].best_score) and math.isnan(rows[0].det_along_px)


def test_summary_by_ring_and_frame_and_the_csv(tmp_path: Path) -> None:
    frames = [_frame([ABOVE, RIGHT, BELOW], [ABOVE, _longer(RIGHT, 2.5)], [0.9, 0.9]),
              _frame([LEFT], [RIGHT], [0.9])]
    rows, errors = breakdown(frames, ["a", "b"])
    summary = summarise_outcomes(rows, errors)
    assert summary["all"] == {"people": 4, FOUND: 1, LOW_SCORE: 0, LOOSE_BOX: 1, MISSED: 2,
                              "false_positives": 2, DUPLICATE: 0, LOOSE: 1, BACKGROUND: 1}
    assert summary["ring:nadir"] == {"people": 1, FOUND: 0, LOW_SCORE: 0, LOOSE_BOX: 0, MISSED: 1,
                                     "false_positives": 0, DUPLICATE: 0, LOOSE: 0, BACKGROUND: 0}
    assert summary["ring:middle"]["people"] == 2 and summary["ring:rim"][LOOSE_BOX] == 1
    assert summary["ring:rim"]["false_positives"] == 2  # both at RIGHT, 140 of 157 px out
    assert summary["frame:a"]["people"] == 3 and summary["frame:b"] == {
        "people": 1, FOUND: 0, LOW_SCORE: 0, LOOSE_BOX: 0, MISSED: 1,
        "false_positives": 1, DUPLICATE: 0, LOOSE: 0, BACKGROUND: 1}
    # every person here is 20 x 40 px (28 px): small; so are both false positives (20 x 100, 20 x 40)
    assert summary["size:small"]["people"] == 4 and summary["size:small"]["false_positives"] == 2
    assert summary["size:medium"]["people"] == summary["size:large"]["false_positives"] == 0
    large = summarise_outcomes(breakdown([_frame([[199.5, 99.5, 80.0, 160.0]], [], [])], ["c"])[0])
    assert large["size:large"][MISSED] == 1 and large["size:small"]["people"] == 0  # 113 px
    empty = summarise_outcomes([])
    assert list(empty) == ["all", "ring:nadir", "ring:middle", "ring:rim", "size:small", "size:medium",
                           "size:large"]
    assert all(count == 0 for counts in empty.values() for count in counts.values())
    fp_path = tmp_path / "fp.csv"
    write_rows_csv(errors, fp_path, FalsePositive)
    assert [r["kind"] for r in csv.DictReader(fp_path.read_text().splitlines())] == [LOOSE, BACKGROUND]
    write_rows_csv([], fp_path, FalsePositive)
    assert fp_path.read_text().splitlines() == [",".join(FalsePositive.__dataclass_fields__)]
    path = tmp_path / "people.csv"
    write_rows_csv(rows, path, PersonOutcome)
    read = list(csv.DictReader(path.read_text().splitlines()))
    assert [r["outcome"] for r in read] == [r.outcome for r in rows]
    assert read[0]["frame"] == "a" and float(read[0]["best_iou"]) == 1.0
    assert float(read[3]["best_iou"]) == 0.0 and read[3]["distance_m"] == ""  # NaN: empty
    with pytest.raises(ValueError):
        breakdown(frames, ["a"])


def _near(image: np.ndarray, colour: tuple[int, int, int], x: float, y: float, reach: int = 4) -> bool:
    """Whether `colour` (BGR) is drawn within `reach` px of (x, y)."""
    x0, y0 = round(x), round(y)
    patch = image[max(0, y0 - reach):y0 + reach + 1, max(0, x0 - reach):x0 + reach + 1].astype(int)
    return bool(np.any(np.abs(patch - np.array(colour)).sum(axis=2) < 30))


def test_a_drawn_frame_shows_each_person_in_their_outcomes_colour() -> None:
    # ABOVE found, RIGHT found below the threshold, LEFT missed; one detection on nobody
    frame = _frame([ABOVE, RIGHT, LEFT], [ABOVE, RIGHT, [199.5, 320.5, 20.0, 40.0]], [0.9, 0.3, 0.8])
    outcomes, errors = frame_breakdown(frame, "f")
    assert [o.outcome for o in outcomes] == [FOUND, LOW_SCORE, MISSED] and len(errors) == 1
    image = draw_evaluated(np.full((400, 400, 3), 90, np.uint8), frame, outcomes, errors)
    assert image.shape == (400, 400, 3)
    # each person's box edge (the far end along the ray, 20 px from the centre) in their colour
    assert _near(image, OUTCOME_COLOURS[FOUND], 199.5, 79.5)
    assert _near(image, OUTCOME_COLOURS[LOW_SCORE], 359.5, 199.5)
    assert _near(image, OUTCOME_COLOURS[MISSED], 79.5, 199.5)
    assert _near(image, FALSE_POSITIVE, 199.5, 340.5)  # the detection on nobody
    assert not _near(image, DETECTION, 199.5, 340.5)
    assert not _near(image, OUTCOME_COLOURS[MISSED], 199.5, 340.5)
    big = draw_evaluated(np.full((3200, 2400, 3), 90, np.uint8), frame, outcomes, errors)
    assert big.shape == (1600, 1200, 3)  # the longer side at most 1600 px
    with pytest.raises(ValueError, match="outcomes"):
        draw_evaluated(np.full((400, 400, 3), 90, np.uint8), frame, outcomes[:2], errors)


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
    out, people, wrong = tmp_path / "metrics.json", tmp_path / "people.csv", tmp_path / "fp.csv"
    assert main(["eval", "--model", str(DEFAULT_MODEL_PATH), "--data", str(data), "--json", str(out),
                 "--people", str(people), "--false-positives", str(wrong),
                 "--draw", str(tmp_path / "drawn")]) == 0
    drawn = cv2.imread(str(tmp_path / "drawn" / "e.png"))
    assert drawn.shape == (400, 400, 3)  # the frame, its three people drawn missed (nobody stands there)
    assert all(_near(drawn, OUTCOME_COLOURS[MISSED], 130.0 + 40 * k, 120.0) for k in range(3))
    metrics = json.loads(out.read_text())
    counts = metrics["people"]["all"]
    assert counts["people"] == metrics["num_gt"] == 3
    assert sum(counts[o] for o in (FOUND, LOW_SCORE, LOOSE_BOX, MISSED)) == 3
    assert counts[FOUND] == round(metrics["recall"] * 3)  # nobody stands in a grey frame
    rows = list(csv.DictReader(people.read_text().splitlines()))
    assert [(r["frame"], r["person"]) for r in rows] == [("e", "0"), ("e", "1"), ("e", "2")]
    assert len(list(csv.DictReader(wrong.read_text().splitlines()))) == counts["false_positives"]
