"""Losses of the centre-heatmap detector, returned as named terms.

`L_det` is CenterNet's: a penalty-reduced focal loss on the heatmap, L1 on `log w`, `log h` and L1
on the radial/tangential centre offset at the people's cells, each normalised by the number of
people. The rotation-equivariant objective of LOAF (DESIGN.md) adds

    λ · L_det(D(rot(F(I), a)), rot(gt, a)),  λ = 0.5, a ~ U[0, 2π) per image,

where the features F(I) of the *unrotated* image are rotated about the principal point (the input
centre) with grid_sample, decoded by the head D, and supervised with the ground truth rotated about
the same point. This differs from rotation augmentation, which rotates the image before F.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor
from torch.nn import functional

from detector.model import HEATMAP, LOG_H, LOG_W, OFFSET_RADIAL, OFFSET_TANGENTIAL, FishLocNet
from detector.rotation import random_angles, rotate_boxes, rotate_features
from detector.targets import TargetConfig, Targets, build_batch_targets


@dataclass(frozen=True)
class LossConfig:
    heatmap_weight: float = 1.0
    size_weight: float = 1.0
    offset_weight: float = 1.0
    equivariance: bool = True
    equivariance_weight: float = 0.5  # λ of the paper
    focal_alpha: float = 2.0
    focal_beta: float = 4.0
    targets: TargetConfig = field(default_factory=TargetConfig)


def focal_heatmap_loss(logits: Tensor, target: Tensor, positives: Tensor, alpha: float, beta: float
                       ) -> Tensor:
    """CenterNet's focal loss: logits, target (B, 1, h, w), positives (B, h, w) bool -> scalar.

    -Σ_pos (1-p)^α log p - Σ_neg (1-y)^β p^α log(1-p), divided by max(#pos, 1).
    """
    positive = positives[:, None].to(logits.dtype)
    probability = torch.sigmoid(logits)
    log_p = functional.logsigmoid(logits)
    log_not_p = functional.logsigmoid(-logits)
    positive_term = (1 - probability) ** alpha * log_p * positive
    negative_term = (1 - target) ** beta * probability ** alpha * log_not_p * (1 - positive)
    count = torch.clamp(positive.sum(), min=1.0)
    return -(positive_term.sum() + negative_term.sum()) / count


def masked_l1(prediction: Tensor, target: Tensor, mask: Tensor) -> Tensor:
    """Mean over masked cells of the summed |error| of (B, C, h, w) maps; mask (B, h, w) bool."""
    weight = mask[:, None].to(prediction.dtype)
    count = torch.clamp(weight.sum(), min=1.0)
    return (torch.abs(prediction - target) * weight).sum() / count


def detection_terms(predictions: Tensor, targets: Targets, config: LossConfig) -> dict[str, Tensor]:
    """Head output (B, 5, h, w) against targets -> {"heatmap", "size", "offset"} (unweighted)."""
    return {
        "heatmap": focal_heatmap_loss(predictions[:, HEATMAP:HEATMAP + 1], targets.heatmap,
                                      targets.mask, config.focal_alpha, config.focal_beta),
        "size": masked_l1(predictions[:, LOG_W:LOG_H + 1], targets.regression[:, 0:2], targets.mask),
        "offset": masked_l1(predictions[:, OFFSET_RADIAL:OFFSET_TANGENTIAL + 1],
                            targets.regression[:, 2:4], targets.mask),
    }


def weighted_detection_loss(terms: dict[str, Tensor], config: LossConfig) -> Tensor:
    return (config.heatmap_weight * terms["heatmap"] + config.size_weight * terms["size"]
            + config.offset_weight * terms["offset"])


def equivariance_loss(features: Tensor, head: torch.nn.Module, boxes: Sequence[NDArray[np.floating]],
                      angles_rad: Tensor, input_size: int, config: LossConfig) -> Tensor:
    """L_det(D(rot(F(I), a)), rot(gt, a)) for features (B, C, h, w) and (B,) angles."""
    rotated = rotate_features(features, angles_rad.to(features.device), input_size)
    rotated_boxes = [rotate_boxes(b, float(a), input_size) for b, a in zip(boxes, angles_rad, strict=True)]
    targets = build_batch_targets(rotated_boxes, input_size, config.targets, features.device)
    return weighted_detection_loss(detection_terms(head(rotated), targets, config), config)


class DetectionLoss:
    """The training objective; `__call__` returns every named term and their weighted `total`."""

    def __init__(self, config: LossConfig) -> None:
        self.config = config

    def __call__(self, model: FishLocNet, images: Tensor, boxes: Sequence[NDArray[np.floating]],
                 generator: torch.Generator | None = None) -> dict[str, Tensor]:
        """images (B, 3, S, S) normalised; boxes: one (N_i, 4) input-px array per image."""
        config = self.config
        size = model.config.input_size
        features = model.features(images)  # (B, C, S/4, S/4)
        targets = build_batch_targets(boxes, size, config.targets, images.device)
        terms = detection_terms(model.head(features), targets, config)
        total = weighted_detection_loss(terms, config)
        if config.equivariance:
            angles = random_angles(len(boxes), generator)
            terms["equivariance"] = equivariance_loss(features, model.head, boxes, angles, size, config)
            total = total + config.equivariance_weight * terms["equivariance"]
        else:
            terms["equivariance"] = torch.zeros((), device=images.device)
        terms["total"] = total
        return terms
