from __future__ import annotations

import math

import numpy as np
import pytest

from detector.metrics import EvalFrame, average_precision, compute_metrics, greedy_match
from fisheye import camera_from_dict

# An ideal equidistant lens, 100 px per radian, 3 m up, principal point at the centre of 400x400.
CAMERA = camera_from_dict({"id": "hand", "altitude_m": 3.0, "image_size": [400, 400],
                           "principal_point": [199.5, 199.5], "focal_px": [100.0, 100.0], "kb": [1.0]})
PP = CAMERA.principal_point


def _frame(gt: list[list[float]], locations: list[list[float]], dets: list[list[float]],
           scores: list[float]) -> EvalFrame:
    gt_boxes = np.array(gt, dtype=float).reshape(-1, 4)
    locations_m = np.array(locations, dtype=float).reshape(-1, 2)
    return EvalFrame(gt_boxes, locations_m, np.hypot(locations_m[:, 0], locations_m[:, 1]),
                     np.array(dets, dtype=float).reshape(-1, 4), np.array(scores, dtype=float), PP, CAMERA)


def test_average_precision_by_hand() -> None:
    # TP, FP, TP over 2 people: precision 1, 1/2, 2/3 at recall 1/2, 1/2, 1.
    # 101-point envelope: 51 points at 1.0 (recall <= 0.5), 50 points at 2/3.
    ap = average_precision(np.array([0.9, 0.8, 0.7]), np.array([True, False, True]), 2)
    assert ap == pytest.approx((51 + 50 * 2 / 3) / 101)
    assert math.isnan(average_precision(np.zeros(0), np.zeros(0, bool), 0))
    assert average_precision(np.zeros(0), np.zeros(0, bool), 3) == 0.0


def test_greedy_match_prefers_the_higher_iou_and_never_reuses_a_person() -> None:
    iou = np.array([[0.6, 0.9], [0.7, 0.8], [0.55, 0.0]])
    np.testing.assert_array_equal(greedy_match(iou, 0.5), [1, 0, -1])
    np.testing.assert_array_equal(greedy_match(iou, 0.75), [1, -1, -1])


def test_map_ap50_ap75_on_hand_made_detections() -> None:
    person = [199.5, 99.5, 20.0, 40.0]  # centre 100 px above the principal point
    shorter = [199.5, 99.5, 20.0, 40.0 * 0.78]  # same centre and width: IoU = 0.78
    frames = [_frame([person], [[0.0, 1.0]], [shorter], [0.9])]
    metrics = compute_metrics(frames, min_score=0.5)
    # TP at IoU thresholds 0.50 ... 0.75 (6 of 10), FP at 0.80 ... 0.95.
    assert metrics["AP50"] == pytest.approx(1.0)
    assert metrics["AP75"] == pytest.approx(1.0)
    assert metrics["mAP"] == pytest.approx(0.6)
    assert metrics["precision"] == 1.0 and metrics["recall"] == 1.0


def test_foot_point_and_centre_errors_by_hand() -> None:
    # Box centre 80 px above the principal point, h = 40: foot point 60 px away -> θ = 0.6 rad,
    # floor distance 3·tan(0.6) along +y (image up); the centre 80 px away -> 3·tan(0.8).
    box = [199.5, 119.5, 16.0, 40.0]
    frames = [_frame([box], [[0.0, 2.0]], [box], [0.95])]
    metrics = compute_metrics(frames, min_score=0.3)
    assert metrics["mPE"] == pytest.approx(abs(3 * math.tan(0.6) - 2.0), abs=1e-6)
    assert metrics["mPE_center"] == pytest.approx(abs(3 * math.tan(0.8) - 2.0), abs=1e-6)
    assert metrics["PE_near"] == pytest.approx(metrics["mPE"])
    assert math.isnan(metrics["PE_far"]) and math.isnan(metrics["AP_far"])


def test_distance_bins_precision_and_recall() -> None:
    near = [199.5, 119.5, 16.0, 40.0]  # person about 2 m out
    far_radius = 145.0  # 3·tan(1.45) ≈ 24.7 m from the nadir
    far = [199.5 + far_radius, 199.5, 6.0, 10.0]
    far_xy = [25.0, 0.0]
    false_alarm = [199.5, 330.0, 10.0, 20.0]
    frames = [
        _frame([near, far], [[0.0, 2.0], far_xy], [near, false_alarm], [0.9, 0.8]),
        _frame([near], [[0.0, 2.0]], [near], [0.7]),
    ]
    metrics = compute_metrics(frames, min_score=0.75)
    # Near bin: both near people found before any near false alarm (the false alarm is ~4 m out).
    # Its detections: TP 0.9, FP 0.8, TP 0.7 over 2 people -> the hand AP above.
    assert metrics["AP_near"] == pytest.approx((51 + 50 * 2 / 3) / 101)
    assert metrics["AP_far"] == 0.0  # one far person, never found
    assert math.isnan(metrics["AP_mid"])  # nobody 10-20 m away
    # Overall: TP .9, FP .8, TP .7 over 3 people.
    assert metrics["AP50"] == pytest.approx((34 + 33 * 2 / 3) / 101)
    # At 0.75: detections 0.9 (TP) and 0.8 (FP) -> precision 1/2, recall 1/3.
    assert metrics["precision"] == pytest.approx(0.5) and metrics["recall"] == pytest.approx(1 / 3)
    assert metrics["num_gt"] == 3


def test_detections_on_crowd_boxes_count_neither_way() -> None:
    person = [199.5, 119.5, 16.0, 40.0]
    hidden = [260.0, 199.5, 12.0, 30.0]
    frame = _frame([person], [[0.0, 2.0]], [person, hidden], [0.6, 0.9])
    with_crowd = EvalFrame(frame.gt_boxes, frame.gt_locations_m, frame.gt_distances_m, frame.det_boxes,
                           frame.det_scores, PP, CAMERA, crowd_boxes=np.array([hidden]))
    assert compute_metrics([frame], 0.5)["AP50"] == pytest.approx(0.5)  # FP 0.9 before TP 0.6
    metrics = compute_metrics([with_crowd], 0.5)
    assert metrics["AP50"] == pytest.approx(1.0)
    assert metrics["precision"] == 1.0 and metrics["recall"] == 1.0
