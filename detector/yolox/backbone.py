"""CSPDarknet, the backbone of YOLOX (after Megvii YOLOX `yolox/models/darknet.py`).

A Focus stem and four stages, each a stride-2 convolution and a CSP block; the last stage pools
with an SPP block first. It returns the stride 8, 16 and 32 features ("dark3", "dark4", "dark5").
"""

from __future__ import annotations

from torch import Tensor, nn

from detector.yolox.blocks import CSPLayer, Focus, SPPBottleneck, conv_block


class CSPDarknet(nn.Module):
    """(B, 3, H, W) image -> features at strides 8, 16, 32 with 4, 8 and 16 x `base_channels`.

    `base_channels` is 64 x width (16 in the Nano); `base_depth` is the number of bottlenecks of the
    first and last CSP blocks (the middle ones have 3 x that).
    """

    def __init__(self, base_channels: int, base_depth: int, depthwise: bool) -> None:
        super().__init__()
        c, d = base_channels, base_depth
        self.stem = Focus(3, c, kernel_size=3)  # dense even in the Nano, as in YOLOX
        self.dark2 = nn.Sequential(
            conv_block(c, 2 * c, 3, 2, depthwise),
            CSPLayer(2 * c, 2 * c, n=d, depthwise=depthwise),
        )
        self.dark3 = nn.Sequential(
            conv_block(2 * c, 4 * c, 3, 2, depthwise),
            CSPLayer(4 * c, 4 * c, n=3 * d, depthwise=depthwise),
        )
        self.dark4 = nn.Sequential(
            conv_block(4 * c, 8 * c, 3, 2, depthwise),
            CSPLayer(8 * c, 8 * c, n=3 * d, depthwise=depthwise),
        )
        self.dark5 = nn.Sequential(
            conv_block(8 * c, 16 * c, 3, 2, depthwise),
            SPPBottleneck(16 * c, 16 * c),
            CSPLayer(16 * c, 16 * c, n=d, shortcut=False, depthwise=depthwise),
        )

    def forward(self, images: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        x = self.stem(images)  # (B, c, H/2, W/2)
        x = self.dark2(x)  # (B, 2c, H/4, W/4)
        dark3 = self.dark3(x)  # (B, 4c, H/8, W/8)
        dark4 = self.dark4(dark3)  # (B, 8c, H/16, W/16)
        dark5 = self.dark5(dark4)  # (B, 16c, H/32, W/32)
        return dark3, dark4, dark5
