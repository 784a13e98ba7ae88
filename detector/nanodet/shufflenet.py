"""ShuffleNetV2 1.0x, NanoDet-Plus-m's backbone (after RangiLyu/nanodet
`nanodet/model/backbone/shufflenetv2.py`, itself after torchvision's): a stride-2 stem and max-pool,
then three stages of shuffle units; the stages' outputs (strides 8, 16, 32) feed the neck."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import pairwise

import torch
from torch import Tensor, nn

from detector.nanodet.blocks import ConvAct, depthwise

STAGE_REPEATS = (4, 8, 4)
STAGE_CHANNELS = (24, 116, 232, 464)  # the stem's, then each stage's (ShuffleNetV2 1.0x)


def channel_shuffle(x: Tensor, groups: int) -> Tensor:
    """(B, C, H, W) -> (B, C, H, W) with the channels of `groups` interleaved (ShuffleNet)."""
    B, C, H, W = x.shape
    return x.reshape(B, groups, C // groups, H, W).transpose(1, 2).reshape(B, C, H, W)


class ShuffleUnit(nn.Module):
    """ShuffleNetV2's unit. Stride 1: half the channels pass, the other half go through `branch2`.
    Stride 2: the input goes through both branches (`branch1` downsamples it too). Then a shuffle."""

    def __init__(self, in_channels: int, out_channels: int, stride: int) -> None:
        super().__init__()
        if stride not in (1, 2) or out_channels % 2 or (stride == 1 and in_channels != out_channels):
            raise ValueError(f"no shuffle unit {in_channels} -> {out_channels} at stride {stride}")
        self.stride = stride
        half = out_channels // 2
        self.branch1 = (nn.Sequential(depthwise(in_channels, 3, stride, act=False),
                                      ConvAct(in_channels, half, 1))
                        if stride == 2 else nn.Sequential())
        branch2_in = in_channels if stride == 2 else half
        self.branch2 = nn.Sequential(ConvAct(branch2_in, half, 1), depthwise(half, 3, stride, act=False),
                                     ConvAct(half, half, 1))

    def forward(self, x: Tensor) -> Tensor:
        if self.stride == 1:
            kept, through = x.chunk(2, dim=1)  # (B, C/2, H, W) each
            out = torch.cat([kept, self.branch2(through)], dim=1)
        else:
            out = torch.cat([self.branch1(x), self.branch2(x)], dim=1)  # (B, out, H/2, W/2)
        return channel_shuffle(out, 2)


class ShuffleNetV2(nn.Module):
    """(B, 3, H, W) normalised BGR -> [(B, c, H/s, W/s) for (c, s) in (116, 8), (232, 16), (464, 32)]."""

    def __init__(self, repeats: Sequence[int] = STAGE_REPEATS,
                 channels: Sequence[int] = STAGE_CHANNELS) -> None:
        super().__init__()
        self.stem = ConvAct(3, channels[0], 3, stride=2)
        self.pool = nn.MaxPool2d(3, stride=2, padding=1)
        self.stages = nn.ModuleList()
        for count, (c_in, c_out) in zip(repeats, pairwise(channels), strict=True):
            units = [ShuffleUnit(c_in, c_out, 2), *[ShuffleUnit(c_out, c_out, 1) for _ in range(count - 1)]]
            self.stages.append(nn.Sequential(*units))
        self.out_channels = tuple(channels[1:])

    def forward(self, images: Tensor) -> list[Tensor]:
        x = self.pool(self.stem(images))  # (B, 24, H/4, W/4)
        outs: list[Tensor] = []
        for stage in self.stages:
            x = stage(x)
            outs.append(x)
        return outs
