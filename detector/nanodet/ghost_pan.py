"""Ghost-PAN, NanoDet-Plus's neck (after RangiLyu/nanodet `nanodet/model/fpn/ghost_pan.py`): the
backbone's three levels reduced to one width, fused top-down then bottom-up by Ghost bottlenecks,
plus an extra level at twice the coarsest stride (strides 8, 16, 32, 64 out)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import Tensor, nn

from detector.nanodet.blocks import ConvAct, DepthwiseSeparable, depthwise


class GhostModule(nn.Module):
    """GhostNet's module: a 1x1 convolution makes half the output channels, a cheap depthwise 3x3 on
    those makes the other half (both activated, or neither)."""

    def __init__(self, in_channels: int, out_channels: int, act: bool) -> None:
        super().__init__()
        primary = math.ceil(out_channels / 2)
        self.out_channels = out_channels
        self.primary = ConvAct(in_channels, primary, 1, act=act)
        self.cheap = depthwise(primary, 3, act=act)

    def forward(self, x: Tensor) -> Tensor:
        x1 = self.primary(x)  # (B, out/2, H, W)
        return torch.cat([x1, self.cheap(x1)], dim=1)[:, :self.out_channels]


class GhostBottleneck(nn.Module):
    """Two Ghost modules (the second without activation) plus a shortcut: identity where the widths
    agree, else a depthwise k x k then a 1x1 projection (neither activated)."""

    def __init__(self, in_channels: int, mid_channels: int, out_channels: int, kernel_size: int) -> None:
        super().__init__()
        self.ghost1 = GhostModule(in_channels, mid_channels, act=True)
        self.ghost2 = GhostModule(mid_channels, out_channels, act=False)
        self.shortcut = (nn.Sequential() if in_channels == out_channels else
                         nn.Sequential(depthwise(in_channels, kernel_size, act=False),
                                       ConvAct(in_channels, out_channels, 1, act=False)))

    def forward(self, x: Tensor) -> Tensor:
        return self.ghost2(self.ghost1(x)) + self.shortcut(x)  # (B, out, H, W)


class GhostPAN(nn.Module):
    """Backbone levels [(B, c_i, H/s_i, W/s_i)] -> [(B, width, H/s, W/s) for s in 8, 16, 32, 64]."""

    def __init__(self, in_channels: Sequence[int], width: int = 96, kernel_size: int = 5) -> None:
        super().__init__()
        levels = len(in_channels)
        self.reduce = nn.ModuleList([ConvAct(c, width, 1) for c in in_channels])
        self.top_down = nn.ModuleList([GhostBottleneck(2 * width, width, width, kernel_size)
                                       for _ in range(levels - 1)])
        self.downsamples = nn.ModuleList([DepthwiseSeparable(width, width, kernel_size, stride=2)
                                          for _ in range(levels - 1)])
        self.bottom_up = nn.ModuleList([GhostBottleneck(2 * width, width, width, kernel_size)
                                        for _ in range(levels - 1)])
        self.extra_in = DepthwiseSeparable(width, width, kernel_size, stride=2)
        self.extra_out = DepthwiseSeparable(width, width, kernel_size, stride=2)

    @staticmethod
    def _upsample(x: Tensor) -> Tensor:
        return nn.functional.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)

    def forward(self, features: Sequence[Tensor]) -> list[Tensor]:
        reduced = [reduce(x) for reduce, x in zip(self.reduce, features, strict=True)]
        inner = [reduced[-1]]  # top-down, coarsest first
        for block, low in zip(self.top_down, reversed(reduced[:-1]), strict=True):
            inner.insert(0, block(torch.cat([self._upsample(inner[0]), low], dim=1)))
        outs = [inner[0]]  # bottom-up, finest first
        for down, block, high in zip(self.downsamples, self.bottom_up, inner[1:], strict=True):
            outs.append(block(torch.cat([down(outs[-1]), high], dim=1)))
        outs.append(self.extra_in(reduced[-1]) + self.extra_out(outs[-1]))  # (B, width, H/64, W/64)
        return outs
