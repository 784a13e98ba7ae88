"""The torch Dataset of training and evaluation: frames letterboxed to the model input, with boxes.

Each sample is the letterboxed uint8 input (S, S, 3) RGB (the same preprocessing as the service,
`fisheye.Letterbox`) and its radius-aligned boxes in input pixels. Augmentation is drawn from a
generator seeded by (seed, epoch, index), so an epoch is the same whether or not training was
interrupted and resumed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor
from torch.utils.data import Dataset

from detector.data.readers import FrameAnnotations
from detector.rotation import rotate_boxes, rotate_image
from fisheye import Letterbox

PAD_VALUE = 0


@dataclass(frozen=True)
class AugmentConfig:
    """`rotation`: rotate input and boxes about the centre by U[0, 360°) (the ablation's switch);
    `flip`: mirror left-right; `photometric`: brightness/contrast/colour jitter."""

    rotation: bool = False
    flip: bool = True
    photometric: bool = True


@dataclass(frozen=True)
class Sample:
    image: Tensor  # (S, S, 3) uint8 RGB
    boxes_cxcywh: NDArray[np.float64]  # (N, 4) input px
    index: int


@dataclass(frozen=True)
class Batch:
    images: Tensor  # (B, S, S, 3) uint8
    boxes: list[NDArray[np.float64]]
    indices: list[int]


def load_rgb(frame: FrameAnnotations) -> NDArray[np.uint8]:
    """The frame's image as (H, W, 3) uint8 RGB; ValueError when it is missing or of another size."""
    import cv2

    bgr = cv2.imread(str(frame.path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise ValueError(f"cannot read image {frame.path}")
    if bgr.shape[:2] != (frame.height, frame.width):
        raise ValueError(f"{frame.path} is {bgr.shape[1]}x{bgr.shape[0]}, annotations say "
                         f"{frame.width}x{frame.height}")
    return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def letterboxed(frame: FrameAnnotations, input_size: int) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
    """(S, S, 3) letterboxed input and the frame's boxes (N, 4) in input px."""
    letterbox = Letterbox.fit((frame.width, frame.height), input_size)
    boxes = letterbox.boxes_frame_to_input(frame.boxes_cxcywh).reshape(-1, 4)
    return letterbox.apply(load_rgb(frame), PAD_VALUE), boxes


def _photometric(image: NDArray[np.uint8], rng: np.random.Generator) -> NDArray[np.uint8]:
    gain = rng.uniform(0.7, 1.3) * rng.uniform(0.9, 1.1, size=3)
    bias = rng.uniform(-20, 20)
    out = image.astype(np.float32) * gain[None, None, :].astype(np.float32) + np.float32(bias)
    return np.clip(out, 0, 255).astype(np.uint8)


class DetectionDataset(Dataset[Sample]):
    """Frames -> Samples at `input_size`; with `augment`, randomised per (seed, epoch, index)."""

    def __init__(self, frames: Sequence[FrameAnnotations], input_size: int,
                 augment: AugmentConfig | None = None, seed: int = 0, cache: bool = True) -> None:
        self.frames = list(frames)
        self.input_size = input_size
        self.augment = augment
        self.seed = seed
        self.epoch = 0
        self._cache: dict[int, tuple[NDArray[np.uint8], NDArray[np.float64]]] | None = {} if cache else None

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.frames)

    def _base(self, index: int) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
        if self._cache is not None and index in self._cache:
            return self._cache[index]
        item = letterboxed(self.frames[index], self.input_size)
        if self._cache is not None:
            self._cache[index] = item
        return item

    def __getitem__(self, index: int) -> Sample:
        image, boxes = self._base(index)
        if self.augment is not None:
            rng = np.random.default_rng([self.seed, self.epoch, index])
            image, boxes = self._augmented(image, boxes, rng)
        return Sample(torch.from_numpy(np.ascontiguousarray(image)), boxes, index)

    def _augmented(self, image: NDArray[np.uint8], boxes: NDArray[np.float64], rng: np.random.Generator
                   ) -> tuple[NDArray[np.uint8], NDArray[np.float64]]:
        assert self.augment is not None
        size = self.input_size
        if self.augment.flip and rng.random() < 0.5:
            image = image[:, ::-1]
            boxes = boxes.copy()
            boxes[:, 0] = size - 1 - boxes[:, 0]
        if self.augment.rotation:
            angle = float(rng.uniform(0.0, 2 * math.pi))
            image = rotate_image(np.ascontiguousarray(image), angle, PAD_VALUE)
            boxes = rotate_boxes(boxes, angle, size)
        if self.augment.photometric:
            image = _photometric(image, rng)
        return image, boxes


def collate(samples: Sequence[Sample]) -> Batch:
    return Batch(torch.stack([s.image for s in samples]), [s.boxes_cxcywh for s in samples],
                 [s.index for s in samples])
