"""Design (c): one YOLOX reading the polar strip with a second head for the inner disc.

The COCO network reads the ring well but never finds people near the nadir, who are seen from above
and smeared along the strip's bottom rows; fine-tuning the whole network on renders teaches it
those people but costs it real ones elsewhere (README, "Detector"). Here the backbone, neck and
head stay COCO's, and a copy of the head (`inner_head`) answers for the cells whose centre lies in
the bottom `inner_fraction` of the strip's rows, i.e. the disc within `inner_fraction` of the
strip's radius. Trained with everything else frozen, it can only change what the model says there.
"""

from __future__ import annotations

import copy

import torch
from torch import Tensor

from detector.yolox.head import YoloxHead
from detector.yolox.network import YoloxConfig, YoloxNano


class InnerHeadYolox(YoloxNano):
    """YoloxNano whose cells in the bottom `inner_fraction` of the input's rows come from
    `inner_head`; (B, 3, H, W) BGR 0-255 -> [(B, 5 + C, H/s, W/s) for s in 8, 16, 32]."""

    def __init__(self, config: YoloxConfig, inner_fraction: float) -> None:
        super().__init__(config)
        if not 0.0 < inner_fraction < 1.0:
            raise ValueError(f"inner_fraction must lie in (0, 1), got {inner_fraction}")
        self.inner_fraction = inner_fraction
        self.inner_head = copy.deepcopy(self.head)

    @classmethod
    def from_network(cls, network: YoloxNano, inner_fraction: float) -> InnerHeadYolox:
        """`network` with a copy of its head as the inner head (both answer alike to begin with)."""
        model = cls(network.config, inner_fraction)
        state = network.state_dict()
        state.update({f"inner_{k}": v for k, v in state.items() if k.startswith("head.")})
        model.load_state_dict(state, strict=True)
        return model

    def forward(self, images: Tensor) -> list[Tensor]:
        _, _, height, _ = images.shape  # (B, 3, H, W)
        features = self.neck(self.backbone(images))
        outer: list[Tensor] = self.head(features)
        inner: list[Tensor] = YoloxHead.forward(self.inner_head, features)
        first_inner_row = height * (1.0 - self.inner_fraction)  # input px
        merged = []
        for outer_map, inner_map in zip(outer, inner, strict=True):
            rows = outer_map.shape[2]  # (B, 5 + C, h, w)
            stride = height / rows
            centres = (torch.arange(rows, dtype=outer_map.dtype, device=outer_map.device) + 0.5) * stride
            is_inner = (centres >= first_inner_row).reshape(1, 1, rows, 1)
            merged.append(torch.where(is_inner, inner_map, outer_map))
        return merged
