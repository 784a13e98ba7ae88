"""The FishLoc network: a small stride-4 U-Net-like backbone and a centre-heatmap head.

`F(I)` (the backbone, `features`) maps a normalised image to a stride-4 feature map; `D` (the head,
`head`) maps features to dense predictions. The rotation-equivariant objective rotates the output of
`F` before `D`, so the head receives its own coordinate channels *after* any rotation: at every cell
it knows the radial direction (cos φ, sin φ) and the normalised radius from the input centre, the
principal point of the letterboxed input.

Every dense prediction is expressed in the radius-aligned frame of its cell, so it is invariant under
rotations about the principal point: the heatmap logit, `log w`, `log h` (input px) and the sub-cell
offset of the box centre along the ray and across it (cells).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import torch
from torch import Tensor, nn

HEATMAP, LOG_W, LOG_H, OFFSET_RADIAL, OFFSET_TANGENTIAL = range(5)
HEAD_CHANNELS = 5
STRIDE = 4


@dataclass(frozen=True)
class DetectorConfig:
    """Hyper-parameters of the network (saved in every checkpoint)."""

    input_size: int = 384
    # Sized for training from scratch on two CPU cores (~10 frames/s at 384 px).
    widths: tuple[int, ...] = (12, 24, 32, 64, 96)  # strides 2, 4, 8, 16, 32
    blocks: tuple[int, ...] = (1, 1, 2, 2, 1)
    neck_width: int = 24
    head_width: int = 24
    heatmap_prior: float = 0.01  # initial person probability of a cell (CenterNet's bias init)
    max_detections: int = 300
    pixel_mean: float = 0.45
    pixel_std: float = 0.25
    model_name: str = "fishloc-centernet"

    def __post_init__(self) -> None:
        if len(self.widths) != 5 or len(self.blocks) != 5:
            raise ValueError("widths and blocks need one entry per stride 2, 4, 8, 16, 32")
        if self.input_size % 32 != 0:
            raise ValueError(f"input_size must be a multiple of 32, got {self.input_size}")

    @property
    def output_size(self) -> int:
        return self.input_size // STRIDE

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> DetectorConfig:
        known = {k: v for k, v in record.items() if k in cls.__dataclass_fields__}
        for key in ("widths", "blocks"):
            if key in known:
                known[key] = tuple(known[key])
        return cls(**known)


def tiny_config(input_size: int = 64) -> DetectorConfig:
    """A network small enough for unit tests."""
    return DetectorConfig(input_size=input_size, widths=(8, 8, 12, 16, 16), blocks=(1, 1, 1, 1, 1),
                          neck_width=12, head_width=12, max_detections=20)


def polar_channels(height: int, width: int, input_size: int, like: Tensor) -> Tensor:
    """(1, 3, H, W) stride-4 cell coordinates: cos φ, sin φ and radius / (input_size / 2), measured
    in input pixels from the input centre ((S - 1) / 2, (S - 1) / 2) at each cell centre."""
    centre = (input_size - 1) / 2.0
    ys = torch.arange(height, dtype=like.dtype, device=like.device) * STRIDE + (STRIDE - 1) / 2 - centre
    xs = torch.arange(width, dtype=like.dtype, device=like.device) * STRIDE + (STRIDE - 1) / 2 - centre
    dy = ys[:, None].expand(height, width)
    dx = xs[None, :].expand(height, width)
    radius = torch.sqrt(dx * dx + dy * dy)
    safe = torch.clamp(radius, min=1e-6)
    grid = torch.stack([dx / safe, dy / safe, radius / (input_size / 2.0)], dim=0)
    return grid[None]


class ConvBnAct(nn.Sequential):
    """3x3 (or k x k) convolution, batch norm, ReLU."""

    def __init__(self, in_channels: int, out_channels: int, stride: int = 1, kernel: int = 3) -> None:
        super().__init__(
            nn.Conv2d(in_channels, out_channels, kernel, stride, kernel // 2, bias=False),
            nn.BatchNorm2d(out_channels),
            nn.ReLU(inplace=True),
        )


class ResidualBlock(nn.Module):
    """Two 3x3 convolutions with an identity shortcut."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv1 = ConvBnAct(channels, channels)
        self.conv2 = nn.Sequential(nn.Conv2d(channels, channels, 3, 1, 1, bias=False),
                                   nn.BatchNorm2d(channels))
        self.act = nn.ReLU(inplace=True)

    def forward(self, x: Tensor) -> Tensor:
        return self.act(x + self.conv2(self.conv1(x)))


class Stage(nn.Sequential):
    """A stride-2 convolution followed by residual blocks."""

    def __init__(self, in_channels: int, out_channels: int, blocks: int) -> None:
        layers: list[nn.Module] = [ConvBnAct(in_channels, out_channels, stride=2)]
        layers += [ResidualBlock(out_channels) for _ in range(max(0, blocks - 1))]
        super().__init__(*layers)


class Backbone(nn.Module):
    """`F`: normalised image (B, 3, S, S) -> features (B, C, S/4, S/4) through a U-Net-like neck."""

    def __init__(self, config: DetectorConfig) -> None:
        super().__init__()
        widths, blocks = config.widths, config.blocks
        in_channels = 3
        self.stages = nn.ModuleList()
        for width, count in zip(widths, blocks, strict=True):
            self.stages.append(Stage(in_channels, width, count))
            in_channels = width
        neck = config.neck_width
        # Lateral 1x1 projections of strides 4..32, merged top-down and smoothed.
        self.laterals = nn.ModuleList([nn.Conv2d(w, neck, 1) for w in widths[1:]])
        self.smooth = nn.ModuleList([ConvBnAct(neck, neck) for _ in widths[1:-1]])
        self.upsample = nn.Upsample(scale_factor=2, mode="nearest")

    def forward(self, image: Tensor) -> Tensor:
        x = image  # (B, 3, S, S)
        skips: list[Tensor] = []
        for stage in self.stages:
            x = stage(x)
            skips.append(x)
        top = self.laterals[-1](skips[-1])  # (B, neck, S/32, S/32)
        for level in range(len(self.smooth) - 1, -1, -1):  # strides 16, 8, 4
            top = self.smooth[level](self.laterals[level](skips[level + 1]) + self.upsample(top))
        return top  # (B, neck, S/4, S/4)


class Head(nn.Module):
    """`D`: features (B, C, h, w) + polar coordinate channels -> dense predictions (B, 5, h, w)."""

    def __init__(self, config: DetectorConfig) -> None:
        super().__init__()
        self.input_size = config.input_size
        width = config.head_width
        self.trunk = nn.Sequential(
            ConvBnAct(config.neck_width + 3, width),
            ConvBnAct(width, width, kernel=1),
        )
        self.heatmap = nn.Conv2d(width, 1, 1)
        self.regression = nn.Conv2d(width, HEAD_CHANNELS - 1, 1)
        assert self.heatmap.bias is not None and self.regression.bias is not None
        prior = config.heatmap_prior
        nn.init.constant_(self.heatmap.bias, float(torch.log(torch.tensor(prior / (1 - prior)))))
        nn.init.normal_(self.regression.weight, std=1e-3)
        # log sizes start near a mid-sized person (~ input_size / 16 px)
        with torch.no_grad():
            self.regression.bias.copy_(torch.tensor(
                [float(torch.log(torch.tensor(config.input_size / 24.0))),
                 float(torch.log(torch.tensor(config.input_size / 12.0))), 0.0, 0.0]))

    def forward(self, features: Tensor) -> Tensor:
        B, _, h, w = features.shape  # (B, C, h, w)
        polar = polar_channels(h, w, self.input_size, features).expand(B, 3, h, w)
        x = self.trunk(torch.cat([features, polar], dim=1))
        return torch.cat([self.heatmap(x), self.regression(x)], dim=1)  # (B, 5, h, w)


class FishLocNet(nn.Module):
    """The detector: `head(features(image))`; `image` is normalised float (B, 3, S, S)."""

    def __init__(self, config: DetectorConfig) -> None:
        super().__init__()
        self.config = config
        self.backbone = Backbone(config)
        self.head = Head(config)

    def features(self, image: Tensor) -> Tensor:
        return self.backbone(image)

    def forward(self, image: Tensor) -> Tensor:
        return self.head(self.features(image))

    def normalise(self, image_uint8_nhwc: Tensor) -> Tensor:
        """(B, S, S, 3) uint8 RGB -> (B, 3, S, S) float, as the exported graph does it."""
        image = image_uint8_nhwc.permute(0, 3, 1, 2).to(torch.float32) / 255.0
        return (image - self.config.pixel_mean) / self.config.pixel_std


def build_model(config: DetectorConfig) -> FishLocNet:
    return FishLocNet(config)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
