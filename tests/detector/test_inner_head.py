"""Design (c): the inner-disc head answers for the bottom rows only, trains alone, and exports."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from contract import OnnxModel, SessionThreads
from detector.checkpoint import load_checkpoint
from detector.yolox.inner_head import InnerHeadYolox
from detector.yolox.network import YoloxNano
from detector.yolox.polar import PolarDetectorConfig, init_from_pretrained
from exporter.export import export_onnx
from service.cli import main

ONNX_PATH = Path(__file__).resolve().parents[2] / "models" / "pretrained" / "yolox_nano.onnx"
CONFIG = PolarDetectorConfig(input_size=64, polar_width=256, polar_overlap=32, inner_fraction=0.25)


@pytest.fixture(scope="module")
def plain() -> YoloxNano:
    return init_from_pretrained(str(ONNX_PATH), PolarDetectorConfig(input_size=64, polar_width=256,
                                                                     polar_overlap=32))


def _images() -> torch.Tensor:
    return torch.from_numpy(np.random.default_rng(0).uniform(0, 255, (1, 3, 64, 288)).astype(np.float32))


def test_a_copied_inner_head_answers_like_the_network(plain: YoloxNano) -> None:
    model = init_from_pretrained(str(ONNX_PATH), CONFIG)
    assert isinstance(model, InnerHeadYolox)
    with torch.no_grad():
        for ours, theirs in zip(model(_images()), plain(_images()), strict=True):
            torch.testing.assert_close(ours, theirs)


def test_the_inner_head_changes_the_bottom_rows_only(plain: YoloxNano) -> None:
    model = InnerHeadYolox.from_network(plain, 0.25)
    with torch.no_grad():
        for pred in model.inner_head.obj_preds:
            pred.bias.add_(3.0)
        for ours, theirs in zip(model(_images()), plain(_images()), strict=True):
            rows = ours.shape[2]
            stride = 64 / rows
            inner = (torch.arange(rows) + 0.5) * stride >= 64 * 0.75
            changed = (ours - theirs).abs().amax(dim=(0, 1, 3)) > 1e-4  # per row
            assert torch.equal(changed, inner), (rows, changed, inner)


def test_training_the_inner_head_alone_then_export(toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    data = toy_dataset(count=2, size=128, people=3)
    out = tmp_path / "inner"
    frozen = ["stem", "dark2", "dark3", "dark4", "dark5", "neck", "head"]
    assert main(["train", "--init-from", str(ONNX_PATH), "--data", str(data), "--out", str(out), "--quiet",
                 "--threads", "1", "--strip", "64", "256", "32", "--inner-head", "0.25", "--epochs", "1",
                 "--batch-size", "2", "--lr", "0.01", "--freeze", *frozen]) == 0
    checkpoint = load_checkpoint(out / "last.pt")
    assert checkpoint.config == CONFIG
    start = init_from_pretrained(str(ONNX_PATH), CONFIG).state_dict()
    moved = {k for k, v in checkpoint.model_state.items() if not torch.equal(v, start[k])}
    assert moved and all(k.startswith("inner_head.") for k in moved)
    report = export_onnx(checkpoint, tmp_path / "inner.onnx")
    assert report.parity.frames > 0
    model = OnnxModel(tmp_path / "inner.onnx", SessionThreads(1))
    assert model.info.view == "polar" and model.info.input_wh == (288, 64)
