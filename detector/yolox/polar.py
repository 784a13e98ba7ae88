"""The person detector of FishLoc 0.2: YOLOX-Nano (COCO-pretrained) reading the polar unwrap.

`PolarDetectorConfig` is what a checkpoint stores of it (the network's size and the strip it reads,
DESIGN.md's `polar` view); `PolarContract` is the module that becomes the ONNX graph: uint8 RGB
strips in, the top `max_detections` person boxes (`xyxy` strip px) and scores out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import torch
from torch import Tensor, nn

from contract import BOX_FORMATS, VIEW_POLAR, ModelInfo, PolarSpec
from detector.nanodet.decode import top_people as nanodet_top_people
from detector.nanodet.network import NanoDetConfig, NanoDetPlus
from detector.yolox.decode import top_people
from detector.yolox.network import DetectorConfigRecord, YoloxNano

ARCH = "yolox-polar"  # the checkpoints' name of this config (kept when the network is not YOLOX)
YOLOX_NANO, NANODET_PLUS_M = "yolox-nano", "nanodet-plus-m"
NETWORKS = (YOLOX_NANO, NANODET_PLUS_M)
LICENCES = {
    YOLOX_NANO: "Apache-2.0 (weights from or fine-tuned from YOLOX-Nano, Copyright (c) Megvii Inc.)",
    NANODET_PLUS_M: "Apache-2.0 (weights from or fine-tuned from NanoDet-Plus-m, Copyright (c) RangiLyu)",
}
LICENCE = LICENCES[YOLOX_NANO]
PAD_VALUE = 0
# YOLOX's boxes are in pixel-edge coordinates (pixel i spans [i, i + 1)); FishLoc's pixel centres
# sit at integers. Training labels add this, the graph takes it away.
EDGE_TO_CENTRE_PX = 0.5


@dataclass(frozen=True)
class PolarDetectorConfig(DetectorConfigRecord):
    """A YOLOX network reading a polar strip of `input_size` rows and `polar_width` columns per
    turn plus `polar_overlap` repeated ones, whose top row is the ring θ = `polar_max_theta_deg`."""

    input_size: int = 416
    polar_width: int = 1664
    polar_overlap: int = 128
    polar_max_theta_deg: float = 90.0
    num_classes: int = 1
    depth: float = 0.33
    width: float = 0.25
    max_detections: int = 300
    model_name: str = "fishloc-yolox-nano-polar"
    arch: str = ARCH
    # Design (c): > 0 gives the network a second head for the cells of the bottom rows, the disc
    # within this fraction of the strip's radius (detector.yolox.inner_head); 0: one head.
    inner_fraction: float = 0.0
    foot: bool = False  # a foot output: each box's floor-contact point (detector.yolox.foot)
    foot_refine: bool = False  # its second stage on the stride-8 features (foot.FootRefiner)
    foot_refine_steps: int = 1  # passes of that stage
    foot_neck: bool = False  # the foot reads its own copy of the neck (foot.FootNeck)
    foot_neck_top_down: bool = False  # ... of its top-down path alone (neck.TopDownFPN)
    # The graph (0.6 on): the top K among peak cells only, and an input of any height and width
    # whose view the service plans per camera (DESIGN.md's planned views; `fishloc.view_planned`).
    peaks: bool = False
    planned: bool = False
    # The network that reads the strip: YOLOX-Nano (every FishLoc model up to 0.6) or NanoDet-Plus-m
    # (`detector.nanodet`: a stronger COCO start, no foot branch, no inner head).
    network: str = YOLOX_NANO

    def __post_init__(self) -> None:
        if self.network not in NETWORKS:
            raise ValueError(f"network {self.network!r} is none of {', '.join(NETWORKS)}")
        if self.network != YOLOX_NANO and (self.foot or self.inner_fraction > 0 or self.num_classes != 1):
            raise ValueError(f"{self.network} reads the strip with one person class, no foot and no "
                             "inner head")
        if self.input_size % 32 or (self.polar_width + self.polar_overlap) % 32:
            raise ValueError(f"strip {self.input_size} x ({self.polar_width} + {self.polar_overlap}) px: "
                             "height and total width must be multiples of 32")
        if self.arch != ARCH:
            raise ValueError(f"arch {self.arch!r} is not {ARCH!r}")
        PolarSpec(self.polar_width, self.polar_overlap, self.polar_max_theta_deg)  # checks the strip
        if not 0.0 <= self.inner_fraction < 1.0:
            raise ValueError(f"inner_fraction must lie in [0, 1), got {self.inner_fraction}")
        if (self.foot_refine or self.foot_neck) and not self.foot:
            raise ValueError("a foot refiner or neck needs the foot output (foot)")
        if self.foot_neck_top_down and not self.foot_neck:
            raise ValueError("foot_neck_top_down cuts the foot's own neck (foot_neck)")
        if not 1 <= self.foot_refine_steps <= 4:
            raise ValueError(f"foot_refine_steps must lie in [1, 4], got {self.foot_refine_steps}")
        if self.foot and self.inner_fraction > 0:
            raise ValueError("a foot branch and an inner-disc head are not built together")

    @property
    def strip_wh(self) -> tuple[int, int]:
        return self.polar_width + self.polar_overlap, self.input_size

    def model_info(self, version: str, trained_on: str, default_min_score: float) -> ModelInfo:
        """The contract metadata of this network's export."""
        return ModelInfo(name=self.model_name, version=version, view=VIEW_POLAR, input_size=self.input_size,
                         pad_value=PAD_VALUE, default_min_score=default_min_score, trained_on=trained_on,
                         box_format=BOX_FORMATS[VIEW_POLAR], licence=LICENCES[self.network],
                         polar=PolarSpec(self.polar_width, self.polar_overlap, self.polar_max_theta_deg),
                         planned=self.planned)


def build_polar_network(config: PolarDetectorConfig) -> YoloxNano | NanoDetPlus:
    if config.network == NANODET_PLUS_M:
        return NanoDetPlus(NanoDetConfig(num_classes=config.num_classes))
    if config.inner_fraction > 0:
        from detector.yolox.inner_head import InnerHeadYolox

        return InnerHeadYolox(config.yolox, config.inner_fraction)
    return YoloxNano(config.yolox)


class PolarContract(nn.Module):
    """(N, H, W, 3) uint8 RGB strips -> boxes (N, K, 4) float32 `xyxy` strip px (pixel centres at
    integers), scores (N, K) float32 descending: the person scores of the top K cells (YOLOX:
    objectness x p(person); NanoDet: p(person)), and for a network with a foot branch `foot`
    (N, K, 2) strip px."""

    def __init__(self, net: YoloxNano | NanoDetPlus, max_detections: int, peaks: bool = False) -> None:
        super().__init__()
        self.net = net
        self.max_detections = max_detections
        self.peaks = peaks

    def forward(self, image: Tensor) -> tuple[Tensor, ...]:
        foot: Tensor | None = None
        if isinstance(self.net, NanoDetPlus):
            cxcywh, scores = nanodet_top_people(self.net, image, self.max_detections, self.peaks)
        else:
            cxcywh, scores, foot = top_people(self.net, image, self.max_detections, self.peaks)  # (N, K, 4)
        centre, half = cxcywh[..., :2] - EDGE_TO_CENTRE_PX, cxcywh[..., 2:] / 2
        boxes = torch.cat([centre - half, centre + half], dim=-1)
        if foot is None:
            return boxes, scores
        return boxes, scores, foot - EDGE_TO_CENTRE_PX  # (N, K, 2) strip px


class YoloxSize(Protocol):
    """What `init_from_pretrained` reads of a detector config (polar or fisheye view)."""

    @property
    def num_classes(self) -> int: ...

    @property
    def depth(self) -> float: ...

    @property
    def width(self) -> float: ...


def init_from_pretrained(path: str, config: YoloxSize) -> YoloxNano:
    """The COCO YOLOX-Nano of an ONNX file, its head cut to the person class: the starting point
    of fine-tuning and the zero-shot baseline. PretrainedWeightsError naming the file if unusable."""
    from detector.yolox.network import PERSON, keep_classes
    from detector.yolox.onnx_weights import load_yolox_onnx

    if isinstance(config, PolarDetectorConfig) and config.network != YOLOX_NANO:
        raise ValueError(f"{config.network} starts from its own weights (init_network_from_pretrained)")
    coco = load_yolox_onnx(path)
    if config.num_classes != 1 or (config.depth, config.width) != (coco.config.depth, coco.config.width):
        raise ValueError(f"{path}: the pretrained network is YOLOX depth {coco.config.depth}, width "
                         f"{coco.config.width}; the config asks for {config.depth}, {config.width} with "
                         f"{config.num_classes} classes (a person detector has 1)")
    person = keep_classes(coco, [PERSON])
    if isinstance(config, PolarDetectorConfig) and config.foot:
        footed = person.with_foot()
        if config.foot_refine:
            footed = footed.with_foot_refiner().with_foot_refine_steps(config.foot_refine_steps)
        if not config.foot_neck:
            return footed
        necked = footed.with_foot_neck()
        return necked.with_foot_neck_top_down() if config.foot_neck_top_down else necked
    if isinstance(config, PolarDetectorConfig) and config.inner_fraction > 0:
        from detector.yolox.inner_head import InnerHeadYolox

        return InnerHeadYolox.from_network(person, config.inner_fraction)
    return person


def init_network_from_pretrained(path: str, config: PolarDetectorConfig) -> YoloxNano | NanoDetPlus:
    """The COCO network of `config.network` read from its ONNX file, cut to the person class
    (`init_from_pretrained` for YOLOX-Nano); PretrainedWeightsError naming the file if unusable."""
    if config.network == NANODET_PLUS_M:
        from detector.nanodet.onnx_weights import load_nanodet_onnx

        return load_nanodet_onnx(path).to_person_only()
    return init_from_pretrained(path, config)
