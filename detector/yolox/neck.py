"""PAFPN, the neck of YOLOX (after Megvii YOLOX `yolox/models/yolo_pafpn.py`).

A top-down path (stride 32 -> 16 -> 8) then a bottom-up one (8 -> 16 -> 32), each step a
concatenation and a CSP block without shortcuts. Module names follow YOLOX's, lower-cased.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional

from detector.yolox.blocks import BaseConv, CSPLayer, conv_block


def upsample2(x: Tensor) -> Tensor:
    """(B, C, h, w) -> (B, C, 2h, 2w), nearest neighbour (YOLOX's nn.Upsample)."""
    return functional.interpolate(x, scale_factor=2.0, mode="nearest")


class TopDownFPN(nn.Module):
    """The top-down path of `PAFPN` alone (its module names): backbone features (strides 8, 16, 32)
    -> its stride-8 output, its stride-16 one and the stride-32 backbone feature, the shapes of
    `PAFPN`'s outputs at a fraction of its cost (the bottom-up path is 41 % of it). The foot branch
    reads it where `YoloxConfig.foot_neck_top_down` (docs/DETECTOR.md, "A lighter foot neck")."""

    def __init__(self, channels: tuple[int, int, int], depth: int, depthwise: bool) -> None:
        super().__init__()
        c3, c4, c5 = channels
        self.lateral_conv0 = BaseConv(c5, c4, 1)
        self.c3_p4 = CSPLayer(2 * c4, c4, n=depth, shortcut=False, depthwise=depthwise)
        self.reduce_conv1 = BaseConv(c4, c3, 1)
        self.c3_p3 = CSPLayer(2 * c3, c3, n=depth, shortcut=False, depthwise=depthwise)

    def top_down(self, features: tuple[Tensor, Tensor, Tensor]) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        """(stride-8 output, stride-16 output, the stride-16 and stride-32 laterals)."""
        dark3, dark4, dark5 = features  # (B, c3, H/8, W/8), (B, c4, H/16, W/16), (B, c5, H/32, W/32)

        fpn_out0 = self.lateral_conv0(dark5)  # (B, c4, H/32, W/32)
        f_out0 = torch.cat([upsample2(fpn_out0), dark4], dim=1)  # (B, 2 c4, H/16, W/16)
        f_out0 = self.c3_p4(f_out0)  # (B, c4, H/16, W/16)

        fpn_out1 = self.reduce_conv1(f_out0)  # (B, c3, H/16, W/16)
        f_out1 = torch.cat([upsample2(fpn_out1), dark3], dim=1)  # (B, 2 c3, H/8, W/8)
        pan_out2 = self.c3_p3(f_out1)  # (B, c3, H/8, W/8)
        return pan_out2, f_out0, fpn_out1, fpn_out0

    def forward(self, features: tuple[Tensor, Tensor, Tensor]) -> tuple[Tensor, Tensor, Tensor]:
        pan_out2, f_out0, _, _ = self.top_down(features)
        return pan_out2, f_out0, features[2]


class PAFPN(TopDownFPN):
    """Backbone features (strides 8, 16, 32; `channels` c3, c4, c5) -> fused features, same shapes."""

    def __init__(self, channels: tuple[int, int, int], depth: int, depthwise: bool) -> None:
        super().__init__(channels, depth, depthwise)
        c3, c4, c5 = channels
        # bottom-up
        self.bu_conv2 = conv_block(c3, c3, 3, 2, depthwise)
        self.c3_n3 = CSPLayer(2 * c3, c4, n=depth, shortcut=False, depthwise=depthwise)
        self.bu_conv1 = conv_block(c4, c4, 3, 2, depthwise)
        self.c3_n4 = CSPLayer(2 * c4, c5, n=depth, shortcut=False, depthwise=depthwise)

    def forward(self, features: tuple[Tensor, Tensor, Tensor]) -> tuple[Tensor, Tensor, Tensor]:
        pan_out2, _, fpn_out1, fpn_out0 = self.top_down(features)

        p_out1 = torch.cat([self.bu_conv2(pan_out2), fpn_out1], dim=1)  # (B, 2 c3, H/16, W/16)
        pan_out1 = self.c3_n3(p_out1)  # (B, c4, H/16, W/16)

        p_out0 = torch.cat([self.bu_conv1(pan_out1), fpn_out0], dim=1)  # (B, 2 c4, H/32, W/32)
        pan_out0 = self.c3_n4(p_out0)  # (B, c5, H/32, W/32)

        return pan_out2, pan_out1, pan_out0
