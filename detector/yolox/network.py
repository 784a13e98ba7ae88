"""YOLOX-Nano: CSPDarknet backbone, PAFPN neck and decoupled head (after Megvii YOLOX
`yolox/models/yolox.py`), sized by `YoloxConfig`.

The network takes what the released ONNX takes: float32 (B, 3, H, W) **BGR** images with values
0-255, no normalisation, H and W multiples of 32 (any size, not only 416). It returns the raw head
maps of strides 8, 16, 32; `detector.yolox.decode` turns them into the ONNX's output layout or into
boxes in pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, Self

import torch
from torch import Tensor, nn

from detector.yolox.backbone import CSPDarknet
from detector.yolox.blocks import BaseConv
from detector.yolox.foot import FootHead, FootNeck
from detector.yolox.head import YoloxHead
from detector.yolox.neck import PAFPN, TopDownFPN

STRIDES = (8, 16, 32)  # of the head levels, in output order
PERSON = 0  # COCO class index


@dataclass(frozen=True)
class YoloxConfig:
    """Hyper-parameters of a YOLOX network; the defaults are YOLOX-Nano on COCO."""

    num_classes: int = 80
    depth: float = 0.33  # multiplies the number of bottlenecks
    width: float = 0.25  # multiplies every channel count
    depthwise: bool = True  # depthwise-separable 3x3 convolutions outside the stem
    prior_prob: float = 0.01  # initial objectness and class probability of an untrained head
    model_name: str = "yolox-nano"
    foot: bool = False  # a foot branch on the box branch (detector.yolox.foot)
    foot_refine: bool = False  # and its second stage on the stride-8 features (FootRefiner)
    foot_refine_steps: int = 1  # passes of that stage, each about the previous one's point
    foot_neck: bool = False  # the foot branch reads its own copy of the neck (FootNeck)
    # ... of its top-down path alone (neck.TopDownFPN; docs/DETECTOR.md, "A lighter foot neck")
    foot_neck_top_down: bool = False

    def __post_init__(self) -> None:
        if self.foot_neck_top_down and not self.foot_neck:
            raise ValueError("foot_neck_top_down cuts the foot's own neck (foot_neck)")
        if self.num_classes < 1:
            raise ValueError(f"num_classes must be at least 1, got {self.num_classes}")
        if self.depth <= 0 or self.width <= 0:
            raise ValueError(f"depth and width must be positive, got {self.depth}, {self.width}")

    @property
    def base_channels(self) -> int:
        return int(64 * self.width)  # the stem's output; 16 in the Nano

    @property
    def base_depth(self) -> int:
        return max(round(3 * self.depth), 1)  # bottlenecks of the outer backbone CSP blocks

    @property
    def neck_depth(self) -> int:
        return round(3 * self.depth)

    @property
    def level_channels(self) -> tuple[int, int, int]:
        return int(256 * self.width), int(512 * self.width), int(1024 * self.width)  # 64, 128, 256

    @property
    def head_width(self) -> int:
        return int(256 * self.width)  # 64 in the Nano


class YoloxNano(nn.Module):
    """(B, 3, H, W) BGR 0-255 -> [(B, 5 + C, H/s, W/s) for s in 8, 16, 32], raw maps.

    Channels of a map: x, y offset (cells), log w, log h (log cells), objectness logit, C class
    logits.
    """

    def __init__(self, config: YoloxConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or YoloxConfig()
        self.backbone = CSPDarknet(config.base_channels, config.base_depth, config.depthwise)
        self.neck = PAFPN(config.level_channels, config.neck_depth, config.depthwise)
        self.head = YoloxHead(config.num_classes, config.level_channels, config.head_width,
                              config.depthwise, config.prior_prob)
        self.foot = (FootHead(config.head_width, len(STRIDES), config.depthwise, config.foot_refine,
                              config.foot_refine_steps, self._foot_neck(config) if config.foot_neck else None)
                     if config.foot else None)

    @staticmethod
    def _foot_neck(config: YoloxConfig) -> FootNeck:
        fpn = TopDownFPN if config.foot_neck_top_down else PAFPN
        return FootNeck(fpn(config.level_channels, config.neck_depth, config.depthwise),
                        nn.ModuleList([BaseConv(c, config.head_width, 1) for c in config.level_channels]))

    def forward(self, images: Tensor) -> list[Tensor]:
        features = self.backbone(images)  # strides 8, 16, 32
        fused = self.neck(features)  # same shapes
        maps: list[Tensor] = self.head(fused)  # (B, 5 + C, H/s, W/s) per stride s
        return maps

    def forward_with_foot(self, images: Tensor) -> tuple[list[Tensor], list[Tensor], Tensor]:
        """The maps, the foot offsets (B, 2, H/s, W/s) per stride s and the stride-8 features the
        foot's refiner reads: the head's stem output, or its `FootNeck`'s where it has one (a
        network with a foot branch)."""
        if self.foot is None:
            raise ValueError("this network has no foot branch (YoloxConfig.foot)")
        levels = self.backbone(images)
        maps, stem_features = self.head.forward_features(self.neck(levels))
        if self.foot.features is not None:
            stem_features = self.foot.features(levels)
        offsets: list[Tensor] = self.foot(stem_features)
        return maps, offsets, stem_features[0]

    def _grown(self, new_weights: str | None, dropped: tuple[str, ...] = (), **changes: Any) -> YoloxNano:
        """A copy built with `changes` to the config, every weight copied but the new ones (all
        named `new_weights`...; None: no new one), which start as built, and those named `dropped`...,
        which the copy no longer has; on this network's device, in its mode."""
        grown = YoloxNano(replace(self.config, **changes))
        kept = {key: value for key, value in self.state_dict().items() if not key.startswith(dropped)}
        missing, unexpected = grown.load_state_dict(kept, strict=False)
        if unexpected or any(new_weights is None or not key.startswith(new_weights) for key in missing):
            raise ValueError(f"{changes}: unexpected weights {unexpected}, missing {missing}")
        return grown.to(next(self.parameters()).device).train(self.training)

    def with_foot_refiner(self) -> YoloxNano:
        """A copy whose foot branch has a new (untrained, identity) refiner; all else unchanged."""
        if self.foot is None:
            raise ValueError("a foot refiner needs a foot branch (YoloxConfig.foot)")
        return self._grown("foot.refiner.", foot_refine=True)

    def with_foot(self) -> YoloxNano:
        """A copy with a new foot branch (its convolutions a copy of the box branch's, its offsets
        zero: the box-side foot point until trained); every other weight is copied unchanged."""
        footed = self._grown("foot.", foot=True)
        assert footed.foot is not None
        for foot_convs, box_convs in zip(footed.foot.convs, footed.head.reg_convs, strict=True):
            foot_convs.load_state_dict(box_convs.state_dict())
        return footed

    def with_foot_neck(self) -> YoloxNano:
        """A copy whose foot branch reads its own neck (`FootNeck`), started as a copy of the
        detector's neck and stems, so that it answers as before until trained; all else unchanged."""
        if self.foot is None:
            raise ValueError("a foot neck needs a foot branch (YoloxConfig.foot)")
        necked = self._grown("foot.features.", foot_neck=True)
        assert necked.foot is not None and necked.foot.features is not None
        necked.foot.features.neck.load_state_dict(necked.neck.state_dict())
        necked.foot.features.stems.load_state_dict(necked.head.stems.state_dict())
        return necked

    def with_foot_neck_top_down(self) -> YoloxNano:
        """A copy whose foot neck keeps its top-down path alone (`neck.TopDownFPN`): its stride-8
        output unchanged, the stride-16 and stride-32 levels of the foot branch read the path's
        stride-16 output and the backbone's stride-32 feature in place of the bottom-up outputs
        (so those levels answer differently until trained); every kept weight is copied."""
        if self.foot is None or self.foot.features is None:
            raise ValueError("a top-down foot neck cuts the foot's own neck (YoloxConfig.foot_neck)")
        bottom_up = tuple(f"foot.features.neck.{name}." for name in ("bu_conv2", "c3_n3", "bu_conv1",
                                                                     "c3_n4"))
        return self._grown(None, dropped=bottom_up, foot_neck_top_down=True)

    def with_foot_refine_steps(self, steps: int) -> YoloxNano:
        """A copy whose foot refiner runs `steps` passes; every weight unchanged."""
        return self._grown(None, foot_refine_steps=steps)

    def to_person_only(self) -> YoloxNano:
        """A copy that predicts COCO's person class alone (C = 1), e.g. to fine-tune and export."""
        return keep_classes(self, [PERSON])


def keep_classes(model: YoloxNano, classes: Sequence[int]) -> YoloxNano:
    """A copy of `model` whose class predictions are `classes` only, in that order; every other
    weight is copied unchanged, so the kept classes score exactly as before."""
    count = model.config.num_classes
    if not classes or len(set(classes)) != len(classes) or not all(0 <= c < count for c in classes):
        raise ValueError(f"classes must be distinct indices in [0, {count}), got {list(classes)}")
    subset = YoloxNano(replace(model.config, num_classes=len(classes)))
    index = torch.tensor(list(classes), dtype=torch.long)
    state = model.state_dict()
    for key, value in state.items():
        if key.startswith("head.cls_preds."):
            state[key] = value.index_select(0, index.to(value.device))  # (C', ...) rows of the kept
    subset.load_state_dict(state, strict=True)
    device = next(model.parameters()).device
    return subset.to(device).train(model.training)


class DetectorConfigRecord:
    """What the detector configs of both views share (they are frozen dataclasses that mix this in):
    the YOLOX size they build and the dict a checkpoint stores."""

    num_classes: int
    depth: float
    width: float

    @property
    def yolox(self) -> YoloxConfig:
        return YoloxConfig(num_classes=self.num_classes, depth=self.depth, width=self.width,
                           foot=bool(getattr(self, "foot", False)),
                           foot_refine=bool(getattr(self, "foot_refine", False)),
                           foot_refine_steps=int(getattr(self, "foot_refine_steps", 1)),
                           foot_neck=bool(getattr(self, "foot_neck", False)),
                           foot_neck_top_down=bool(getattr(self, "foot_neck_top_down", False)))

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]

    @classmethod
    def from_dict(cls, record: dict[str, Any]) -> Self:
        names = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        return cls(**{k: v for k, v in record.items() if k in names})
