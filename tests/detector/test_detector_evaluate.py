from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from contract import FrameDetections
from detector.data.readers import read_dataset
from detector.evaluate import evaluate
from fisheye import FisheyeCamera

SIZE = 400
CENTRE = ((SIZE - 1) / 2, (SIZE - 1) / 2)
# 100 px above / right of the centre, each drawn 44° off its ray (a sitting person), and a
# radius-aligned box that covers each drawn box at IoU 0.53 but its radius-aligned conversion at 0.36.
SITTING = [199.5, 99.5, 30.0, 60.0, 44.0]
HUGS_SITTING = [199.5, 99.5, 58.0, 32.0]
CROWD = [299.5, 199.5, 30.0, 60.0, -46.0]
HUGS_CROWD = [299.5, 199.5, 58.0, 32.0]


class FixedPredictor:
    """Answers every frame with the same detections."""

    default_min_score = 0.5

    def __init__(self, boxes: list[list[float]], scores: list[float]) -> None:
        self.detections = FrameDetections(np.array(boxes), np.array(scores), CENTRE)

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        return [self.detections for _ in frames_rgb]


def _cepdof_file(folder: Path) -> Path:
    cv2.imwrite(str(folder / "Lunch_1.jpg"), np.zeros((SIZE, SIZE, 3), np.uint8))
    document = {
        "images": [{"id": "Lunch_1", "file_name": "Lunch_1.jpg", "width": SIZE, "height": SIZE}],
        "annotations": [
            {"image_id": "Lunch_1", "category_id": 1, "bbox": SITTING, "iscrowd": 0, "person_id": 1},
            {"image_id": "Lunch_1", "category_id": 1, "bbox": CROWD, "iscrowd": 1, "person_id": 2},
        ],
        "categories": [{"id": 1, "name": "person"}],
    }
    path = folder / "cepdof.json"
    path.write_text(json.dumps(document))
    return path


def test_a_cepdof_file_is_scored_against_its_own_boxes(tmp_path: Path) -> None:
    frames = read_dataset(_cepdof_file(tmp_path))
    predictor = FixedPredictor([HUGS_CROWD, HUGS_SITTING], [0.9, 0.6])
    metrics = evaluate(predictor, frames).metrics
    # Against the file's boxes: the person is found and the detection on the crowd box is ignored.
    assert metrics["AP50"] == 1.0 and metrics["precision"] == 1.0 and metrics["recall"] == 1.0
    # Against their radius-aligned conversions both detections are false alarms.
    assert metrics["AP50_radius_aligned"] == 0.0 and metrics["precision_radius_aligned"] == 0.0
    assert metrics["recall_radius_aligned"] == 0.0 and metrics["mAP_radius_aligned"] == 0.0
    # The assumed camera invents neither positions nor distances.
    assert metrics["PE_matches"] == 0.0
    assert all(math.isnan(metrics[k]) for k in ("mPE", "mPE_center", "AP_near", "AP_mid", "AP_far"))


def test_no_floor_error_is_measured_with_an_assumed_camera(tmp_path: Path) -> None:
    """Even where a CEPDOF-style file gives a person's position, the assumed camera would only
    measure its own guess: no localisation error is reported."""
    path = _cepdof_file(tmp_path)
    document = json.loads(path.read_text())
    document["annotations"][0]["location_m"] = [0.0, 3.0]
    path.write_text(json.dumps(document))
    (frame,) = read_dataset(path)
    assert frame.camera_assumed and np.isfinite(frame.distances_m).all()
    metrics = evaluate(FixedPredictor([HUGS_SITTING], [0.9]), [frame]).metrics
    assert metrics["AP50"] == 1.0
    assert metrics["PE_matches"] == 0.0 and math.isnan(metrics["mPE"]) and math.isnan(metrics["mPE_center"])


@pytest.mark.parametrize("assumed", ["short-side", "image-circle"])
def test_eval_takes_the_assumed_camera_of_uncalibrated_frames(tmp_path: Path, assumed: str) -> None:
    """`fishloc eval --assumed-camera image-circle` gives each CEPDOF frame the camera of its fitted
    circle (here wider than the frame) and says which assumption it made."""
    from models import DEFAULT_MODEL_PATH
    from service.cli import main
    from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame

    frame = draw_circle_frame(CircleFrame((656, 540), (330.0, 268.0), 322.0))
    cv2.imwrite(str(tmp_path / "wide.png"), frame)
    data = tmp_path / "wide.json"
    data.write_text(json.dumps({
        "images": [{"id": "w", "file_name": "wide.png", "width": 656, "height": 540}],
        "annotations": [{"id": 1, "image_id": "w", "category_id": 1,
                         "bbox": [600.0, 270.0, 20.0, 50.0, 0.0]}],
    }))
    out = tmp_path / "metrics.json"
    assert main(["eval", "--model", str(DEFAULT_MODEL_PATH), "--data", str(data), "--json", str(out),
                 "--assumed-camera", assumed]) == 0
    metrics = json.loads(out.read_text())
    assert metrics["assumed_camera"] == assumed and metrics["mPE"] is None


def test_eval_refuses_a_second_look_out_of_range(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from models import DEFAULT_MODEL_PATH
    from service.cli import main

    data = _cepdof_file(tmp_path)
    out = tmp_path / "metrics.json"
    assert main(["eval", "--model", str(DEFAULT_MODEL_PATH), "--data", str(data), "--json", str(out),
                 "--second-look", "-1"]) == 2
    assert "second_look_pixels must lie in [0, 4194304]" in capsys.readouterr().err and not out.exists()
