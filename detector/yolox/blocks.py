"""The small blocks of YOLOX (after Megvii YOLOX `yolox/models/network_blocks.py`).

Every convolution is a `BaseConv`: a Conv2d whose bias already holds the folded BatchNorm, then
SiLU. That is the form the released ONNX carries, so the pretrained weights load one-to-one; it
also means fine-tuning runs without BatchNorm (the statistics are frozen into the biases).
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn import functional


class BaseConv(nn.Module):
    """k x k convolution with bias (BatchNorm folded) and SiLU; 'same' padding, any stride."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1,
                 groups: int = 1) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel_size, stride,
                              padding=(kernel_size - 1) // 2, groups=groups, bias=True)
        self.act = nn.SiLU()

    def forward(self, x: Tensor) -> Tensor:
        return self.act(self.conv(x))  # (B, out, H / stride, W / stride)


class DWConv(nn.Module):
    """Depthwise k x k convolution (carries the stride) followed by a pointwise 1x1 one."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1) -> None:
        super().__init__()
        self.dconv = BaseConv(in_channels, in_channels, kernel_size, stride, groups=in_channels)
        self.pconv = BaseConv(in_channels, out_channels, 1)

    def forward(self, x: Tensor) -> Tensor:
        return self.pconv(self.dconv(x))  # (B, out, H / stride, W / stride)


def conv_block(in_channels: int, out_channels: int, kernel_size: int, stride: int,
               depthwise: bool) -> BaseConv | DWConv:
    """The spatial convolution of YOLOX: depthwise-separable in the Nano, dense otherwise."""
    if depthwise:
        return DWConv(in_channels, out_channels, kernel_size, stride)
    return BaseConv(in_channels, out_channels, kernel_size, stride)


class Bottleneck(nn.Module):
    """1x1 then 3x3 convolution, with an identity shortcut when asked and the widths agree."""

    def __init__(self, in_channels: int, out_channels: int, shortcut: bool, depthwise: bool) -> None:
        super().__init__()
        hidden = out_channels  # YOLOX's CSP bottlenecks use expansion 1.0
        self.conv1 = BaseConv(in_channels, hidden, 1)
        self.conv2 = conv_block(hidden, out_channels, 3, 1, depthwise)
        self.use_add = shortcut and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.conv2(self.conv1(x))  # (B, out, H, W)
        return x + y if self.use_add else y


class CSPLayer(nn.Module):
    """Cross-stage partial block: half the channels go through `n` bottlenecks, half go around."""

    def __init__(self, in_channels: int, out_channels: int, n: int, shortcut: bool = True,
                 depthwise: bool = False) -> None:
        super().__init__()
        hidden = out_channels // 2
        self.conv1 = BaseConv(in_channels, hidden, 1)
        self.conv2 = BaseConv(in_channels, hidden, 1)
        self.conv3 = BaseConv(2 * hidden, out_channels, 1)
        self.m = nn.Sequential(*[Bottleneck(hidden, hidden, shortcut, depthwise) for _ in range(n)])

    def forward(self, x: Tensor) -> Tensor:
        through = self.conv1(x)  # (B, out / 2, H, W)
        around = self.conv2(x)  # (B, out / 2, H, W)
        through = self.m(through)  # after conv2, as YOLOX runs it (and its export orders the convs)
        return self.conv3(torch.cat([through, around], dim=1))  # (B, out, H, W)


class Focus(nn.Module):
    """Space-to-depth stem: each 2x2 pixel block becomes 4 x C channels (YOLOX's order: top left,
    bottom left, top right, bottom right), then a dense k x k conv.

    Both steps together are one convolution of the image with a 2k x 2k kernel at stride 2 (YOLOv5
    runs its Focus so): the same sums, and what `forward` runs (images of even sides). In onnxruntime
    it costs 0.6x the slices, the channel concatenation and the k x k conv on the 2x2 blocks
    (10.8 against 17.7 ms on a 416 x 1792 strip, the stem with its SiLU; docs/DETECTOR.md, "The nadir view and
    a faster graph")."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int = 3) -> None:
        super().__init__()
        self.conv = BaseConv(4 * in_channels, out_channels, kernel_size)

    def strided_weight(self) -> Tensor:
        """The k x k weight over 4C block channels as a 2k x 2k weight over the C image channels:
        block channel (2 dx + dy) C + c, tap (a, b) reads pixel (2a + dy, 2b + dx) of channel c."""
        weight = self.conv.conv.weight  # (O, 4C, k, k)
        out, blocks, k, _ = weight.shape
        channels = blocks // 4
        split = weight.reshape(out, 2, 2, channels, k, k)  # (O, dx, dy, C, a, b)
        return split.permute(0, 3, 4, 2, 5, 1).reshape(out, channels, 2 * k, 2 * k)  # (O, C, a dy, b dx)

    def forward(self, x: Tensor) -> Tensor:
        conv = self.conv.conv
        assert isinstance(conv.padding, tuple)
        padding = 2 * int(conv.padding[0])
        strided = functional.conv2d(x, self.strided_weight(), conv.bias, stride=2, padding=padding)
        return self.conv.act(strided)  # (B, out, H / 2, W / 2)


class SPPBottleneck(nn.Module):
    """Spatial pyramid pooling: stride-1 max pools of several sizes, concatenated, then mixed."""

    def __init__(self, in_channels: int, out_channels: int,
                 kernel_sizes: tuple[int, ...] = (5, 9, 13)) -> None:
        super().__init__()
        hidden = in_channels // 2
        self.conv1 = BaseConv(in_channels, hidden, 1)
        self.pools = nn.ModuleList([nn.MaxPool2d(k, stride=1, padding=k // 2) for k in kernel_sizes])
        self.conv2 = BaseConv(hidden * (len(kernel_sizes) + 1), out_channels, 1)

    def forward(self, x: Tensor) -> Tensor:
        x = self.conv1(x)  # (B, in / 2, H, W)
        pooled = torch.cat([x, *[pool(x) for pool in self.pools]], dim=1)  # (B, 2 in, H, W)
        return self.conv2(pooled)  # (B, out, H, W)
