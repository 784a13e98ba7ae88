"""A model's raw outputs -> the kept detections of one frame, in frame px.

Score threshold, finite and positive boxes, mapping back to the frame through the view, rotated
NMS about the camera's principal point, at most `max_detections`. `ModelRunner` chains it with
`views.prepare_input` for callers that hold decoded frames (evaluation, benchmarks); the service's
pipeline calls the same two functions between its own decode and localisation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from contract.metadata import ModelInfo
from contract.model import RawOutputs
from contract.views import InputMapping, min_decoded_side, prepare_input
from fisheye import FisheyeCamera, rotated_nms

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrameDetections:
    """Kept detections of one frame: `boxes_cxcywh` (N, 4) frame px radius-aligned about
    `principal_point`, `scores` (N,) descending, `foot_px` (N, 2) frame px of the model's own
    floor-contact points or None when the model predicts none."""

    boxes_cxcywh: FloatArray
    scores: FloatArray
    principal_point: tuple[float, float]
    foot_px: FloatArray | None = None

    def __post_init__(self) -> None:
        n = len(self.scores)
        if self.boxes_cxcywh.shape != (n, 4) or (self.foot_px is not None and self.foot_px.shape != (n, 2)):
            raise ValueError(f"boxes {self.boxes_cxcywh.shape}, scores {self.scores.shape} and foot "
                             f"{None if self.foot_px is None else self.foot_px.shape} disagree")


def select_detections(raw: RawOutputs, mapping: InputMapping, principal_point: tuple[float, float],
                      min_score: float, nms_iou: float | None = 0.6, max_detections: int = 300
                      ) -> FrameDetections:
    """One image's RawOutputs -> FrameDetections with score ≥ `min_score`, in frame px."""
    boxes = raw.boxes.astype(np.float64)
    scores = raw.scores.astype(np.float64)
    keep = np.isfinite(scores) & (scores >= min_score) & np.all(np.isfinite(boxes), axis=1)
    keep[keep] = mapping.has_area(boxes[keep])
    foot = None
    if raw.foot is not None:
        foot_input = raw.foot.astype(np.float64)
        keep &= np.all(np.isfinite(foot_input), axis=1)
        foot = mapping.points_to_frame(foot_input[keep])
    boxes, scores = boxes[keep], scores[keep]
    if nms_iou is not None:
        first = mapping.presuppress(boxes, scores, nms_iou)
        boxes, scores = boxes[first], scores[first]
        foot = None if foot is None else foot[first]
    boxes_frame = mapping.boxes_to_frame(boxes)
    if nms_iou is not None and len(scores) > 1:
        kept = rotated_nms(boxes_frame, scores, principal_point, nms_iou)[:max_detections]
    else:
        kept = np.arange(min(len(scores), max_detections))
    return FrameDetections(boxes_frame[kept], scores[kept], principal_point,
                           None if foot is None else foot[kept])


def reduce_like_decode(rgb: NDArray[np.uint8], min_long_side: int) -> NDArray[np.uint8]:
    """A full-size frame shrunk by the largest factor of 2, 4, 8 that divides both sides and keeps
    the long side ≥ `min_long_side` (what the service's reduced JPEG decode gives, area-averaged)."""
    height, width = rgb.shape[:2]
    for factor in (8, 4, 2):
        if width % factor == 0 and height % factor == 0 and max(width, height) // factor >= min_long_side:
            small = cv2.resize(rgb, (width // factor, height // factor), interpolation=cv2.INTER_AREA)
            return np.asarray(small, dtype=np.uint8)
    return rgb


class ContractModel(Protocol):
    """What runs a model of the contract: an `OnnxModel`, or a torch module wrapped alike."""

    @property
    def info(self) -> ModelInfo: ...

    def run(self, image: NDArray[np.uint8]) -> RawOutputs: ...


class ModelRunner:
    """Decoded full-size frames with their cameras -> FrameDetections, as the service computes them."""

    def __init__(self, model: ContractModel, nms_iou: float | None = 0.6, max_detections: int = 300) -> None:
        self.model = model
        self.nms_iou = nms_iou
        self.max_detections = max_detections

    @property
    def default_min_score(self) -> float:
        return self.model.info.default_min_score

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        """Frames (H, W, 3) uint8 RGB and each one's camera (at the frame's size) -> detections."""
        info = self.model.info
        found = []
        for rgb, camera in zip(frames_rgb, cameras, strict=True):
            reduced = reduce_like_decode(rgb, min_decoded_side(info, camera))
            image, mapping = prepare_input(info, reduced, camera)
            raw = self.model.run(image)
            pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
            found.append(select_detections(raw, mapping, pp, min_score, self.nms_iou, self.max_detections))
        return found
