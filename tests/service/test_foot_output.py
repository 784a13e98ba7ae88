"""A model with a `foot` output is served from its feet; one without, from its boxes' near sides.

Two small polar YOLOX networks (COCO weights, a 64-row strip) are exported and served by real
uvicorn servers: one with a foot branch whose offsets are set away from the box side, one without.
"""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import httpx
import numpy as np
import pytest
import torch
from service_frames import encode, person_frame
from service_live_server import LiveServer

from detector.checkpoint import Checkpoint, ModelInfo
from detector.yolox.polar import PolarDetectorConfig, init_from_pretrained
from exporter.export import export_onnx
from fisheye import FisheyeCamera, foot_points
from models import ASSETS_DIR
from service.core.config import Settings

CONFIG = PolarDetectorConfig(input_size=64, polar_width=256, polar_overlap=32, foot=True)


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory) -> dict[bool, Path]:
    folder = tmp_path_factory.mktemp("foot-models")
    footed = init_from_pretrained(str(ASSETS_DIR / "pretrained" / "yolox_nano.onnx"), CONFIG)
    plain = copy.deepcopy(footed)
    plain.foot = None
    with torch.no_grad():  # half a box to the side and a fifth of its height towards the centre
        for pred in footed.foot.preds:  # type: ignore[union-attr]
            pred.bias.copy_(torch.tensor([0.5, 0.2]))  # type: ignore[union-attr]
    paths = {}
    for has_foot, network in ((True, footed), (False, plain)):
        config = dataclasses.replace(CONFIG, foot=has_foot)
        checkpoint = Checkpoint(config, network.state_dict(), ModelInfo(f"foot-{has_foot}", "test", 0.01), {})
        paths[has_foot] = folder / f"foot-{has_foot}.onnx"
        export_onnx(checkpoint, paths[has_foot])
    return paths


def test_positions_come_from_the_models_feet(models: dict[bool, Path], tmp_path: Path,
                                             demo_camera: FisheyeCamera) -> None:
    frame = person_frame(demo_camera, (1.5, -1.1), (1024, 1024))
    answers = {}
    for has_foot, path in models.items():
        settings = Settings(model=path, database=str(tmp_path / f"cameras-{has_foot}.db"), http_port=0,
                            grpc_port=-1, threads=1)
        with LiveServer(settings) as server:
            response = httpx.post(f"{server.url}/v1/cameras/demo/detect", content=encode(frame.bgr),
                                  headers={"content-type": "image/jpeg"}, params={"min_score": 0.0},
                                  timeout=60)
        assert response.status_code == 200, response.text
        answers[has_foot] = response.json()["detections"]
    assert answers[True] and len(answers[True]) == len(answers[False])
    camera = demo_camera.scaled_to((1024, 1024))
    for footed, plain in zip(answers[True], answers[False], strict=True):
        assert footed["box"] == pytest.approx(plain["box"], abs=1e-3)  # the foot changes no box
        box = plain["box"]
        cxcywh = np.array([[box["cx"], box["cy"], box["w"], box["h"]]])
        box_side = foot_points(cxcywh, camera.principal_point)[0]
        np.testing.assert_allclose(plain["foot_px"], box_side, atol=0.02)  # answers round to 0.01 px
        assert np.linalg.norm(np.array(footed["foot_px"]) - box_side) > 1.0
        for detection in (footed, plain):
            if detection["position_m"] is not None:
                expected = camera.pixels_to_floor(np.array([detection["foot_px"]]))[0]
                np.testing.assert_allclose(detection["position_m"], expected, atol=0.01)
