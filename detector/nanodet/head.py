"""NanoDet-Plus's head (after RangiLyu/nanodet `nanodet/model/head/nanodet_plus_head.py`): per
level two depthwise-separable 5x5 convolutions, then one 1x1 prediction of the class logits and
the generalised-focal-loss box distributions (4 sides x `BINS` bins each)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from detector.nanodet.blocks import DepthwiseSeparable

BINS = 8  # per box side: distances 0 .. 7 strides (NanoDet's reg_max 7)
BOX_CHANNELS = 4 * BINS  # after the class logits: left, top, right, bottom distributions


class NanoDetHead(nn.Module):
    """Neck levels (B, width, h_i, w_i) -> maps (B, num_classes + 4 * BINS, h_i, w_i): class logits,
    then the logits of each side's distance distribution."""

    def __init__(self, num_classes: int, width: int, levels: int, kernel_size: int = 5,
                 stacked: int = 2) -> None:
        super().__init__()
        self.num_classes = num_classes
        self.convs = nn.ModuleList([
            nn.Sequential(*[DepthwiseSeparable(width, width, kernel_size) for _ in range(stacked)])
            for _ in range(levels)])
        self.preds = nn.ModuleList([nn.Conv2d(width, num_classes + BOX_CHANNELS, 1) for _ in range(levels)])

    def forward(self, features: Sequence[Tensor]) -> list[Tensor]:
        return [pred(convs(x)) for x, convs, pred in zip(features, self.convs, self.preds, strict=True)]


def distances(box_logits: Tensor) -> Tensor:
    """(..., 4 * BINS) distribution logits -> (..., 4) expected distances in strides (left, top,
    right, bottom): the softmax-weighted mean of the bins 0 .. BINS - 1 (GFL's integral)."""
    probabilities = box_logits.unflatten(-1, (4, BINS)).softmax(dim=-1)  # (..., 4, BINS)
    bins = torch.arange(BINS, dtype=box_logits.dtype, device=box_logits.device)
    return (probabilities * bins).sum(dim=-1)
