"""The small blocks of NanoDet-Plus (after RangiLyu/nanodet `nanodet/model/module/conv.py`).

Every convolution is a `ConvAct`: a Conv2d whose bias already holds the folded BatchNorm, then
LeakyReLU(0.1) where NanoDet has an activation. That is the form the released weights carry
(`../shared/pretrained/nanodet-plus-m_416.onnx`), so they load one-to-one, as YOLOX's do
(`detector.yolox.blocks`).
"""

from __future__ import annotations

from torch import Tensor, nn

LEAKY_SLOPE = 0.1  # NanoDet-Plus's LeakyReLU


class ConvAct(nn.Module):
    """k x k convolution with bias (BatchNorm folded), then LeakyReLU(0.1) if `act`; 'same' padding."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1,
                 groups: int = 1, act: bool = True) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel_size, stride,
                              padding=(kernel_size - 1) // 2, groups=groups, bias=True)
        self.act: nn.Module = nn.LeakyReLU(LEAKY_SLOPE) if act else nn.Identity()

    @property
    def has_act(self) -> bool:
        return isinstance(self.act, nn.LeakyReLU)

    def forward(self, x: Tensor) -> Tensor:
        return self.act(self.conv(x))  # (B, out, H / stride, W / stride)


def depthwise(channels: int, kernel_size: int, stride: int = 1, act: bool = True) -> ConvAct:
    """A depthwise k x k `ConvAct` (one filter per channel)."""
    return ConvAct(channels, channels, kernel_size, stride, groups=channels, act=act)


class DepthwiseSeparable(nn.Module):
    """NanoDet's DepthwiseConvModule: depthwise k x k (carries the stride), then pointwise 1x1,
    each followed by LeakyReLU."""

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1) -> None:
        super().__init__()
        self.depthwise = depthwise(in_channels, kernel_size, stride)
        self.pointwise = ConvAct(in_channels, out_channels, 1)

    def forward(self, x: Tensor) -> Tensor:
        return self.pointwise(self.depthwise(x))  # (B, out, H / stride, W / stride)
