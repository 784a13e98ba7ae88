"""The NanoDet-Plus fine-tuning loss: its assignment on four levels, its distribution focal loss,
and a head that learns from it."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import pytest
import torch

from detector.checkpoint import load_checkpoint
from detector.nanodet import load_nanodet_onnx
from detector.nanodet.head import BINS
from detector.nanodet.loss import (
    LEVEL_RANGES_PX,
    NanoDetDetectionLoss,
    distribution_focal,
    quality_focal,
)
from detector.nanodet.network import STRIDES
from detector.yolox.loss import anchors_of, assign
from detector.yolox.polar import PolarDetectorConfig
from service.cli import main
from tests.detector.test_nanodet_load import nanodet_onnx_path

HEIGHT, WIDTH = 128, 256


def blank_maps(value: float = -8.0) -> list[torch.Tensor]:
    """Raw maps of a 128 x 256 strip (one image): every person logit and bin logit at `value`."""
    return [torch.full((1, 1 + 4 * BINS, math.ceil(HEIGHT / s), math.ceil(WIDTH / s)), value)
            for s in STRIDES]


def test_distribution_focal_is_least_at_the_true_split() -> None:
    target = torch.tensor([[2.25, 0.0, 5.5, 6.99]])  # (1, 4) distances in bins
    exact = torch.full((1, 4, BINS), -30.0)
    for side, distance in enumerate(target[0].tolist()):
        left = math.floor(distance)
        weight = distance - left
        probabilities = torch.zeros(BINS)
        probabilities[left] = 1 - weight
        if weight > 0:
            probabilities[left + 1] = weight
        exact[0, side] = probabilities.clamp(min=1e-12).log()
    best = distribution_focal(exact, target)  # the cross-entropy's minimum: the split's entropy
    shifted = distribution_focal(exact.roll(1, dims=-1), target)
    assert torch.all(best < shifted)
    entropy = [-(w * math.log(w) + (1 - w) * math.log(1 - w)) if 0 < w < 1 else 0.0
               for w in (0.25, 0.0, 0.5, 0.99)]
    torch.testing.assert_close(best[0], torch.tensor(entropy), atol=1e-4, rtol=0)


def test_quality_focal_vanishes_where_the_score_equals_its_target() -> None:
    logits = torch.tensor([0.0, 2.0, -3.0])
    targets = logits.sigmoid()
    assert quality_focal(logits, targets, beta=2.0).abs().max() < 1e-9
    assert quality_focal(logits, torch.tensor([1.0, 0.0, 1.0]), beta=2.0).min() > 0.1


@pytest.mark.parametrize(("side_px", "levels"), [(0.0, set()), (40.0, {0, 1}), (100.0, {1, 2}),
                                                 (200.0, {2, 3})])
def test_boxes_are_assigned_to_the_levels_their_size_fits(side_px: float, levels: set[int]) -> None:
    anchors = anchors_of(blank_maps(), STRIDES, centre_offset=0.0)
    if side_px == 0.0:
        owner = assign(anchors, torch.zeros((0, 4)), 2.5, LEVEL_RANGES_PX)
        assert bool((owner == -1).all())
        return
    half = side_px / 2
    label = torch.tensor([[128 - half / 3, 64 - half, 128 + half / 3, 64 + half]])  # tall, as people are
    owner = assign(anchors, label, 2.5, LEVEL_RANGES_PX)
    assert set(anchors.levels[owner == 0].tolist()) == levels


def test_loss_is_low_for_maps_that_encode_the_label() -> None:
    label = torch.tensor([[100.0, 40.0, 124.0, 88.0]])  # 24 x 48 px: stride 8 (and 16)
    good = blank_maps()
    for level, stride in enumerate(STRIDES):
        anchors = anchors_of([good[level]], (stride,), centre_offset=0.0)
        owner = assign(anchors_of(good, STRIDES, 0.0), label, 2.5, LEVEL_RANGES_PX)
        start = sum(m.shape[2] * m.shape[3] for m in good[:level])
        width = good[level].shape[3]
        for index in (owner[start:start + len(anchors.strides)] == 0).nonzero()[:, 0].tolist():
            row, col = divmod(index, width)
            cx, cy = col * stride, row * stride
            ltrb = torch.tensor([cx - 100.0, cy - 40.0, 124.0 - cx, 88.0 - cy]) / stride
            good[level][0, 0, row, col] = 6.0
            for side, distance in enumerate(ltrb.clamp(0, BINS - 1.01).tolist()):
                left = int(distance)
                right = distance - left  # the bins' logits give the split's probabilities
                good[level][0, 1 + side * BINS + left, row, col] = 12.0 + math.log(1 - right + 1e-6)
                good[level][0, 1 + side * BINS + left + 1, row, col] = 12.0 + math.log(right + 1e-6)
    loss = NanoDetDetectionLoss()
    encoded, blank = loss(good, [label]), loss(blank_maps(), [label])
    assert encoded["iou"] < 0.05 < blank["iou"]
    assert encoded["dfl"] < 0.8 < blank["dfl"]
    assert encoded["total"] < 0.5 * blank["total"]
    assert blank["distill"] == 0 and loss(blank_maps(), [torch.zeros((0, 4))])["iou"] == 0


def test_distillation_counts_only_cells_outside_every_label() -> None:
    label = torch.tensor([[0.0, 0.0, 256.0, 128.0]])  # covers the whole strip
    student, teacher = blank_maps(-8.0), blank_maps(3.0)
    assert NanoDetDetectionLoss()(student, [label], teacher)["distill"] == 0
    assert NanoDetDetectionLoss()(student, [torch.zeros((0, 4))], teacher)["distill"] > 1.0


def test_cli_fine_tunes_the_head_alone_and_validates(toy_dataset: Callable[..., Path],
                                                     tmp_path: Path) -> None:
    data, out = toy_dataset(count=2, size=128, people=2), tmp_path / "nanodet"
    onnx_path = nanodet_onnx_path()
    code = main(["train", "--init-from", str(onnx_path), "--network", "nanodet-plus-m", "--data", str(data),
                 "--val", str(data), "--out", str(out), "--quiet", "--threads", "1",
                 "--strip", "64", "256", "32", "--freeze", "backbone", "neck", "--epochs", "1",
                 "--batch-size", "2", "--distill", "4"])
    assert code == 0
    record = json.loads((out / "log.jsonl").read_text().splitlines()[0])
    assert set(record["train"]) == {"quality", "iou", "dfl", "distill", "total"}
    assert {"AP50", "recall"} <= set(record["val"])
    trained = load_checkpoint(out / "last.pt")
    assert isinstance(trained.config, PolarDetectorConfig) and trained.config.network == "nanodet-plus-m"
    start = load_nanodet_onnx(onnx_path).to_person_only().state_dict()
    frozen = [k for k in start if k.startswith(("backbone", "neck"))]
    assert frozen and all(torch.equal(trained.model_state[k], start[k]) for k in frozen)
    assert any(not torch.equal(trained.model_state[k], v) for k, v in start.items() if k.startswith("head"))
    assert main(["train", "--init-from", str(onnx_path), "--network", "nanodet-plus-m", "--data", str(data),
                 "--out", str(tmp_path / "bad"), "--quiet", "--foot"]) == 2  # NanoDet has no foot branch
    # Without --freeze NanoDet's backbone stays frozen and its neck trains (YOLOX's stage names would
    # not fit it).
    assert main(["train", "--init-from", str(onnx_path), "--network", "nanodet-plus-m", "--data", str(data),
                 "--out", str(tmp_path / "default"), "--quiet", "--threads", "1",
                 "--strip", "64", "256", "32", "--epochs", "1", "--batch-size", "2"]) == 0
    defaulted = load_checkpoint(tmp_path / "default" / "last.pt").model_state
    backbone = [k for k in start if k.startswith("backbone")]
    assert backbone and all(torch.equal(defaulted[k], start[k]) for k in backbone)
    assert any(not torch.equal(defaulted[k], v) for k, v in start.items() if k.startswith("neck"))
    assert main(["train", "--init-from", str(onnx_path), "--network", "nanodet-plus-m", "--data", str(data),
                 "--out", str(tmp_path / "stem"), "--quiet", "--freeze", "stem"]) == 2
