"""Training frames of the fisheye-view YOLOX: annotated frames letterboxed as the service does it.

A frame is reduced as the service's JPEG decode would (`contract.reduce_like_decode`) and
letterboxed by `contract.views.prepare_input` with the config's `ModelInfo`, so training and serving
share one letterbox. Its labels are the radius-aligned boxes in input px
(`Letterbox.boxes_frame_to_input`) written as YOLOX boxes in edge coordinates
(`radius_aligned_to_yolox`): the network regresses tangential x radial extents as if they were
width x height. Crowd boxes are left out (`FrameAnnotations.boxes_cxcywh` holds none); boxes over the
principal point stay (the nadir is where this view should beat the polar one).

Augmentation is one affine map about the principal point's input position p (the input centre for
a centred camera): an optional mirror across the vertical line through p, then a rotation about p
by a random angle. Both map rays from p to rays from p, so radius-aligned boxes stay radius-aligned
about the camera's principal point: centres move, `w` and `h` stay. Then the photometric jitter of
the polar strips (`strips.photometric`). Draws come from `np.random.default_rng((seed, epoch,
index))`: reproducible per sample.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from contract import FisheyeInput, ModelInfo
from contract.detect import reduce_like_decode
from contract.views import min_decoded_side, prepare_input
from detector.data.dataset import load_rgb
from detector.data.readers import FrameAnnotations
from detector.yolox.fisheye import FisheyeDetectorConfig
from detector.yolox.polar import EDGE_TO_CENTRE_PX
from detector.yolox.strips import photometric
from fisheye import assumed_camera

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

MIN_SIDE_PX = 2.0  # labels thinner than this (input px) are left out


@dataclass(frozen=True)
class FrameAugment:
    """Augmentation strengths; `FrameAugment.none()` turns everything off. The photometric fields
    are those of `strips.StripAugment` and mean the same."""

    rotation: bool = True  # rotate about the principal point by U[0, 2π)
    flip: float = 0.5  # probability of a mirror across the vertical through the principal point
    brightness: float = 0.4
    contrast: float = 0.4
    saturation: float = 0.5
    hue_deg: float = 12.0
    blur: float = 0.25
    jpeg: float = 0.3

    @classmethod
    def none(cls) -> FrameAugment:
        return cls(rotation=False, flip=0.0, brightness=0.0, contrast=0.0, saturation=0.0, hue_deg=0.0,
                   blur=0.0, jpeg=0.0)


def training_info(config: FisheyeDetectorConfig) -> ModelInfo:
    """The contract metadata the frames are letterboxed by (only the view's geometry matters here)."""
    return config.model_info("training", "training", 0.3)


def radius_aligned_to_yolox(boxes_cxcywh: FloatArray) -> FloatArray:
    """(N, 4) radius-aligned `cxcywh` input px -> (N, 4) YOLOX `xyxy` edge px: the box that
    `FisheyeContract` reads back as the same `cxcywh` (w along YOLOX's x, h along its y)."""
    boxes = np.asarray(boxes_cxcywh, dtype=np.float64).reshape(-1, 4)
    centre = boxes[:, :2] + EDGE_TO_CENTRE_PX
    half = boxes[:, 2:] / 2
    return np.concatenate([centre - half, centre + half], axis=1)


def affine_about(centre_xy: tuple[float, float], angle_rad: float, mirror: bool) -> FloatArray:
    """(2, 3) map p -> c + R(a)·M·(p − c), M the mirror u -> −u when `mirror` (R as in
    `detector.rotation`: clockwise on screen, since v points down)."""
    cos_a, sin_a = math.cos(angle_rad), math.sin(angle_rad)
    linear = np.array([[cos_a, -sin_a], [sin_a, cos_a]]) @ np.diag([-1.0 if mirror else 1.0, 1.0])
    centre = np.asarray(centre_xy, dtype=np.float64)
    return np.concatenate([linear, (centre - linear @ centre)[:, None]], axis=1)


def transform_boxes(boxes_cxcywh: FloatArray, matrix: FloatArray) -> FloatArray:
    """(N, 4) radius-aligned boxes -> (N, 4) under a rotation/mirror `matrix` (2, 3) about the
    principal point: centres move, `w`, `h` stay."""
    boxes = np.asarray(boxes_cxcywh, dtype=np.float64).reshape(-1, 4)
    centres = boxes[:, :2] @ matrix[:, :2].T + matrix[:, 2]
    return np.concatenate([centres, boxes[:, 2:]], axis=1)


def transform_image(image: NDArray[np.uint8], matrix: FloatArray, pad_value: int) -> NDArray[np.uint8]:
    """(S, S, 3) image -> the same under `matrix` (2, 3) (bilinear; uncovered px get `pad_value`)."""
    size = image.shape[1], image.shape[0]
    warped = cv2.warpAffine(image, matrix, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=(pad_value,) * 3)
    return np.asarray(warped, dtype=np.uint8)


def frame_input(frame: FrameAnnotations, info: ModelInfo
                ) -> tuple[NDArray[np.uint8], FloatArray, tuple[float, float]]:
    """A frame -> its letterboxed input (S, S, 3) RGB as served, its boxes (N, 4) radius-aligned
    `cxcywh` input px and the principal point's input position."""
    camera = frame.camera if frame.camera is not None else assumed_camera(frame.width, frame.height)
    reduced = reduce_like_decode(load_rgb(frame), min_decoded_side(info, camera))
    image, mapping = prepare_input(info, reduced, camera)
    if not isinstance(mapping, FisheyeInput):
        raise ValueError(f"model {info.name} has the {info.view} view, not fisheye")
    boxes = mapping.letterbox.boxes_frame_to_input(frame.boxes_cxcywh).reshape(-1, 4)
    pp = mapping.letterbox.frame_to_input(np.asarray([frame.principal_point]))[0]
    return image, boxes, (float(pp[0]), float(pp[1]))


@dataclass(frozen=True)
class FrameSample:
    """One letterboxed frame: `image` (S, S, 3) uint8 RGB, `labels_xyxy` (N, 4) YOLOX coordinates
    (edge px) of its radius-aligned boxes, `principal_point_xy` the principal point in input px."""

    image: NDArray[np.uint8]
    labels_xyxy: FloatArray
    principal_point_xy: tuple[float, float]

    def __post_init__(self) -> None:
        if self.image.ndim != 3 or self.labels_xyxy.ndim != 2 or self.labels_xyxy.shape[1] != 4:
            raise ValueError(f"image {self.image.shape}, labels {self.labels_xyxy.shape}")


class FisheyeFrameDataset:
    """Annotated frames -> augmented FrameSamples for a FisheyeDetectorConfig; `set_epoch` first."""

    def __init__(self, frames: Sequence[FrameAnnotations], config: FisheyeDetectorConfig,
                 augment: FrameAugment | None = None, seed: int = 0, cache: bool = True) -> None:
        self.frames = list(frames)
        self.config = config
        self.info = training_info(config)
        self.augment = augment if augment is not None else FrameAugment()
        self.seed = seed
        self.cache = cache
        self.epoch = 0
        self._inputs: dict[int, tuple[NDArray[np.uint8], FloatArray, tuple[float, float]]] = {}
        self.labels_left_out = 0  # this epoch's: thin ones, or moved off the input by a rotation

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch
        self.labels_left_out = 0

    def __len__(self) -> int:
        return len(self.frames)

    def left_out(self) -> dict[str, int]:
        """Counters for the epoch's log record."""
        return {"labels_left_out": self.labels_left_out}

    def base(self, index: int) -> tuple[NDArray[np.uint8], FloatArray, tuple[float, float]]:
        """The frame's letterboxed input, boxes (input px) and principal point, cached when `cache`."""
        if index in self._inputs:
            return self._inputs[index]
        item = frame_input(self.frames[index], self.info)
        if self.cache:
            self._inputs[index] = item
        return item

    def __getitem__(self, index: int) -> FrameSample:
        rng = np.random.default_rng((self.seed, self.epoch, index))
        image, boxes, pp = self.base(index)
        mirror = bool(rng.random() < self.augment.flip)
        angle = float(rng.uniform(0.0, 2 * math.pi)) if self.augment.rotation else 0.0
        if mirror or angle:
            matrix = affine_about(pp, angle, mirror)
            image = transform_image(image, matrix, self.info.pad_value)
            boxes = transform_boxes(boxes, matrix)
        size = self.config.input_size
        inside = np.all((boxes[:, :2] >= -0.5) & (boxes[:, :2] <= size - 0.5), axis=1)
        keep = inside & np.all(boxes[:, 2:] >= MIN_SIDE_PX, axis=1)
        self.labels_left_out += int((~keep).sum())
        image = photometric(image, self.augment, rng)
        return FrameSample(image, radius_aligned_to_yolox(boxes[keep]), pp)
