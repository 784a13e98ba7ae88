"""The model's operating point (score threshold and NMS IoU in its metadata, chosen together on
validation frames) and the foot points fused over each kept detection's cluster."""

from __future__ import annotations

import numpy as np
import pytest
from polar_double import METADATA

from contract import ModelError, PolarInput, RawOutputs, parse_metadata, select_detections
from contract.detect import FOOT_FUSION_IOU, FOOT_FUSION_SCORE
from contract.metadata import LEGACY_NMS_IOU
from detector.metrics import EvalFrame
from detector.operating_point import choose, sweep
from fisheye.polar import PolarGrid

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


def test_a_kept_detection_stands_at_the_score_weighted_foot_of_its_cluster() -> None:
    raw = _raw(
        [[100, 20, 110, 40],   # a person's best cell
         [200, 10, 210, 30],   # another person
         [100, 21, 110, 41],   # the first person's other cells ...
         [100, 27, 110, 47],   # ... one suppressed by the NMS (IoU 0.48) but too far off to vote
         [101, 20, 111, 40],
         [100, 20, 110, 40]],  # ... one too weak to vote
        [0.9, 0.8, 0.6, 0.5, 0.3, 0.9 * FOOT_FUSION_SCORE * 0.9],
        [[105, 40], [205, 30], [106, 44], [150, 60], [102, 38], [150, 60]])
    found = select_detections(raw, PolarInput(GRID), PP, min_score=0.25, nms_iou=0.45)
    assert len(found.scores) == 2 and found.foot_px is not None
    weights = np.array([0.9, 0.6, 0.3])
    expected = (weights[:, None] * np.array([[105, 40], [106, 44], [102, 38]])).sum(0) / weights.sum()
    np.testing.assert_allclose(found.foot_px[0], GRID.strip_to_frame(expected[None])[0], atol=1e-6)
    np.testing.assert_allclose(found.foot_px[1], GRID.strip_to_frame(np.array([[205.0, 30.0]]))[0], atol=1e-6)
    assert 0.48 < FOOT_FUSION_IOU < 0.82  # the fourth candidate's IoU, the fifth's


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
