"""The module that becomes the ONNX graph: uint8 RGB images in, decoded boxes and scores out.

Everything model-specific (normalisation, the network, peak extraction, top-K) lives inside, so the
service only letterboxes frames and reads `boxes` (N, K, 4) and `scores` (N, K).
"""

from __future__ import annotations

import dataclasses

from torch import Tensor, nn

from contract import BOX_FORMATS, VIEW_FISHEYE, ModelInfo, OperatingPoint
from detector.checkpoint import Checkpoint
from detector.checkpoint import ModelInfo as CheckpointInfo
from detector.data.dataset import PAD_VALUE
from detector.decode import decode
from detector.model import DetectorConfig, FishLocNet
from detector.nanodet.network import NanoDetPlus
from detector.yolox.fisheye import FisheyeContract, FisheyeDetectorConfig
from detector.yolox.network import YoloxNano
from detector.yolox.polar import PolarContract, PolarDetectorConfig


class ContractModel(nn.Module):
    """(N, S, S, 3) uint8 RGB -> boxes (N, K, 4) float32 input px `cxcywh`, scores (N, K) float32."""

    def __init__(self, net: FishLocNet) -> None:
        super().__init__()
        self.net = net
        self.input_size = net.config.input_size
        self.max_detections = net.config.max_detections

    def forward(self, image: Tensor) -> tuple[Tensor, Tensor]:
        predictions = self.net(self.net.normalise(image))  # (N, 5, S/4, S/4)
        return decode(predictions, self.input_size, self.max_detections)


def centernet_info(config: DetectorConfig, info: CheckpointInfo) -> ModelInfo:
    """The contract metadata of a CenterNet (`fisheye` view) network with `config` and `info`."""
    return ModelInfo(name=config.model_name, version=info.model_version, view=VIEW_FISHEYE,
                     input_size=config.input_size, pad_value=PAD_VALUE,
                     default_min_score=info.default_min_score, trained_on=info.trained_on,
                     box_format=BOX_FORMATS[VIEW_FISHEYE])


def contract_info(checkpoint: Checkpoint) -> ModelInfo:
    """The contract metadata that `checkpoint`'s export carries (and evaluation reads it by)."""
    config, info = checkpoint.config, checkpoint.info
    if isinstance(config, PolarDetectorConfig | FisheyeDetectorConfig):
        base = config.model_info(info.model_version, info.trained_on, info.default_min_score)
    else:
        base = centernet_info(config, info)
    points = tuple((layout, OperatingPoint(float(score), float(iou)))
                   for layout, (score, iou) in sorted(info.view_points.items()))
    return dataclasses.replace(base, nms_iou=info.nms_iou, view_points=points)


def contract_module(checkpoint: Checkpoint, source: str = "<memory>") -> nn.Module:
    """`checkpoint`'s network wrapped to the ONNX contract, in eval mode (a polar network's top K
    taken among its peak cells where its config says `peaks`: `detector.yolox.decode.peak_cells`)."""
    network = checkpoint.build(source)
    if isinstance(network, YoloxNano | NanoDetPlus) and isinstance(checkpoint.config, PolarDetectorConfig):
        config = checkpoint.config
        return PolarContract(network, config.max_detections, config.peaks).eval()
    if isinstance(network, YoloxNano) and isinstance(checkpoint.config, FisheyeDetectorConfig):
        return FisheyeContract(network, checkpoint.config.max_detections).eval()
    if isinstance(network, FishLocNet):
        return ContractModel(network).eval()
    raise TypeError(f"no contract module for {type(network).__name__}")
