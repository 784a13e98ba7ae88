"""NanoDet-Plus-m: ShuffleNetV2 1.0x backbone, Ghost-PAN neck and NanoDet-Plus head (after
RangiLyu/nanodet, config `nanodet-plus-m_416.yml`), sized by `NanoDetConfig`.

The network takes what YOLOX's does (`detector.yolox.network`): float32 (B, 3, H, W) **BGR**
images with values 0-255, H and W multiples of 32 (any size, not only 416); it normalises them as
NanoDet was trained (ImageNet mean and std, BGR). It returns the raw head maps of strides 8, 16,
32, 64; `detector.nanodet.decode` turns them into boxes in pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import torch
from torch import Tensor, nn

from detector.nanodet.ghost_pan import GhostPAN
from detector.nanodet.head import BOX_CHANNELS, NanoDetHead
from detector.nanodet.shufflenet import ShuffleNetV2

STRIDES = (8, 16, 32, 64)  # of the head levels, in output order
PERSON = 0  # COCO class index
BGR_MEAN = (103.53, 116.28, 123.675)
BGR_STD = (57.375, 57.12, 58.395)


@dataclass(frozen=True)
class NanoDetConfig:
    """Hyper-parameters of a NanoDet-Plus network; the defaults are NanoDet-Plus-m on COCO."""

    num_classes: int = 80
    width: int = 96  # of the neck and head
    kernel_size: int = 5  # of the neck's and head's depthwise convolutions
    model_name: str = "nanodet-plus-m"

    def __post_init__(self) -> None:
        if self.num_classes < 1:
            raise ValueError(f"num_classes must be at least 1, got {self.num_classes}")


class NanoDetPlus(nn.Module):
    """(B, 3, H, W) BGR 0-255 -> [(B, C + 32, H/s, W/s) for s in 8, 16, 32, 64], raw maps.

    Channels of a map: C class logits, then 4 x 8 distance-distribution logits (`head.distances`).
    """

    def __init__(self, config: NanoDetConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or NanoDetConfig()
        self.backbone = ShuffleNetV2()
        self.neck = GhostPAN(self.backbone.out_channels, config.width, config.kernel_size)
        self.head = NanoDetHead(config.num_classes, config.width, len(STRIDES), config.kernel_size)
        self.mean: Tensor
        self.std: Tensor
        self.register_buffer("mean", torch.tensor(BGR_MEAN).reshape(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(BGR_STD).reshape(1, 3, 1, 1), persistent=False)

    def forward(self, images: Tensor) -> list[Tensor]:
        normalised = (images - self.mean) / self.std  # (B, 3, H, W)
        maps: list[Tensor] = self.head(self.neck(self.backbone(normalised)))
        return maps

    def to_person_only(self) -> NanoDetPlus:
        """A copy that predicts COCO's person class alone (C = 1)."""
        return keep_classes(self, [PERSON])


def keep_classes(model: NanoDetPlus, classes: Sequence[int]) -> NanoDetPlus:
    """A copy of `model` whose class predictions are `classes` only, in that order; the box
    distributions and every other weight unchanged, so the kept classes score exactly as before."""
    count = model.config.num_classes
    if not classes or len(set(classes)) != len(classes) or not all(0 <= c < count for c in classes):
        raise ValueError(f"classes must be distinct indices in [0, {count}), got {list(classes)}")
    subset = NanoDetPlus(replace(model.config, num_classes=len(classes)))
    rows = torch.tensor([*classes, *range(count, count + BOX_CHANNELS)], dtype=torch.long)  # kept, then boxes
    state = model.state_dict()
    for key, value in state.items():
        if key.startswith("head.preds."):
            state[key] = value.index_select(0, rows.to(value.device))
    subset.load_state_dict(state, strict=True)
    return subset.to(next(model.parameters()).device).train(model.training)
