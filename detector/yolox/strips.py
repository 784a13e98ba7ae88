"""Training strips of the polar YOLOX: annotated frames unwrapped as the service unwraps them.

A frame is reduced as the service's JPEG decode would (`contract.reduce_like_decode`) and unwrapped
by `contract.views.prepare_input` with the `PolarGrid` of `contract.views.polar_grid`, so training
and serving share one grid. Its labels are `grid.radius_aligned_to_polar(boxes)` plus
`EDGE_TO_CENTRE_PX` (YOLOX's pixel-edge coordinates). A box over the principal point (a person
straight below the lens) covers the whole turn in the strip and is left out (counted).

The unwrap of a frame is cached as one full turn without overlap (start angle 0). Rolling it by k
columns is the unwrap with `start_rad = 2πk / width` exactly, so the random roll of the angle (nobody
is always at the seam) costs a `np.roll`; the overlap columns are then the first ones repeated.
Each copy of a label (its first-turn columns, and those plus `width` where they reach into the
overlap) is kept where most of it lies inside the strip, and clipped to it.

Augmentation is drawn from `np.random.default_rng((seed, epoch, index))`: reproducible per sample.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor

from contract import ModelInfo
from contract.detect import reduce_like_decode
from contract.views import min_decoded_side, nadir_input, polar_grid, prepare_input, view_plan
from detector.data.dataset import load_rgb
from detector.data.readers import FrameAnnotations
from detector.yolox.foot import strip_feet
from detector.yolox.polar import EDGE_TO_CENTRE_PX, PolarDetectorConfig
from fisheye.polar import PolarGrid
from fisheye.view_plan import NadirPiece

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

MIN_VISIBLE = 0.5  # a label copy is kept where at least this fraction of its area lies in the strip
MIN_SIDE_PX = 2.0  # labels thinner than this (strip px) are left out


@dataclass(frozen=True)
class StripAugment:
    """Augmentation strengths; `StripAugment.none()` turns everything off."""

    roll: bool = True  # random start angle of the turn
    flip: float = 0.5  # probability of a left-right mirror
    brightness: float = 0.4  # ± fraction
    contrast: float = 0.4  # ± fraction
    saturation: float = 0.5  # ± fraction
    hue_deg: float = 12.0  # ± degrees
    blur: float = 0.25  # probability of a Gaussian blur (σ up to 1.5 px)
    jpeg: float = 0.3  # probability of a JPEG round trip (quality 25–85)
    # Zoom: the strip's top row at this multiple of the served radius (people look smaller above
    # 1, larger below); one is drawn per sample. Every scale caches its own strips.
    radius_scales: tuple[float, ...] = (1.0,)
    # A planned view's band: the strip at this multiple of the served rows and columns per turn over
    # the same radii (people this much larger, their shape kept), cut to a window of the served rows
    # about a random person, or under 1 padded to them below the rim (a view whose budget shrinks
    # its band); one is drawn per sample. Not `radius_scales`, which keeps the columns: its people
    # shrink along the ray alone.
    band_scales: tuple[float, ...] = (1.0,)
    # > 0: train on windows of this many columns (a multiple of 32), centred near a random label:
    # the network is convolutional, and a window costs a fraction of the strip's forward pass.
    crop_width: int = 0
    # Each strip px the mean of this many samples of the frame along each axis, as a view of
    # `ViewPlanConfig.unwrap_samples` serves it (docs/DETECTOR.md, "Other runtimes and an
    # area-averaged unwrap"); 1: one bilinear sample, as the service's default view.
    unwrap_samples: int = 1
    # The probability that a sample is the frame's nadir view (`fisheye.view_plan.NadirPiece`, as
    # the default view plans it for the frame's camera) rather than a strip: the upright crop of the
    # disc below the lens the service runs as a second input, which a head trained on strips alone
    # reads zero-shot. Its labels are the upright boxes `contract.views.upright_to_radius_aligned`
    # turns back into each person's box (`nadir_labels`); its people have no foot labels (the
    # service takes their feet from the box). 0 (the default): strips alone.
    nadir_view: float = 0.0
    # The probability that a sample's colours and textures are redrawn by a random convolution
    # (`rand_conv`), its shapes kept: what tells a rendered person from a real one is their
    # surfaces, and the head should not learn to find people by them. 0 (the default): never.
    rand_conv: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.nadir_view <= 1.0:
            raise ValueError(f"nadir_view must lie in [0, 1], got {self.nadir_view}")
        if not 0.0 <= self.rand_conv <= 1.0:
            raise ValueError(f"rand_conv must lie in [0, 1], got {self.rand_conv}")
        if not self.radius_scales or min(self.radius_scales) <= 0:
            raise ValueError(f"radius_scales must be positive, got {self.radius_scales}")
        if not self.band_scales or min(self.band_scales) < 0.5:
            raise ValueError(f"band_scales must be at least 0.5, got {self.band_scales}")
        if self.crop_width < 0 or self.crop_width % 32:
            raise ValueError(f"crop_width must be 0 or a positive multiple of 32, got {self.crop_width}")
        if not 1 <= self.unwrap_samples <= 4:
            raise ValueError(f"unwrap_samples must lie in [1, 4], got {self.unwrap_samples}")

    @classmethod
    def none(cls) -> StripAugment:
        return cls(roll=False, flip=0.0, brightness=0.0, contrast=0.0, saturation=0.0, hue_deg=0.0,
                   blur=0.0, jpeg=0.0)


def training_info(config: PolarDetectorConfig) -> ModelInfo:
    """The contract metadata the strips are made by (only the view's geometry matters here)."""
    return config.model_info("training", "training", 0.3)


def full_turn_mask(grid: PolarGrid, xyxy: FloatArray) -> NDArray[np.bool_]:
    """(N,) which strip boxes of `radius_aligned_to_polar` are a box over the principal point."""
    return (xyxy[:, 2] - xyxy[:, 0]) >= grid.width - 1e-9


def visible_labels(boxes: FloatArray, strip_wh: tuple[int, int]) -> tuple[FloatArray, NDArray[np.bool_]]:
    """(N, 4) boxes clipped to [−0.5, W − 0.5] × [−0.5, H − 0.5] and (N,) which to keep: at least
    MIN_VISIBLE of their area inside and both sides ≥ MIN_SIDE_PX. Pixel-centre coordinates."""
    low, high = np.array([-0.5, -0.5]), np.array(strip_wh, dtype=np.float64) - 0.5
    clipped = np.concatenate([np.clip(boxes[:, :2], low, high), np.clip(boxes[:, 2:], low, high)], axis=1)
    area = np.prod(np.maximum(boxes[:, 2:] - boxes[:, :2], 1e-9), axis=1)
    sides = clipped[:, 2:] - clipped[:, :2]
    visible = np.prod(np.maximum(sides, 0.0), axis=1) / area
    return clipped, (visible >= MIN_VISIBLE) & np.all(sides >= MIN_SIDE_PX, axis=1)


def label_copies(xyxy: FloatArray, width: int, strip_wh: tuple[int, int]
                 ) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
    """(N, 4) strip boxes with first-turn centres -> (M, 4) label copies in the strip: each box and
    its copy one turn (`width` columns) to the right, as `visible_labels` keeps them; with each
    copy's source box (M,) and the columns it was moved by (M,). Pixel-centre coordinates."""
    if len(xyxy) == 0:
        return np.zeros((0, 4)), np.zeros(0, dtype=np.int64), np.zeros(0)
    copies = np.concatenate([xyxy, xyxy + np.array([width, 0.0, width, 0.0])])
    clipped, keep = visible_labels(copies, strip_wh)
    source = np.tile(np.arange(len(xyxy)), 2)
    moved = np.repeat([0.0, float(width)], len(xyxy))
    return clipped[keep], source[keep], moved[keep]


def crop_window(image: NDArray[np.uint8], labels: FloatArray, feet: FloatArray, width: int,
                rng: np.random.Generator) -> tuple[NDArray[np.uint8], FloatArray, FloatArray]:
    """A window of `width` columns of a strip (H, W, 3), centred near a random label when there is
    one, with the labels (N, 4) and feet (N, 3) that lie in it (kept as `visible_labels` keeps them)."""
    strip_w = image.shape[1]
    if width >= strip_w:
        return image, labels, feet
    if len(labels) and rng.random() < 0.9:
        pick = labels[int(rng.integers(len(labels)))]
        centre = (pick[0] + pick[2]) / 2 + rng.uniform(-0.4, 0.4) * width
    else:
        centre = rng.uniform(0, strip_w)
    x0 = int(np.clip(round(centre - width / 2), 0, strip_w - width))
    return _window(image, labels, feet, x0, width, axis=0)


def crop_rows(image: NDArray[np.uint8], labels: FloatArray, feet: FloatArray, height: int,
              rng: np.random.Generator) -> tuple[NDArray[np.uint8], FloatArray, FloatArray]:
    """A window of `height` rows of a strip (H, W, 3) (starting at a multiple of 32), about a random
    label when there is one, with the labels (N, 4) and feet (N, 3) that lie in it (kept as
    `visible_labels` keeps them)."""
    strip_h = image.shape[0]
    if height >= strip_h:
        return image, labels, feet
    if len(labels):
        pick = labels[int(rng.integers(len(labels)))]
        centre = (pick[1] + pick[3]) / 2 + rng.uniform(-0.3, 0.3) * height
    else:
        centre = rng.uniform(0, strip_h)
    y0 = int(np.clip(round((centre - height / 2) / 32) * 32, 0, strip_h - height))
    return _window(image, labels, feet, y0, height, axis=1)


def pad_rows(image: NDArray[np.uint8], height: int, pad_value: int) -> NDArray[np.uint8]:
    """A strip (H, W, 3) of fewer than `height` rows with pad rows below it (past the rim, as a
    planned view pads a band's piece to the canvas); the strip itself where it has them."""
    missing = height - image.shape[0]
    if missing <= 0:
        return image
    return np.concatenate([image, np.full((missing, *image.shape[1:]), pad_value, dtype=image.dtype)])


def _window(image: NDArray[np.uint8], labels: FloatArray, feet: FloatArray, start: int, size: int,
            axis: int) -> tuple[NDArray[np.uint8], FloatArray, FloatArray]:
    """`size` columns (`axis` 0, x) or rows (1, y) of a strip from `start` on, with the labels and
    feet that lie in them, moved into the window."""
    shift = np.zeros(2)
    shift[axis] = start
    window = np.ascontiguousarray(image[:, start:start + size] if axis == 0 else image[start:start + size])
    clipped, keep = visible_labels(labels - np.tile(shift, 2), (window.shape[1], window.shape[0]))
    kept_feet = feet[keep].copy()
    kept_feet[:, axis] -= start
    return window, clipped[keep], kept_feet


def place_labels(xyxy: FloatArray, width: int, strip_wh: tuple[int, int]) -> FloatArray:
    """The label copies of `label_copies`, alone."""
    return label_copies(xyxy, width, strip_wh)[0]


def frame_strip(frame: FrameAnnotations, info: ModelInfo, radius_scale: float = 1.0, band_scale: float = 1.0,
                samples: int = 1) -> tuple[NDArray[np.uint8], FloatArray, FloatArray, int]:
    """A frame -> its full-turn strip (H, width, 3) RGB at start angle 0 (the served one, its radius
    times `radius_scale`, its rows and columns times `band_scale`, each px the mean of `samples` ×
    `samples` samples of a frame decoded that much larger), its labels (N, 4) strip px
    (first-turn centres, full turns left out), their feet (N, 3) (`detector.yolox.foot.strip_feet`:
    strip px and metres per px, NaN where unknown) and how many full-turn labels were left out."""
    if frame.camera is None or info.polar is None:
        raise ValueError(f"{frame.path}: polar strips need the frame's camera and a polar model")
    camera = frame.camera
    turn_info = dataclasses.replace(info, polar=dataclasses.replace(info.polar, overlap=0))
    reduced = reduce_like_decode(load_rgb(frame),
                                 math.ceil(min_decoded_side(turn_info, camera) * band_scale * samples))
    if radius_scale == 1.0 and band_scale == 1.0 and samples == 1:
        strip, _ = prepare_input(turn_info, reduced, camera)
        grid = polar_grid(turn_info, camera)
    else:
        grid = polar_grid(turn_info, camera)
        grid = dataclasses.replace(grid, radius_px=grid.radius_px * radius_scale,
                                   height=round(grid.height * band_scale),
                                   width=round(grid.width * band_scale))
        width, height = camera.image_size
        scale_xy = (reduced.shape[1] / width, reduced.shape[0] / height)
        strip = grid.unwrap(reduced, scale_xy, info.pad_value, samples)
    xyxy = grid.radius_aligned_to_polar(frame.boxes_cxcywh).reshape(-1, 4)
    full = full_turn_mask(grid, xyxy)
    feet = strip_feet(grid, camera, frame.locations_m[~full], xyxy[~full])
    return strip, xyxy[~full], feet, int(full.sum())


def roll_strip(strip: NDArray[np.uint8], xyxy: FloatArray, shift: int, overlap: int
               ) -> tuple[NDArray[np.uint8], FloatArray]:
    """The full-turn strip started `shift` columns later (start angle + 2π·shift/width), with its
    first `overlap` columns repeated at the right -> (H, width + overlap, 3) and the boxes'
    first-turn columns (centres in [−0.5, width − 0.5))."""
    width = strip.shape[1]
    rolled = np.roll(strip, -shift, axis=1)
    image = np.concatenate([rolled, rolled[:, :overlap]], axis=1)
    centre = (xyxy[:, 0] + xyxy[:, 2]) / 2 - shift
    move = np.floor((centre + 0.5) / width) * width + shift  # what takes the centre into the first turn
    moved = xyxy - np.stack([move, np.zeros_like(move), move, np.zeros_like(move)], axis=1)
    return np.ascontiguousarray(image), moved


class Photometric(Protocol):
    """The photometric strengths `photometric` reads (of a StripAugment or a frames.FrameAugment)."""

    @property
    def brightness(self) -> float: ...

    @property
    def contrast(self) -> float: ...

    @property
    def saturation(self) -> float: ...

    @property
    def hue_deg(self) -> float: ...

    @property
    def blur(self) -> float: ...

    @property
    def jpeg(self) -> float: ...


def photometric(image: NDArray[np.uint8], augment: Photometric, rng: np.random.Generator
                ) -> NDArray[np.uint8]:
    """Brightness, contrast, saturation and hue jitter, blur and JPEG noise of an RGB image."""
    out: NDArray[Any] = image.astype(np.float32)
    if augment.brightness:
        out *= 1.0 + rng.uniform(-augment.brightness, augment.brightness)
    if augment.contrast:
        mean = out.mean()
        out = (out - mean) * (1.0 + rng.uniform(-augment.contrast, augment.contrast)) + mean
    out = np.clip(out, 0, 255).astype(np.uint8)
    if augment.saturation or augment.hue_deg:
        hsv = cv2.cvtColor(out, cv2.COLOR_RGB2HSV).astype(np.float32)  # hue in [0, 180)
        hsv[..., 0] = (hsv[..., 0] + rng.uniform(-augment.hue_deg, augment.hue_deg) / 2) % 180
        hsv[..., 1] *= 1.0 + rng.uniform(-augment.saturation, augment.saturation)
        out = cv2.cvtColor(np.clip(hsv, 0, [179, 255, 255]).astype(np.uint8), cv2.COLOR_HSV2RGB)
    if rng.random() < augment.blur:
        out = cv2.GaussianBlur(out, (0, 0), sigmaX=rng.uniform(0.5, 1.5))
    if rng.random() < augment.jpeg:
        quality = int(rng.integers(25, 86))
        ok, encoded = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = np.asarray(cv2.imdecode(encoded, cv2.IMREAD_UNCHANGED))
    return np.asarray(out, dtype=np.uint8)


RAND_CONV_SIZES = (1, 3, 5, 7)  # the random filters' sides, one drawn per image


def rand_conv(image: NDArray[np.uint8], rng: np.random.Generator) -> NDArray[np.uint8]:
    """An RGB image with its colours and fine textures redrawn, its edges kept (RandConv, Xu et al.,
    ICLR 2021): the image through a random k × k filter mixing its three channels (k drawn from
    `RAND_CONV_SIZES`, weights normal with variance 1 / (3 k²)), each channel brought back to the
    image's own mean and spread, then blended with the image by a weight drawn from [0, 1]."""
    side = int(rng.choice(RAND_CONV_SIZES))
    weights = rng.normal(0.0, 1.0 / math.sqrt(3 * side * side), (3, 3, side, side)).astype(np.float32)
    planes = image.astype(np.float32)
    mixed = np.zeros_like(planes)
    for out in range(3):
        for channel in range(3):
            mixed[..., out] += cv2.filter2D(planes[..., channel], -1, weights[out, channel],
                                            borderType=cv2.BORDER_REFLECT)
    mean, spread = planes.mean(axis=(0, 1)), planes.std(axis=(0, 1))
    mixed = (mixed - mixed.mean(axis=(0, 1))) / (mixed.std(axis=(0, 1)) + 1e-6) * spread + mean
    keep = rng.uniform(0.0, 1.0)
    return np.clip(keep * planes + (1.0 - keep) * mixed, 0, 255).astype(np.uint8)


def nadir_labels(nadir: NadirPiece, cxcywh: FloatArray) -> FloatArray:
    """(N, 4) radius-aligned frame boxes (cx, cy, across, along) -> (N, 4) upright `xyxy` boxes of
    the nadir view (its own px, pixel centres): each bounds the ellipse its person's box holds, the
    box `contract.views.upright_to_radius_aligned` reads back as that person's (exactly on the
    image axes and for a round person; on a diagonal ray the box is square and reads back round,
    as the service reads any upright box there)."""
    boxes = np.asarray(cxcywh, dtype=np.float64).reshape(-1, 4)
    angle = np.arctan2(boxes[:, 1] - nadir.centre_px[1], boxes[:, 0] - nadir.centre_px[0])
    along, across = boxes[:, 3] / 2, boxes[:, 2] / 2
    half = np.stack([np.hypot(along * np.cos(angle), across * np.sin(angle)),
                     np.hypot(along * np.sin(angle), across * np.cos(angle))], axis=1) * nadir.scale
    corner = np.asarray(nadir.centre_px, dtype=np.float64) - nadir.half_px
    centre = (boxes[:, :2] - corner) * nadir.scale - 0.5
    return np.concatenate([centre - half, centre + half], axis=1)


def frame_nadir(frame: FrameAnnotations, info: ModelInfo) -> tuple[NDArray[np.uint8], FloatArray] | None:
    """A frame's nadir view as the default view plans it for its camera (decoded as the service
    decodes it) and its labels (N, 4) upright px (`nadir_labels`, kept as `visible_labels` keeps
    them); None where the plan has no nadir view."""
    if frame.camera is None:
        raise ValueError(f"{frame.path}: the nadir view needs the frame's camera")
    nadir = view_plan(info, frame.camera).nadir
    if nadir is None:
        return None
    reduced = reduce_like_decode(load_rgb(frame), min_decoded_side(info, frame.camera))
    image = nadir_input(nadir, reduced, frame.camera.image_size, info.pad_value)
    clipped, keep = visible_labels(nadir_labels(nadir, frame.boxes_cxcywh), (nadir.side, nadir.side))
    return image, clipped[keep]


def turn_square(image: NDArray[np.uint8], labels: FloatArray, quarters: int, flip: bool
                ) -> tuple[NDArray[np.uint8], FloatArray]:
    """A square upright view (S, S, 3) turned `quarters` × 90° counter-clockwise as displayed, then
    mirrored left-right where `flip`, with its upright labels (N, 4) (pixel centres) alike."""
    last = image.shape[0] - 1
    for _ in range(quarters % 4):  # (x, y) -> (y, last - x): np.rot90's counter-clockwise turn
        image = np.rot90(image)
        x1, y1, x2, y2 = labels.T
        labels = np.stack([y1, last - x2, y2, last - x1], axis=1)
    if flip:
        image = image[:, ::-1]
        x1, y1, x2, y2 = labels.T
        labels = np.stack([last - x2, y1, last - x1, y2], axis=1)
    return np.ascontiguousarray(image), labels


def pad_to(image: NDArray[np.uint8], height: int, width: int, pad_value: int) -> NDArray[np.uint8]:
    """An image (H, W, 3) padded below and right to `height` × `width` (a batch's size); ValueError
    where it is larger."""
    if image.shape[0] > height or image.shape[1] > width:
        raise ValueError(f"a {image.shape[1]} x {image.shape[0]} px view does not fit {width} x {height}")
    out = np.full((height, width, 3), pad_value, dtype=image.dtype)
    out[:image.shape[0], :image.shape[1]] = image
    return out


@dataclass(frozen=True)
class StripSample:
    """One strip: `image` (H, W, 3) uint8 RGB, `labels_xyxy` (N, 4) YOLOX coordinates (edge px)
    and each label's foot `feet` (N, 3): x, y in the same coordinates and metres per px, NaN rows
    where unknown."""

    image: NDArray[np.uint8]
    labels_xyxy: FloatArray
    feet: FloatArray

    def __post_init__(self) -> None:
        if (self.image.ndim != 3 or self.labels_xyxy.ndim != 2 or self.labels_xyxy.shape[1] != 4
                or self.feet.shape != (len(self.labels_xyxy), 3)):
            raise ValueError(f"image {self.image.shape}, labels {self.labels_xyxy.shape}, "
                             f"feet {self.feet.shape}")


# The strips a dataset caches take at most this many bytes; beyond, a strip is unwrapped each time it
# is drawn. A full turn at 3x the served rows and columns is ~19 MB (1248 x 4992 px): without a bound,
# band scales up to the second look's (`--band-scale 1 2 3`) on 1500 frames outgrow a 24 GiB machine.
STRIP_CACHE_BYTES = 10 * 2 ** 30


class PolarStripDataset:
    """Annotated frames -> augmented StripSamples for a PolarDetectorConfig; `set_epoch` first."""

    def __init__(self, frames: Sequence[FrameAnnotations], config: PolarDetectorConfig,
                 augment: StripAugment | None = None, seed: int = 0, cache: bool = True,
                 cache_bytes: int = STRIP_CACHE_BYTES) -> None:
        self.frames = list(frames)
        self.config = config
        self.info = training_info(config)
        self.augment = augment if augment is not None else StripAugment()
        self.seed = seed
        self.cache = cache
        self.cache_bytes = cache_bytes
        self.cached_bytes = 0
        self.epoch = 0
        self._strips: dict[tuple[int, float, float], tuple[NDArray[np.uint8], FloatArray, FloatArray]] = {}
        self._counted: set[tuple[int, float, float]] = set()
        self._nadirs: dict[int, tuple[NDArray[np.uint8], FloatArray] | None] = {}
        self.full_turns_left_out = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.frames)

    def left_out(self) -> dict[str, int]:
        """Counters for the epoch's log record."""
        return {"full_turn_labels_left_out": self.full_turns_left_out}

    def base(self, index: int, radius_scale: float = 1.0, band_scale: float = 1.0
             ) -> tuple[NDArray[np.uint8], FloatArray, FloatArray]:
        """The frame's full-turn strip, labels and feet (strip px), cached when `cache` while the
        cache holds under `cache_bytes`."""
        key = (index, radius_scale, band_scale)
        if key in self._strips:
            return self._strips[key]
        strip, xyxy, feet, full_turns = frame_strip(self.frames[index], self.info, radius_scale, band_scale,
                                                    self.augment.unwrap_samples)
        if key not in self._counted:  # each strip's labels counted once, cached or not
            self._counted.add(key)
            self.full_turns_left_out += full_turns
            if full_turns:
                log.info("%s: %d people over the principal point left out", self.frames[index].path,
                         full_turns)
        if self.cache and self.cached_bytes + strip.nbytes <= self.cache_bytes:
            self.cached_bytes += strip.nbytes
            self._strips[key] = (strip, xyxy, feet)
        return strip, xyxy, feet

    def nadir(self, index: int) -> tuple[NDArray[np.uint8], FloatArray] | None:
        """The frame's nadir view and its upright labels (`frame_nadir`), cached when `cache` (a
        384 px view is under 0.5 MB: 1500 frames' take 0.7 GB)."""
        if index in self._nadirs:
            return self._nadirs[index]
        found = frame_nadir(self.frames[index], self.info)
        if self.cache:
            self._nadirs[index] = found
        return found

    def nadir_sample(self, index: int, rng: np.random.Generator) -> StripSample | None:
        """The frame's nadir view turned by a random quarter and mirrored at random, photometric
        noise as a strip's, padded to the strips' size (their rows, and `crop_width` columns or the
        whole strip's); None where the frame's plan has no nadir view."""
        found = self.nadir(index)
        if found is None:
            return None
        image, labels = turn_square(*found, int(rng.integers(4)), bool(rng.random() < self.augment.flip))
        width = self.augment.crop_width or self.config.polar_width + self.config.polar_overlap
        image = self.surfaces(photometric(image, self.augment, rng), rng)
        image = pad_to(image, self.config.input_size, width, self.info.pad_value)
        return StripSample(image, labels + EDGE_TO_CENTRE_PX, np.full((len(labels), 3), np.nan))

    def surfaces(self, image: NDArray[np.uint8], rng: np.random.Generator) -> NDArray[np.uint8]:
        """`image` with its surfaces redrawn (`rand_conv`) at the rate `StripAugment.rand_conv` asks."""
        if self.augment.rand_conv and rng.random() < self.augment.rand_conv:
            return rand_conv(image, rng)
        return image

    def __getitem__(self, index: int) -> StripSample:
        rng = np.random.default_rng((self.seed, self.epoch, index))
        if self.augment.nadir_view and rng.random() < self.augment.nadir_view:
            sample = self.nadir_sample(index, rng)
            if sample is not None:
                return sample
        scales = self.augment.radius_scales
        scale = scales[int(rng.integers(len(scales)))] if len(scales) > 1 else scales[0]
        bands = self.augment.band_scales
        band = bands[int(rng.integers(len(bands)))] if len(bands) > 1 else bands[0]
        strip, first_turn, feet = self.base(index, scale, band)
        width = strip.shape[1]  # the served turn, or a band's at its scale
        shift = int(rng.integers(width)) if self.augment.roll else 0
        image, xyxy = roll_strip(strip, first_turn, shift, self.config.polar_overlap)
        labels, source, moved = label_copies(xyxy, width, (image.shape[1], image.shape[0]))
        feet = feet[source].copy()
        feet[:, 0] += (xyxy[:, 0] - first_turn[:, 0])[source] + moved  # each foot moves with its box
        if rng.random() < self.augment.flip:
            image = np.ascontiguousarray(image[:, ::-1])
            right = image.shape[1] - 1
            x1, y1, x2, y2 = labels.T
            labels = np.stack([right - x2, y1, right - x1, y2], axis=1)
            feet[:, 0] = right - feet[:, 0]
        if self.augment.crop_width:
            image, labels, feet = crop_window(image, labels, feet, self.augment.crop_width, rng)
        image, labels, feet = crop_rows(image, labels, feet, self.config.input_size, rng)  # a band's rows
        image = self.surfaces(photometric(image, self.augment, rng), rng)
        image = pad_rows(image, self.config.input_size, self.info.pad_value)  # a band under scale 1
        edge = np.array([EDGE_TO_CENTRE_PX, EDGE_TO_CENTRE_PX, 0.0])
        return StripSample(image, labels + EDGE_TO_CENTRE_PX, feet + edge)


class YoloxSample(Protocol):
    """A training sample of either view: `image` (H, W, 3) uint8 RGB, `labels_xyxy` (N, 4) edge px."""

    @property
    def image(self) -> NDArray[np.uint8]: ...

    @property
    def labels_xyxy(self) -> FloatArray: ...


def collate_feet(samples: Sequence[YoloxSample]) -> list[Tensor] | None:
    """Per-image feet (N_i, 3) float32 of samples that carry them (StripSample), else None."""
    feet = [getattr(s, "feet", None) for s in samples]
    if any(f is None for f in feet):
        return None
    return [torch.from_numpy(np.asarray(f, dtype=np.float32)) for f in feet]


def collate_strips(samples: Sequence[YoloxSample]) -> tuple[Tensor, list[Tensor]]:
    """Samples -> images (B, 3, H, W) float32 BGR 0-255 (what YoloxNano takes) and per-image
    labels (N_i, 4) float32 xyxy in YOLOX coordinates."""
    rgb = np.stack([s.image for s in samples])  # (B, H, W, 3)
    images = torch.from_numpy(rgb).permute(0, 3, 1, 2).flip(1).float()  # (B, 3, H, W) BGR
    labels = [torch.from_numpy(s.labels_xyxy.astype(np.float32)) for s in samples]
    return images.contiguous(), labels
