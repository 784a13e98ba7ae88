"""The model's operating point (score threshold and NMS IoU in its metadata, chosen together on
validation frames) and the foot points fused over each kept detection's cluster."""

from __future__ import annotations

import numpy as np
import pytest
from polar_double import METADATA

from contract import ModelError, PolarInput, RawOutputs, parse_metadata, select_detections
from contract.detect import (
    FOOT_FUSION_IOU,
    FOOT_FUSION_SCORE,
    frame_candidates,
    longest_person,
    too_long,
    weighted_medians,
)
from contract.metadata import LEGACY_NMS_IOU
from contract.views import PlannedInput, strip_nms
from detector.metrics import EvalFrame
from detector.operating_point import choose, sweep
from fisheye import load_camera
from fisheye.polar import PolarGrid
from fisheye.view_plan import LongestPerson, ViewPlanConfig, plan_view

GRID = PolarGrid(principal_point=(255.5, 255.5), radius_px=250.0, height=64, width=256, overlap=32)
PP = GRID.principal_point


def test_nms_iou_is_read_from_the_metadata_and_defaults_to_the_legacy_value() -> None:
    assert parse_metadata(METADATA, "m.onnx").nms_iou == LEGACY_NMS_IOU == 0.6
    assert parse_metadata({**METADATA, "fishloc.nms_iou": "0.3"}, "m.onnx").nms_iou == 0.3


@pytest.mark.parametrize("value", ["0", "1.5", "nan", "-0.2", "half"])
def test_an_unusable_nms_iou_is_refused(value: str) -> None:
    with pytest.raises(ModelError, match=r"m\.onnx: unusable"):
        parse_metadata({**METADATA, "fishloc.nms_iou": value}, "m.onnx")


def _raw(boxes: list[list[float]], scores: list[float], feet: list[list[float]]) -> RawOutputs:
    return RawOutputs(np.asarray(boxes, dtype=np.float32), np.asarray(scores, dtype=np.float32),
                      np.asarray(feet, dtype=np.float32))


def test_a_kept_detection_stands_at_the_score_weighted_median_foot_of_its_cluster() -> None:
    raw = _raw(
        [[100, 20, 110, 40],   # a person's best cell
         [200, 10, 210, 30],   # another person
         [100, 21, 110, 41],   # the first person's other cells ...
         [100, 27, 110, 47],   # ... one suppressed by the NMS (IoU 0.48) but too far off to vote
         [101, 20, 111, 40],
         [100, 20, 110, 40]],  # ... one too weak to vote
        [0.9, 0.8, 0.6, 0.5, 0.4, 0.9 * FOOT_FUSION_SCORE * 0.9],
        [[105, 40], [205, 30], [106, 44], [150, 60], [107, 45], [150, 60]])
    found = select_detections(raw, PolarInput(GRID), PP, min_score=0.25, nms_iou=0.45)
    assert len(found.scores) == 2 and found.foot_px is not None
    # votes 105 (0.9), 106 (0.6), 107 (0.4) and 40, 44, 45: half the weight (0.95) is reached at the
    # second of each, not at the best cell's own foot nor at the mean (105.7, 42.3)
    np.testing.assert_allclose(found.foot_px[0], GRID.strip_to_frame(np.array([[106.0, 44.0]]))[0], atol=1e-6)
    np.testing.assert_allclose(found.foot_px[1], GRID.strip_to_frame(np.array([[205.0, 30.0]]))[0], atol=1e-6)
    assert 0.48 < FOOT_FUSION_IOU < 0.82  # the fourth candidate's IoU, the fifth's


def test_weighted_medians_per_group() -> None:
    groups = np.array([2, 0, 0, 0, 2, 3])
    values = np.array([5.0, 3.0, 1.0, 2.0, 7.0, 4.0])
    weights = np.array([1.0, 1.0, 1.0, 5.0, 3.0, 0.0])
    # group 0: 1 (1), 2 (5), 3 (1) -> 2; group 1: none; group 2: 5 (1), 7 (3) -> 7; group 3: no weight
    np.testing.assert_array_equal(weighted_medians(groups, values, weights, 4), [2.0, np.nan, 7.0, np.nan])
    assert np.isnan(weighted_medians(np.zeros(0, int), np.zeros(0), np.zeros(0), 2)).all()
    one_outlier = weighted_medians(np.zeros(4, int), np.array([10.0, 10.5, 11.0, 90.0]), np.ones(4), 1)
    assert one_outlier[0] == 10.5  # a neighbour's feet do not pull it


def test_without_nms_every_output_keeps_its_own_foot() -> None:
    raw = _raw([[100, 20, 110, 40], [100, 21, 110, 41]], [0.9, 0.6], [[105, 40], [106, 44]])
    found = select_detections(raw, PolarInput(GRID), PP, min_score=0.0, nms_iou=None)
    assert found.foot_px is not None
    np.testing.assert_allclose(found.foot_px, GRID.strip_to_frame(np.array([[105.0, 40.0], [106.0, 44.0]])),
                               atol=1e-6)


def _frame(det_boxes: list[list[float]], scores: list[float]) -> EvalFrame:
    return EvalFrame(gt_boxes=np.array([[300.0, 200.0, 20.0, 40.0]]), gt_locations_m=np.full((1, 2), np.nan),
                     gt_distances_m=np.full(1, np.nan), det_boxes=np.asarray(det_boxes, dtype=np.float64),
                     det_scores=np.asarray(scores, dtype=np.float64), principal_point=(256.0, 256.0))


def test_the_operating_point_is_the_nms_iou_and_threshold_of_best_f1() -> None:
    person, shifted = [300.0, 200.0, 20.0, 40.0], [306.0, 220.0, 20.0, 40.0]  # IoU with the person < 0.5

    def frames_at(nms_iou: float) -> list[EvalFrame]:
        # a duplicate box that only an NMS below 0.4 removes, scoring above the person in one frame
        duplicate = nms_iou >= 0.4
        return [_frame([person, shifted] if duplicate else [person], [0.8, 0.7] if duplicate else [0.8]),
                _frame([shifted, person] if duplicate else [person], [0.9, 0.6] if duplicate else [0.6])]

    points = [point for point, _ in sweep(frames_at, (0.3, 0.45, 0.6))]
    best = points[choose(points)]
    assert best.nms_iou == 0.3 and best.f1 == pytest.approx(1.0) and best.min_score == pytest.approx(0.6)
    assert all(point.f1 < 1.0 for point in points if point.nms_iou >= 0.4)


def _greedy_nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> list[int]:
    """The textbook loop, one pair at a time: the reference `strip_nms` must equal."""
    def iou(a: np.ndarray, b: np.ndarray) -> float:
        width = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
        height = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
        inter = width * height
        return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)

    kept: list[int] = []
    for index in sorted(range(len(scores)), key=lambda i: -scores[i]):
        if all(iou(boxes[index], boxes[other]) <= iou_threshold for other in kept):
            kept.append(index)
    return kept


@pytest.mark.parametrize("count", [0, 1, 40, 700])  # 700: beyond the matrix, the survivors' loop first
def test_strip_nms_is_greedy_nms_best_first(count: int) -> None:
    rng = np.random.default_rng(count)
    corner = rng.uniform(0, 10 * np.sqrt(count) + 1, (count, 2))  # crowded: some pairs overlap
    boxes = np.concatenate([corner, corner + rng.uniform(20, 60, (count, 2))], axis=1)
    scores = rng.choice(np.linspace(0.05, 1.0, 30), count)  # ties: the earlier box ranks first
    kept = strip_nms(boxes, scores, 0.45)
    assert kept.tolist() == _greedy_nms(boxes, scores, 0.45)
    assert 0 < len(kept) < count or count <= 1


VIEW_POINTS = '{"1band+nadir": {"min_score": 0.95, "nms_iou": 0.5}}'


def test_view_operating_points_round_trip_and_fall_back_to_the_models_own() -> None:
    from contract import OperatingPoint, metadata_props

    planned = {**METADATA, "fishloc.view_planned": "1", "fishloc.nms_iou": "0.35"}
    info = parse_metadata({**planned, "fishloc.view_operating_points": VIEW_POINTS}, "m.onnx")
    assert info.view_points == (("1band+nadir", OperatingPoint(0.95, 0.5)),)
    assert parse_metadata(metadata_props(info), "m.onnx") == info
    assert info.point_for("1band+nadir") == OperatingPoint(0.95, 0.5)
    assert info.point_for("2band+nadir") == info.point_for(None) == OperatingPoint(0.3, 0.35)
    assert info.point_for("1band+nadir", nms_iou=0.45) == OperatingPoint(0.95, 0.45)  # a caller's IoU
    assert info.public()["view_operating_points"] == {"1band+nadir": {"min_score": 0.95, "nms_iou": 0.5}}


@pytest.mark.parametrize(("value", "planned", "message"), [
    ('{"3 bands": {"min_score": 0.3, "nms_iou": 0.4}}', True, "unknown view layout"),
    ('{"2band": {"min_score": 1.3, "nms_iou": 0.4}}', True, "min_score in"),
    ('{"2band": {"min_score": 0.3}}', True, "must be"),
    ('{"2band": {"min_score": "0.3", "nms_iou": 0.4}}', True, "must be"),
    ('["2band"]', True, "JSON object"),
    ("{2band", True, "not JSON"),
    ('{"2band": {"min_score": 0.3, "nms_iou": 0.4}}', False, "only a planned model"),
])
def test_unusable_view_operating_points_are_refused(value: str, planned: bool, message: str) -> None:
    props = {**METADATA, "fishloc.view_operating_points": value}
    if planned:
        props["fishloc.view_planned"] = "1"
    with pytest.raises(ModelError, match=rf"m\.onnx: unusable.*{message}"):
        parse_metadata(props, "m.onnx")


@pytest.mark.parametrize(("argument", "message"), [
    ("2band+nadir=0.346", "LAYOUT=SCORE,IOU"),
    ("2band+nadir=0.346,1.5", "IOU in"),
    ("two bands=0.3,0.4", "unknown layout"),
])
def test_a_malformed_view_point_argument_is_refused(argument: str, message: str) -> None:
    from detector.checkpoint import CheckpointError, parse_view_point_args

    assert parse_view_point_args(["2band+nadir=0.346,0.3", "1band=0.2,0.4"]) == {
        "2band+nadir": [0.346, 0.3], "1band": [0.2, 0.4]}
    with pytest.raises(CheckpointError, match=message):
        parse_view_point_args([argument])


def test_a_candidate_longer_than_the_camera_allows_is_dropped_before_nms() -> None:
    # 90 frame px along the ray at most anywhere on this grid (1.8 x 50 px): a strip row is 3.9 px
    longest = LongestPerson(radii_px=(0.0, 300.0), along_px=(50.0, 50.0), ratio=1.8)
    raw = _raw([[100, 10, 110, 40],   # 30 rows: 117 px, the best score, overlapping the next
                [100, 18, 110, 38]],  # 20 rows: 78 px
               [0.9, 0.8], [[105, 40], [105, 38]])
    unbounded = select_detections(raw, PolarInput(GRID), PP, min_score=0.25, nms_iou=0.45)
    assert len(unbounded.scores) == 1 and unbounded.scores[0] == pytest.approx(0.9)
    found = frame_candidates(raw, PolarInput(GRID), PP, 0.25, 0.45, longest)
    assert found.scores.tolist() == pytest.approx([0.8])
    assert found.boxes_cxcywh[0, 3] < 90 < unbounded.boxes_cxcywh[0, 3]


def test_the_planned_views_bound_spares_the_nadir_view() -> None:
    plan = plan_view(load_camera("models/demo_camera.yaml"), config=ViewPlanConfig(longest_person_ratio=1.8))
    mapping = PlannedInput(plan)
    assert longest_person(mapping) is plan.longest_person is not None
    assert longest_person(PolarInput(GRID)) is None
    assert longest_person(PlannedInput(plan_view(load_camera("models/demo_camera.yaml")))) is None
    assert plan.nadir is not None
    column = plan.nadir.column
    # The strip's rows run from the rim (row 0) in; feet at row 150 stand 613 px out, where a standing
    # adult is 172 px long. A box filling the nadir view is never judged; in the strip 150 rows
    # (346 px) are too long, 100 rows (231 px) are not.
    boxes = np.array([[column + 10.0, 10, column + 370, 370], [100, 0, 120, 150], [100, 50, 120, 150]])
    feet = np.array([[column + 190.0, 370], [110, 150], [110, 150]])
    pp = plan.grids[0].principal_point
    found = too_long(plan.longest_person, mapping, boxes, feet, pp)
    np.testing.assert_array_equal(found, [False, True, False])
