from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from detector.metrics import (
    EvalFrame,
    average_precision,
    common_errors,
    compute_metrics,
    greedy_match,
    person_errors,
)
from fisheye import camera_from_dict, cepdof_to_radius_aligned, cxcywh_to_corners, polygon_iou
from fisheye.boxes import cepdof_to_corners

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


def test_the_reported_people_error_keeps_the_matches_at_the_threshold() -> None:
    # Two people, each matched by its own box: foot points 60 px (θ 0.6) and 100 px (θ 1.0) out,
    # the first at score 0.9, the second at 0.2, below the threshold 0.5.
    near, farther = [199.5, 119.5, 16.0, 40.0], [199.5, 79.5, 16.0, 40.0]
    frame = _frame([near, farther], [[0.0, 2.0], [0.0, 4.0]], [near, farther], [0.9, 0.2])
    errors = [abs(3 * math.tan(0.6) - 2.0), abs(3 * math.tan(1.0) - 4.0)]
    metrics = compute_metrics([frame], min_score=0.5)
    assert metrics["mPE"] == pytest.approx(sum(errors) / 2) and metrics["PE_matches"] == 2.0
    assert metrics["mPE_reported"] == pytest.approx(errors[0]) and metrics["PE_matches_reported"] == 1.0
    # With no threshold given, each frame's own operating threshold decides.
    own = compute_metrics([replace(frame, min_score=0.1)], min_score=None)
    assert own["mPE_reported"] == pytest.approx(own["mPE"]) and own["PE_matches_reported"] == 2.0
    nobody = compute_metrics([frame], min_score=0.95)
    assert math.isnan(nobody["mPE_reported"]) and nobody["PE_matches_reported"] == 0.0


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


# CEPDOF-style file boxes [cx, cy, w, h, angle_deg], 100 px above the principal point, where the ray
# points up: angle 0 would lie on it. Annotators draw sitting or leaning people off the ray.
LEANING = [199.5, 99.5, 24.0, 60.0, 40.0]  # 40° off the ray: its radius-aligned conversion is upright
SITTING = [199.5, 99.5, 30.0, 60.0, 44.0]
HUGS_SITTING = [199.5, 99.5, 58.0, 32.0]  # wide and short: covers the 44° box, not its conversion


def _file_frame(file_boxes: list[list[float]], dets: list[list[float]], scores: list[float],
                camera_assumed: bool = True) -> EvalFrame:
    cxcywha = np.array(file_boxes, dtype=float).reshape(-1, 5)
    g = len(cxcywha)
    return EvalFrame(cepdof_to_radius_aligned(cxcywha, PP), np.full((g, 2), np.nan), np.full(g, np.nan),
                     np.array(dets, dtype=float).reshape(-1, 4), np.array(scores, dtype=float), PP,
                     CAMERA, gt_corners=cepdof_to_corners(cxcywha), camera_assumed=camera_assumed)


def test_a_tilted_file_box_is_not_its_radius_aligned_conversion() -> None:
    file_corners = cepdof_to_corners(np.array([LEANING]))
    converted = cxcywh_to_corners(cepdof_to_radius_aligned(np.array([LEANING]), PP), PP)
    assert polygon_iou(file_corners, file_corners)[0, 0] == pytest.approx(1.0)
    assert polygon_iou(file_corners, converted)[0, 0] == pytest.approx(0.4456, abs=1e-4)


@pytest.mark.parametrize(("file_box", "detection", "expected", "radius_aligned"), [
    # The conversion itself: a perfect match radius-aligned, under IoU 0.5 with what was drawn.
    (LEANING, cepdof_to_radius_aligned(np.array([LEANING]), PP)[0].tolist(), (0.0, 0.0), (1.0, 1.0)),
    # A box that hugs the drawn one (IoU 0.53: a match at 0.50 only) but not its conversion (IoU 0.36).
    (SITTING, HUGS_SITTING, (1.0, 0.1), (0.0, 0.0)),
])
def test_file_boxes_are_the_headline_and_radius_aligned_scoring_is_reported_beside_it(
    file_box: list[float], detection: list[float], expected: tuple[float, float],
    radius_aligned: tuple[float, float],
) -> None:
    """(AP50, mAP) against the file's box and against its radius-aligned conversion."""
    metrics = compute_metrics([_file_frame([file_box], [detection], [0.9])], min_score=0.5)
    assert (metrics["AP50"], metrics["mAP"]) == pytest.approx(expected)
    assert (metrics["AP50_radius_aligned"], metrics["mAP_radius_aligned"]) == pytest.approx(radius_aligned)
    assert metrics["precision"] == metrics["recall"] == expected[0]
    assert metrics["precision_radius_aligned"] == metrics["recall_radius_aligned"] == radius_aligned[0]


def test_file_crowd_boxes_are_the_ignore_regions_of_file_box_frames() -> None:
    crowd_file = np.array([[299.5, 199.5, 30.0, 60.0, -46.0]])  # right of the centre, 44° off the ray
    hugs_crowd = [299.5, 199.5, 58.0, 32.0]
    frame = _file_frame([SITTING], [HUGS_SITTING, hugs_crowd], [0.6, 0.9])
    with_crowd = replace(frame, crowd_boxes=cepdof_to_radius_aligned(crowd_file, PP),
                         crowd_corners=cepdof_to_corners(crowd_file))
    metrics = compute_metrics([with_crowd], min_score=0.5)
    assert metrics["AP50"] == pytest.approx(1.0)  # the detection on the crowd counts neither way
    assert metrics["precision"] == 1.0
    assert metrics["AP50_radius_aligned"] == 0.0  # both miss the conversions
    assert metrics["precision_radius_aligned"] == 0.0


def test_frames_without_file_boxes_are_scored_as_before_and_add_no_keys() -> None:
    box = [199.5, 119.5, 16.0, 40.0]
    frame = _frame([box], [[0.0, 2.0]], [box, [199.5, 300.0, 10.0, 20.0]], [0.95, 0.5])
    metrics = compute_metrics([frame], min_score=0.3)
    assert not any(key.endswith("_radius_aligned") for key in metrics)
    # The same person given as its own file box (corners of the radius-aligned box) scores the same.
    as_file = replace(frame, gt_corners=cxcywh_to_corners(frame.gt_boxes, PP))
    both = compute_metrics([as_file], min_score=0.3)
    assert {k: v for k, v in both.items() if not k.endswith("_radius_aligned")} == pytest.approx(
        metrics, nan_ok=True)
    assert both["AP50_radius_aligned"] == metrics["AP50"] and both["mAP_radius_aligned"] == metrics["mAP"]


def test_an_assumed_camera_gives_no_floor_errors_or_distances() -> None:
    # Even a person with a position gets no error from a camera that is only assumed.
    box = [199.5, 119.5, 16.0, 40.0]
    measured = _frame([box], [[0.0, 2.0]], [box], [0.95])
    assert compute_metrics([measured], 0.3)["PE_matches"] == 1.0
    metrics = compute_metrics([replace(measured, camera_assumed=True)], 0.3)
    assert metrics["PE_matches"] == 0.0 and math.isnan(metrics["mPE"]) and math.isnan(metrics["mPE_center"])
    # A CEPDOF-like frame: no positions, no distances -> distance-binned AP and PE undefined.
    cepdof = compute_metrics([_file_frame([SITTING], [HUGS_SITTING], [0.9])], 0.5)
    assert all(math.isnan(cepdof[k]) for k in ("AP_near", "AP_mid", "AP_far", "mPE", "PE_near"))


def test_recall_of_the_people_below_the_lens() -> None:
    # The image circle (θ ≤ 90°) is 157 px in radius: within 0.2 of it is 31 px from the centre.
    below = [199.5, 214.5, 30.0, 30.0]  # 15 px out: seen from above
    out = [199.5, 119.5, 16.0, 40.0]  # 80 px out
    frames = [_frame([below, out], [[0.0, -0.4], [0.0, 2.0]], [out, below], [0.9, 0.2]),
              _frame([below], [[0.0, -0.4]], [below], [0.8])]
    metrics = compute_metrics(frames, min_score=0.5)
    assert metrics["recall_nadir"] == pytest.approx(0.5)  # the 0.2 detection is under the threshold
    assert compute_metrics(frames, min_score=0.1)["recall_nadir"] == pytest.approx(1.0)
    assert math.isnan(compute_metrics([_frame([out], [[0.0, 2.0]], [out], [0.9])], 0.5)["recall_nadir"])


def test_precision_and_recall_at_each_frames_own_threshold_unless_one_is_given() -> None:
    # Two frames, one person each found at 0.9; the second frame's view runs at 0.95 (its own
    # operating point): without a threshold given, each frame counts at its own.
    person = [199.5, 99.5, 20.0, 40.0]
    frame = _frame([person], [[0.0, 1.0]], [person], [0.9])
    frames = [replace(frame, min_score=0.5), replace(frame, min_score=0.95)]
    own = compute_metrics(frames, None)
    assert own["recall"] == pytest.approx(0.5) and own["precision"] == pytest.approx(1.0)
    assert compute_metrics(frames, 0.3)["recall"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="own operating threshold"):
        compute_metrics([frame], None)


def test_ap_at_low_iou_counts_a_person_found_with_a_loose_box() -> None:
    person = [199.5, 99.5, 20.0, 40.0]
    loose = [199.5, 99.5, 20.0, 40.0 * 0.4]  # the same centre, 0.4 of the length: IoU 0.4
    metrics = compute_metrics([_frame([person], [[0.0, 1.0]], [loose], [0.9])], min_score=0.5)
    assert metrics["AP50"] == 0.0
    assert metrics["AP30"] == pytest.approx(1.0) and metrics["AP10"] == pytest.approx(1.0)


def test_feet_compared_over_the_people_every_model_matches() -> None:
    # Three people. Model a finds the first two, each foot point a px off (a few cm on the floor);
    # model b finds all three, the first two placed exactly and the third (θ 1.4, 17 m out) 15 px
    # too far out, metres off. b's mPE is the larger, yet over the two people both find its feet
    # are the better ones.
    near, second, far = [199.5, 119.5, 16.0, 40.0], [279.5, 199.5, 40.0, 16.0], [199.5, 49.5, 16.0, 20.0]
    truth = [[0.0, 3 * math.tan(0.6)], [3 * math.tan(0.6), 0.0], [0.0, 3 * math.tan(1.4)]]
    frame = _frame([near, second, far], truth, [near, second, far], [0.9, 0.8, 0.7])
    exact = np.array([[199.5, 139.5], [259.5, 199.5], [199.5, 59.5]])  # 60, 60 and 140 px out
    off = exact.copy()
    off[:2, 1] -= 1.0
    model_a = replace(frame, det_boxes=frame.det_boxes[:2], det_scores=frame.det_scores[:2],
                      det_foot_px=off[:2])
    model_b = replace(frame, det_foot_px=exact + np.array([[0.0, 0.0], [0.0, 0.0], [0.0, -15.0]]))
    people_a, people_b = person_errors([model_a]), person_errors([model_b])
    assert sorted(people_a) == [(0, 0), (0, 1)] and sorted(people_b) == [(0, 0), (0, 1), (0, 2)]
    assert people_b[(0, 0)][0] == pytest.approx(0.0, abs=1e-9)
    assert people_a[(0, 0)][0] > 0.01
    common = common_errors({"a": people_a, "b": people_b})
    assert common["a"]["PE_matches_common"] == common["b"]["PE_matches_common"] == 2
    assert common["b"]["mPE_common"] < common["a"]["mPE_common"]
    metrics_a, metrics_b = compute_metrics([model_a], 0.5), compute_metrics([model_b], 0.5)
    assert metrics_b["mPE"] > metrics_a["mPE"]  # the far person's error counts in b's alone
    assert common["a"]["mPE_common"] == pytest.approx(metrics_a["mPE"])
    assert math.isnan(common["a"]["PE_far_common"])  # neither of the two stands past 20 m
    assert common_errors({"only": people_b})["only"]["mPE_common"] == pytest.approx(metrics_b["mPE"])
