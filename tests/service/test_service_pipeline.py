"""The pipeline's geometry, end to end through onnxruntime, checked against known truth.

The model is the plumbing test double of `service_doubles` (see there): it reports a person at the
centroid of a bright disk plus fixed boxes, so frame pixels, angles, foot points and floor
positions can be checked exactly or against the floor point the disk was drawn for.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from service_doubles import (
    BLOB_SCORE,
    BLOB_WH,
    CONSTANT_BOXES,
    CONSTANT_SCORES,
    DEFAULT_MIN_SCORE,
    INPUT_SIZE,
    METADATA,
    save_double_model,
)
from service_frames import encode, person_frame

from contract import OnnxModel, SessionThreads
from fisheye import FisheyeCamera, camera_from_dict, camera_to_dict, cxcywh_to_corners, foot_points
from service.frame_decode import FrameError
from service.pipeline import Pipeline, PipelineConfig, localize
from service.result import result_to_json


@pytest.fixture(scope="module")
def pipeline(double_model_path: Path) -> Pipeline:
    return Pipeline(OnnxModel(double_model_path, SessionThreads(intra_op=1)), PipelineConfig())


def expected_constant_box(index: int, frame_wh: tuple[int, int]) -> np.ndarray:
    """Constant box `index` of the double in frame px, by the letterbox formula written out."""
    width, height = frame_wh
    scale = INPUT_SIZE / max(width, height)
    resized = (round(width * scale), round(height * scale))
    offset = ((INPUT_SIZE - resized[0]) // 2, (INPUT_SIZE - resized[1]) // 2)
    sx, sy = resized[0] / width, resized[1] / height
    cx, cy, w, h = CONSTANT_BOXES[index].astype(np.float64)
    mean = (sx + sy) / 2
    u = (cx - offset[0] + 0.5) / sx - 0.5
    v = (cy - offset[1] + 0.5) / sy - 0.5
    return np.array([u, v, w / mean, h / mean])


@pytest.mark.parametrize("frame_side", [2048, 1024, 512])
def test_person_lands_on_its_floor_point(pipeline: Pipeline, demo_camera: FisheyeCamera,
                                         frame_side: int) -> None:
    truth = person_frame(demo_camera, (1.2, -0.9), (frame_side, frame_side), disk_radius_px=frame_side / 50)
    result, frame = pipeline.detect_frame(encode(truth.bgr), demo_camera, frame_id="7")
    assert frame.reduction == frame_side // INPUT_SIZE
    assert result.image_wh == (frame_side, frame_side) and result.frame_id == "7"
    detections = result.detections
    # The blob (0.9) and constant box A (0.8); A' is suppressed by NMS, C is under the threshold.
    np.testing.assert_allclose(detections.scores, [BLOB_SCORE, CONSTANT_SCORES[0]], atol=1e-6)
    # The disk's centroid survives JPEG and DCT-scaled decoding to well within a pixel (~5 mm here).
    np.testing.assert_allclose(detections.cxcywh[0], truth.box_cxcywh, atol=1.0)
    np.testing.assert_allclose(detections.foot_px[0], truth.foot_px, atol=1.0)
    np.testing.assert_allclose(detections.position_m[0], truth.floor_xy_m, atol=0.005)
    assert detections.distance_m[0] == pytest.approx(math.hypot(1.2, -0.9), abs=0.005)


def test_geometry_is_exact_given_the_boxes(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    truth = person_frame(demo_camera, (-2.0, 1.5), (2048, 2048))
    result = pipeline.detect(encode(truth.bgr), demo_camera)
    d = result.detections
    pp = np.asarray(demo_camera.principal_point)
    np.testing.assert_allclose(d.cxcywh[1], expected_constant_box(0, (2048, 2048)), atol=1e-4)
    angles = np.degrees(np.arctan2(d.cxcywh[:, 1] - pp[1], d.cxcywh[:, 0] - pp[0]))
    np.testing.assert_allclose(d.angle_deg, angles, atol=1e-9)
    np.testing.assert_allclose(d.corners_xy, cxcywh_to_corners(d.cxcywh, pp), atol=1e-9)
    np.testing.assert_allclose(d.foot_px, foot_points(d.cxcywh, pp), atol=1e-9)
    np.testing.assert_allclose(d.position_m, demo_camera.pixels_to_floor(d.foot_px), atol=1e-9)
    # The foot point is the middle of the box side nearest the principal point.
    np.testing.assert_allclose(d.foot_px, d.corners_xy[:, :2].mean(axis=1), atol=1e-9)


def test_letterbox_offsets_of_a_wide_frame_in_jpeg_and_png(pipeline: Pipeline) -> None:
    camera = camera_from_dict({
        "id": "wide", "altitude_m": 3.0, "image_size": [1280, 960], "principal_point": [640.0, 480.0],
        "focal_px": [400.0, 400.0], "kb": [1.0],
    })
    black = np.zeros((960, 1280, 3), dtype=np.uint8)
    jpeg = pipeline.detect_frame(encode(black), camera)
    png = pipeline.detect_frame(encode(black, ".png"), camera)
    assert (jpeg[1].reduction, png[1].reduction) == (4, 1)
    for result, _ in (jpeg, png):
        assert len(result.detections) == 1  # no bright pixels: only constant box A
        expected = expected_constant_box(0, (1280, 960))
        np.testing.assert_allclose(result.detections.cxcywh[0], expected, atol=1e-4)


def test_min_score_and_nms(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    black = encode(np.zeros((2048, 2048, 3), dtype=np.uint8))
    default = pipeline.detect(black, demo_camera)
    assert default.detections.scores.tolist() == pytest.approx([CONSTANT_SCORES[0]])
    low = pipeline.detect(black, demo_camera, min_score=0.1)
    # A' overlaps A (NMS removes it); C is far away and now above the threshold.
    np.testing.assert_allclose(low.detections.scores, CONSTANT_SCORES[[0, 2]], atol=1e-6)
    np.testing.assert_allclose(low.detections.cxcywh[1], expected_constant_box(2, (2048, 2048)), atol=1e-4)
    everything = pipeline.detect(black, demo_camera, min_score=0.0)
    assert len(everything.detections) == 3  # the double's empty blob slot (score 0) is kept at 0
    assert pipeline.info.default_min_score == DEFAULT_MIN_SCORE
    with pytest.raises(ValueError, match="min_score"):
        pipeline.detect(black, demo_camera, min_score=1.5)


def test_the_model_s_own_nms_iou_is_used_unless_the_service_sets_one(tmp_path: Path,
                                                                     demo_camera: FisheyeCamera) -> None:
    black = encode(np.zeros((2048, 2048, 3), dtype=np.uint8))
    path = save_double_model(tmp_path / "no-nms.onnx", metadata={**METADATA, "fishloc.nms_iou": "1.0"})
    own = Pipeline(OnnxModel(path, SessionThreads(intra_op=1)), PipelineConfig())
    assert own.info.nms_iou == 1.0
    # A' overlaps A: kept at the model's IoU of 1.0, removed when the service asks for 0.6.
    np.testing.assert_allclose(own.detect(black, demo_camera, min_score=0.1).detections.scores,
                               CONSTANT_SCORES[:3], atol=1e-6)
    service = Pipeline(OnnxModel(path, SessionThreads(intra_op=1)), PipelineConfig(nms_iou=0.6))
    np.testing.assert_allclose(service.detect(black, demo_camera, min_score=0.1).detections.scores,
                               CONSTANT_SCORES[[0, 2]], atol=1e-6)


def test_site_positions_follow_the_site_pose(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    record = camera_to_dict(demo_camera) | {"site_pose": {"x_m": 10.0, "y_m": 5.0, "yaw_deg": 90.0}}
    camera = camera_from_dict(record)
    truth = person_frame(camera, (1.0, 0.5), (2048, 2048))
    d = pipeline.detect(encode(truth.bgr), camera).detections
    assert d.site_position_m is not None
    x, y = d.position_m[:, 0], d.position_m[:, 1]
    np.testing.assert_allclose(d.site_position_m, np.stack([10.0 - y, 5.0 + x], axis=1), atol=1e-9)
    no_site = pipeline.detect(encode(truth.bgr), camera_from_dict({**record, "site_pose": None}))
    assert no_site.detections.site_position_m is None


def test_no_floor_point_serialises_as_null(demo_camera: FisheyeCamera) -> None:
    pp = np.asarray(demo_camera.principal_point)
    radius = demo_camera.image_circle_radius_px()
    # Foot point beyond the horizon (θ > 90°): the box's near side lies outside the floor's image.
    boxes = np.array([[pp[0] + radius - 5.0, pp[1], 40.0, 20.0], [pp[0] + 200.0, pp[1], 40.0, 60.0]])
    detections = localize(boxes, np.array([0.9, 0.8]), demo_camera)
    assert np.isnan(detections.position_m[0]).all() and np.isfinite(detections.position_m[1]).all()
    from service.result import DetectionResult

    answer = result_to_json(DetectionResult("demo", None, (2048, 2048), "m", "1", detections, {}))
    first, second = answer["detections"]
    assert first["position_m"] is None and first["distance_m"] is None
    assert second["position_m"] is not None and second["distance_m"] > 0


def test_empty_result_has_empty_arrays(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    empty = localize(np.zeros((0, 4)), np.zeros(0), demo_camera)
    assert len(empty) == 0 and empty.corners_xy.shape == (0, 4, 2)
    assert empty.site_position_m is not None and empty.site_position_m.shape == (0, 2)


@pytest.mark.parametrize(("data", "code"), [
    (b"", "empty_body"),
    (b"GIF89a" + bytes(100), "unsupported_image"),
    (b"\xff\xd8\xff\xe0\x00\x10JFIF" + bytes(8), "bad_image"),
])
def test_bad_frames_are_refused(pipeline: Pipeline, demo_camera: FisheyeCamera, data: bytes,
                                code: str) -> None:
    with pytest.raises(FrameError) as caught:
        pipeline.detect(data, demo_camera)
    assert caught.value.code == code


def test_frame_of_another_aspect_ratio_is_refused(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    with pytest.raises(FrameError) as caught:
        pipeline.detect(encode(np.zeros((600, 800, 3), dtype=np.uint8)), demo_camera)
    assert caught.value.code == "frame_size_mismatch"


def test_blob_box_size_scales_with_the_frame(pipeline: Pipeline, demo_camera: FisheyeCamera) -> None:
    truth = person_frame(demo_camera, (0.8, 0.8), (1024, 1024), disk_radius_px=20)
    d = pipeline.detect(encode(truth.bgr), demo_camera).detections
    np.testing.assert_allclose(d.cxcywh[0, 2:], np.array(BLOB_WH) * 4, atol=1e-4)
