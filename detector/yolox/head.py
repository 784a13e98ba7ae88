"""The decoupled head of YOLOX (after Megvii YOLOX `yolox/models/yolo_head.py`).

Per level (strides 8, 16, 32): a 1x1 stem to the head width, then two branches of two 3x3
convolutions each: the class branch ends in `cls_preds`, the box branch in `reg_preds` (4) and
`obj_preds` (1). The maps come out raw: box offsets and log sizes in cells, objectness and class
logits; `detector.yolox.decode` turns them into boxes and probabilities.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor, nn

from detector.yolox.blocks import BaseConv, conv_block

BOX_CHANNELS = 4  # x, y offsets (cells), log w, log h (log cells)
OBJECTNESS = 4  # channel of the objectness logit; the class logits follow it
CLASSES_START = 5


class YoloxHead(nn.Module):
    """Features of the 3 levels (B, c_i, h_i, w_i) -> maps (B, 4 + 1 + num_classes, h_i, w_i)."""

    def __init__(self, num_classes: int, in_channels: Sequence[int], width: int, depthwise: bool,
                 prior_prob: float = 0.01) -> None:
        super().__init__()
        self.num_classes = num_classes
        levels = range(len(in_channels))
        self.stems = nn.ModuleList([BaseConv(c, width, 1) for c in in_channels])
        self.cls_convs = nn.ModuleList([self._branch(width, depthwise) for _ in levels])
        self.reg_convs = nn.ModuleList([self._branch(width, depthwise) for _ in levels])
        self.cls_preds = nn.ModuleList([nn.Conv2d(width, num_classes, 1) for _ in levels])
        self.reg_preds = nn.ModuleList([nn.Conv2d(width, BOX_CHANNELS, 1) for _ in levels])
        self.obj_preds = nn.ModuleList([nn.Conv2d(width, 1, 1) for _ in levels])
        # YOLOX starts every cell at probability `prior_prob` for objectness and for each class.
        prior_logit = -math.log((1 - prior_prob) / prior_prob)
        for pred in [*self.cls_preds, *self.obj_preds]:
            assert isinstance(pred, nn.Conv2d) and pred.bias is not None
            nn.init.constant_(pred.bias, prior_logit)

    @staticmethod
    def _branch(width: int, depthwise: bool) -> nn.Sequential:
        return nn.Sequential(conv_block(width, width, 3, 1, depthwise),
                             conv_block(width, width, 3, 1, depthwise))

    def forward(self, features: Sequence[Tensor]) -> list[Tensor]:
        return self.forward_features(features)[0]

    def forward_features(self, features: Sequence[Tensor]) -> tuple[list[Tensor], list[Tensor]]:
        """The maps and, per level, the stem's output (B, width, h, w) both branches read (what a
        foot branch reads too, `detector.yolox.foot`)."""
        maps: list[Tensor] = []
        stem_features: list[Tensor] = []
        for x, stem, cls_conv, reg_conv, cls_pred, reg_pred, obj_pred in zip(
                features, self.stems, self.cls_convs, self.reg_convs, self.cls_preds, self.reg_preds,
                self.obj_preds, strict=True):
            x = stem(x)  # (B, width, h, w)
            cls_logits = cls_pred(cls_conv(x))  # (B, C, h, w)
            reg_features = reg_conv(x)  # (B, width, h, w)
            box = reg_pred(reg_features)  # (B, 4, h, w)
            obj_logit = obj_pred(reg_features)  # (B, 1, h, w)
            maps.append(torch.cat([box, obj_logit, cls_logits], dim=1))  # (B, 5 + C, h, w)
            stem_features.append(x)
        return maps, stem_features
