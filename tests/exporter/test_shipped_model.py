"""The shipped default model: its release checkpoint exports to the shipped ONNX (same metadata,
same outputs on real strips of the sample frames), and the ONNX is what the service reads."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest

from contract import OnnxModel, SessionThreads, prepare_input
from detector.checkpoint import load_checkpoint
from detector.evaluate import EVAL_MIN_SCORE
from detector.graph import contract_info
from detector.yolox.foot import REFINE_MIN_SCORE
from exporter.export import contract_model, export_onnx
from exporter.parity import check_parity
from fisheye import load_camera
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH

ROOT = Path(__file__).resolve().parents[2]
RELEASE = ROOT / "models" / "fishloc-default.pt"


def _sample_strips(model: OnnxModel) -> np.ndarray:
    camera = load_camera(DEMO_CAMERA_PATH)
    strips = []
    for path in sorted((ROOT / "samples").glob("*.jpg")):
        rgb = np.asarray(cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB), dtype=np.uint8)
        frame_camera = camera.scaled_to((rgb.shape[1], rgb.shape[0]))
        strips.append(prepare_input(model.info, rgb, frame_camera)[0])
    return np.stack(strips)


def test_release_checkpoint_matches_the_shipped_onnx() -> None:
    shipped = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(1))
    checkpoint = load_checkpoint(RELEASE)
    assert dataclasses.replace(shipped.info, sha256="") == contract_info(checkpoint)
    assert shipped.info.view == "polar" and shipped.info.version == "0.8.0" and shipped.has_foot
    assert shipped.info.planned  # any height and width: the service plans each camera's view
    assert (shipped.info.default_min_score, shipped.info.nms_iou) == (0.236, 0.35)
    assert "Apache-2.0" in shipped.info.licence
    # The graph refines the feet of the candidates from REFINE_MIN_SCORE alone: every detection the
    # service reports at the model's operating points, and every one evaluation counts, is among them.
    thresholds = [shipped.info.default_min_score, *(point.min_score for _, point in shipped.info.view_points)]
    assert len(thresholds) >= 2 and min([*thresholds, EVAL_MIN_SCORE]) >= REFINE_MIN_SCORE
    module, _ = contract_model(checkpoint)
    strips = _sample_strips(shipped)
    report = check_parity(module, shipped, strips, shipped.info.default_min_score)
    assert report.detections_above_threshold >= 10  # the sample frames' people, compared one by one


@pytest.mark.slow
def test_export_of_the_release_checkpoint_reproduces_the_shipped_onnx(tmp_path: Path) -> None:
    shipped = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(1))
    strips = _sample_strips(shipped)
    report = export_onnx(load_checkpoint(RELEASE), tmp_path / "again.onnx", parity_frames=strips)
    assert report.parity.detections_above_threshold >= 10
    again = OnnxModel(tmp_path / "again.onnx", SessionThreads(1))
    assert dataclasses.replace(again.info, sha256="") == dataclasses.replace(shipped.info, sha256="")
    for ours, theirs in zip(again.run_batch(strips), shipped.run_batch(strips), strict=True):
        np.testing.assert_allclose(ours.scores, theirs.scores, atol=1e-5)
        top = theirs.scores >= 0.05
        np.testing.assert_allclose(ours.boxes[top], theirs.boxes[top], atol=1e-2)
        assert ours.foot is not None and theirs.foot is not None
        np.testing.assert_allclose(ours.foot[top], theirs.foot[top], atol=1e-2)
