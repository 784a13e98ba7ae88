from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch import nn

from detector.losses import (
    DetectionLoss,
    LossConfig,
    detection_terms,
    equivariance_loss,
    focal_heatmap_loss,
    masked_l1,
)
from detector.model import build_model, tiny_config
from detector.targets import TargetConfig, build_batch_targets

SIZE = 64


def test_focal_loss_matches_a_hand_computation() -> None:
    logits = torch.tensor([[[[0.0, 1.0], [-1.0, 2.0]]]])
    target = torch.tensor([[[[1.0, 0.5], [0.0, 0.25]]]])
    positives = torch.tensor([[[True, False], [False, False]]])
    p = 1 / (1 + np.exp(-np.array([0.0, 1.0, -1.0, 2.0])))
    positive = (1 - p[0]) ** 2 * np.log(p[0])
    negative = sum((1 - y) ** 4 * q ** 2 * np.log(1 - q)
                   for q, y in zip(p[1:], [0.5, 0.0, 0.25], strict=True))
    expected = -(positive + negative) / 1
    assert float(focal_heatmap_loss(logits, target, positives, 2.0, 4.0)) == pytest.approx(expected, rel=1e-6)


def test_masked_l1_averages_over_masked_cells_only() -> None:
    prediction = torch.zeros(1, 2, 2, 2)
    target = torch.tensor([[[[1.0, 5.0], [0.0, 0.0]], [[-2.0, 7.0], [0.0, 0.0]]]])
    mask = torch.tensor([[[True, False], [False, True]]])
    # cell (0,0): |1| + |-2| = 3; cell (1,1): 0 -> mean over 2 cells = 1.5
    assert float(masked_l1(prediction, target, mask)) == pytest.approx(1.5)
    assert float(masked_l1(prediction, target, torch.zeros(1, 2, 2, dtype=torch.bool))) == 0.0


def _oracle_features(boxes: list[np.ndarray]) -> torch.Tensor:
    """Head-output maps that encode the boxes exactly: confident peaks, exact sizes and offsets."""
    targets = build_batch_targets(boxes, SIZE, TargetConfig())
    logits = torch.where(targets.mask[:, None], torch.tensor(40.0), torch.tensor(-40.0))
    return torch.cat([logits, targets.regression], dim=1)


BOXES = [np.array([[20.3, 12.7, 6.0, 14.0], [45.1, 40.2, 8.0, 17.0]]), np.array([[10.0, 50.0, 5.0, 9.0]])]


def test_detection_terms_vanish_for_perfect_predictions() -> None:
    config = LossConfig()
    terms = detection_terms(_oracle_features(BOXES), build_batch_targets(BOXES, SIZE, config.targets), config)
    assert float(terms["heatmap"]) < 1e-6
    assert float(terms["size"]) < 1e-6 and float(terms["offset"]) < 1e-6


@pytest.mark.parametrize("quarter_turns", [1, 2, 3])
def test_equivariance_term_is_zero_for_an_exactly_equivariant_toy(quarter_turns: int) -> None:
    # The toy's features already are its (radius-aligned, hence rotation-invariant) predictions and
    # its head is the identity: rotating the features must decode exactly to the rotated boxes.
    features = _oracle_features(BOXES)
    angles = torch.full((2,), quarter_turns * math.pi / 2)
    loss = equivariance_loss(features, nn.Identity(), BOXES, angles, SIZE, LossConfig())
    assert float(loss) < 1e-5


class _IgnoresItsInput(nn.Module):
    """A head that always predicts the unrotated boxes: the opposite of equivariant."""

    def __init__(self, maps: torch.Tensor) -> None:
        super().__init__()
        self.maps = maps

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.maps


def test_equivariance_term_penalises_a_toy_that_is_not_equivariant() -> None:
    features = _oracle_features(BOXES)
    head = _IgnoresItsInput(features)
    assert float(equivariance_loss(features, head, BOXES, torch.zeros(2), SIZE, LossConfig())) < 1e-5
    turned = equivariance_loss(features, head, BOXES, torch.full((2,), math.pi / 2), SIZE, LossConfig())
    assert float(turned) > 1.0


def test_loss_returns_named_terms_and_switches_equivariance() -> None:
    torch.manual_seed(0)
    model = build_model(tiny_config(SIZE))
    images = torch.randn(2, 3, SIZE, SIZE)
    generator = torch.Generator().manual_seed(1)
    terms = DetectionLoss(LossConfig(equivariance=True))(model, images, BOXES, generator)
    assert set(terms) == {"heatmap", "size", "offset", "equivariance", "total"}
    value = {k: float(t.detach()) for k, t in terms.items()}
    expected = value["heatmap"] + value["size"] + value["offset"] + 0.5 * value["equivariance"]
    assert value["total"] == pytest.approx(expected, rel=1e-6)
    assert value["equivariance"] > 0
    without = DetectionLoss(LossConfig(equivariance=False))(model, images, BOXES)
    assert float(without["equivariance"]) == 0.0
    assert float(without["total"].detach()) == pytest.approx(value["total"] - 0.5 * value["equivariance"],
                                                             rel=1e-5)
    terms["total"].backward()
    assert all(p.grad is not None for p in model.head.parameters())
