"""A person-only YOLOX-Nano exports to ONNX with a dynamic input size and decodes the same there."""

from __future__ import annotations

import contextlib
import io
import logging
import warnings
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from torch import Tensor, nn

from detector.yolox import YoloxNano, decode, load_yolox_onnx
from models import ASSETS_DIR

ONNX_PATH = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"


class Decoded(nn.Module):
    """images (B, 3, H, W) BGR 0-255 -> (B, A, 5 + C) boxes in px and probabilities."""

    def __init__(self, network: YoloxNano) -> None:
        super().__init__()
        self.network = network

    def forward(self, images: Tensor) -> Tensor:
        return decode(self.network(images))


@pytest.mark.slow
def test_person_only_exports_with_a_dynamic_input_size(tmp_path: Path) -> None:
    model = Decoded(load_yolox_onnx(ONNX_PATH).to_person_only()).eval()
    path = tmp_path / "person.onnx"
    rows32, cols32 = torch.export.Dim("rows32", min=1, max=64), torch.export.Dim("cols32", min=1, max=64)
    batch = torch.export.Dim("batch", min=1, max=16)
    # The exporter prints progress and torch-internal notices (pytest turns warnings into errors).
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        logging.getLogger("torch.onnx").setLevel(logging.ERROR)
        torch.onnx.export(model, (torch.zeros(1, 3, 256, 512),), str(path), input_names=["images"],
                          output_names=["output"], opset_version=18, dynamo=True, external_data=False,
                          dynamic_shapes={"images": {0: batch, 2: 32 * rows32, 3: 32 * cols32}})
    onnx.checker.check_model(onnx.load(str(path)), full_check=True)
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(5)
    for height, width, count in [(416, 416, 1), (320, 640, 2)]:
        images = rng.uniform(0, 255, (count, 3, height, width)).astype(np.float32)
        got = session.run(["output"], {"images": images})[0]
        with torch.no_grad():
            expected = model(torch.from_numpy(images)).numpy()
        anchors = sum((height // s) * (width // s) for s in (8, 16, 32))
        assert got.shape == expected.shape == (count, anchors, 6)
        np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-3)
