"""Design (b) of the detector comparison: YOLOX-Nano (COCO-pretrained) reading the letterboxed
fisheye frame itself, its head read as radius-aligned.

The network is unchanged YOLOX; what changes is how its boxes are read. A radius-aligned box
(cx, cy, w, h) about the principal point is trained and served as the YOLOX box (cx, cy, w, h):
YOLOX's "width" is the box's tangential extent and its "height" the radial one, whatever the
direction of the ray through the centre (the angle is implied by the position, DESIGN.md).

`FisheyeDetectorConfig` is what a checkpoint stores of it; `FisheyeContract` is the module that
becomes the ONNX graph of DESIGN.md's `fisheye` view: uint8 RGB letterboxed squares in, the top
`max_detections` radius-aligned boxes (`cxcywh` input px, pixel centres at integers) and scores out.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor, nn

from contract import BOX_FORMATS, VIEW_FISHEYE, ModelInfo
from detector.yolox.decode import top_people
from detector.yolox.network import DetectorConfigRecord, YoloxNano
from detector.yolox.polar import EDGE_TO_CENTRE_PX, LICENCE, PAD_VALUE

ARCH = "yolox-fisheye"


@dataclass(frozen=True)
class FisheyeDetectorConfig(DetectorConfigRecord):
    """A YOLOX network reading the frame letterboxed into an `input_size` square."""

    input_size: int = 640
    num_classes: int = 1
    depth: float = 0.33
    width: float = 0.25
    max_detections: int = 300
    model_name: str = "fishloc-yolox-nano-fisheye"
    arch: str = ARCH

    def __post_init__(self) -> None:
        if self.input_size < 32 or self.input_size % 32:
            raise ValueError(f"input_size must be a positive multiple of 32, got {self.input_size}")
        if self.arch != ARCH:
            raise ValueError(f"arch {self.arch!r} is not {ARCH!r}")
        if self.max_detections < 1:
            raise ValueError(f"max_detections must be at least 1, got {self.max_detections}")

    def model_info(self, version: str, trained_on: str, default_min_score: float) -> ModelInfo:
        """The contract metadata of this network's export."""
        return ModelInfo(name=self.model_name, version=version, view=VIEW_FISHEYE, input_size=self.input_size,
                         pad_value=PAD_VALUE, default_min_score=default_min_score, trained_on=trained_on,
                         box_format=BOX_FORMATS[VIEW_FISHEYE], licence=LICENCE)


def build_fisheye_network(config: FisheyeDetectorConfig) -> YoloxNano:
    return YoloxNano(config.yolox)


class FisheyeContract(nn.Module):
    """(N, S, S, 3) uint8 RGB letterboxed frames -> boxes (N, K, 4) float32 radius-aligned `cxcywh`
    input px (pixel centres at integers; w tangential, h radial), scores (N, K) float32 descending:
    objectness x p(person) of the top K cells."""

    def __init__(self, net: YoloxNano, max_detections: int) -> None:
        super().__init__()
        self.net = net
        self.max_detections = max_detections

    def forward(self, image: Tensor) -> tuple[Tensor, Tensor]:
        cxcywh, scores, _ = top_people(self.net, image, self.max_detections)  # (N, K, 4), (N, K)
        return torch.cat([cxcywh[..., :2] - EDGE_TO_CENTRE_PX, cxcywh[..., 2:]], dim=-1), scores

