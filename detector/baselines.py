"""Zero-shot baselines: a COCO detector of `../shared/pretrained/` (YOLOX-Nano, NanoDet-Plus-m or
PicoDet-S, 416 px, person class) read on views of the frame that need no training, as points of
comparison for FishLoc's detectors (README, "Detector").

- `RotatedCropsPredictor`: the frame is turned `rotations` times about its principal point (every
  360°/`rotations`); each time the square above the principal point (people there stand roughly
  upright, feet towards the centre) is resized to the 416 px input. A crop's box whose centre lies
  within the crop's own angular sector is kept and turned back into a radius-aligned frame box (its
  vertical axis is the ray), at `rotations` times the inference of one crop.
- `LetterboxPredictor`: the whole frame letterboxed into the 416 px input, each upright box turned
  into the radius-aligned box that bounds it (the fisheye view without a radius-aligned head).

Frame boxes are radius-aligned about the camera's principal point.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from contract import FrameDetections, ModelInfo, OnnxModel, RawOutputs, SessionThreads
from contract.metadata import OperatingPoint
from fisheye import FisheyeCamera, Letterbox, rotated_nms

FloatArray = NDArray[np.float64]
INPUT = 416
GFL_BINS = 8  # generalised focal loss: each box side a distribution over 8 bins of one stride
IMAGENET_MEAN_RGB = np.array([0.485, 0.456, 0.406]) * 255
IMAGENET_STD_RGB = np.array([0.229, 0.224, 0.225]) * 255
NANODET_MEAN_BGR = np.array([103.53, 116.28, 123.675])
NANODET_STD_BGR = np.array([57.375, 57.12, 58.395])


def _grid(size: int, strides: Sequence[int]) -> tuple[FloatArray, FloatArray]:
    """(N, 2) cell (column, row) and (N, 1) stride of every cell of `strides`' levels, row-major."""
    cells, per_cell = [], []
    for stride in strides:
        side = math.ceil(size / stride)
        rows, cols = np.mgrid[0:side, 0:side]
        cells.append(np.stack([cols.ravel(), rows.ravel()], axis=1))
        per_cell.append(np.full(side * side, stride))
    return np.concatenate(cells).astype(np.float64), np.concatenate(per_cell).astype(np.float64)[:, None]


def _gfl_boxes(logits: FloatArray, centres: FloatArray, strides: FloatArray) -> FloatArray:
    """(N, 4 * GFL_BINS) side logits (left, top, right, bottom) -> (N, 4) `cxcywh` boxes: each side's
    distance is its softmax's expectation over bins 0..7, in strides, from the cell's centre."""
    bins = logits.reshape(len(logits), 4, GFL_BINS)
    weights = np.exp(bins - bins.max(axis=2, keepdims=True))
    weights /= weights.sum(axis=2, keepdims=True)
    distance = (weights * np.arange(GFL_BINS)).sum(axis=2) * strides  # (N, 4): l, t, r, b
    x1, y1 = centres[:, 0] - distance[:, 0], centres[:, 1] - distance[:, 1]
    x2, y2 = centres[:, 0] + distance[:, 2], centres[:, 1] + distance[:, 3]
    return np.stack([(x1 + x2) / 2, (y1 + y2) / 2, x2 - x1, y2 - y1], axis=1)


def _without_weight_inputs(path: str | Path) -> bytes:
    """The ONNX file with initializers dropped from its graph inputs (PaddleDetection's export lists
    every weight as an input too, which stops onnxruntime from folding them: 1.5x its time)."""
    import onnx

    model = onnx.load(str(path))
    weights = {init.name for init in model.graph.initializer}
    inputs = [i for i in model.graph.input if i.name not in weights]
    del model.graph.input[:]
    model.graph.input.extend(inputs)
    return model.SerializeToString()


class CocoPersonNetwork:
    """A COCO detector of `../shared/pretrained/` (416 px, person = class 0) as its file gives it,
    recognised by its outputs: YOLOX-Nano (`output` [1, 3549, 85]: BGR 0-255, objectness times the
    person class), NanoDet-Plus-m (`output` [1, 3598, 112]: BGR with NanoDet's mean and std, 80 class
    scores then 32 GFL logits, cell centres at col * stride) or PicoDet-S (8 outputs, 4 score maps
    [1, N, 80] then 4 GFL maps [1, N, 32]: RGB / 255 with ImageNet's mean and std, cell centres at
    (col + 0.5) * stride). The README of `../shared/pretrained/` writes each one's pre- and
    post-processing down; a file of none of these shapes is a ValueError."""

    def __init__(self, onnx_path: str | Path, threads: int = 2) -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(_without_weight_inputs(onnx_path), options,
                                                providers=["CPUExecutionProvider"])
        except Exception as error:  # onnx and onnxruntime raise their own kinds
            raise ValueError(f"{onnx_path}: not a readable ONNX model ({error})") from error
        inputs = self.session.get_inputs()
        shapes = [tuple(o.shape) for o in self.session.get_outputs()]
        if len(inputs) != 1 or tuple(inputs[0].shape) != (1, 3, INPUT, INPUT):
            raise ValueError(f"{onnx_path}: wants one [1, 3, {INPUT}, {INPUT}] input, has "
                             f"{[(i.name, i.shape) for i in inputs]}")
        self.input_name = inputs[0].name
        strides: tuple[int, ...]
        if shapes == [(1, 3549, 85)]:
            self.family, strides = "yolox", (8, 16, 32)
        elif shapes == [(1, 3598, 112)]:
            self.family, strides = "nanodet-plus", (8, 16, 32, 64)
        elif len(shapes) == 8 and [s[2] for s in shapes] == [80] * 4 + [4 * GFL_BINS] * 4:
            self.family, strides = "picodet", (8, 16, 32, 64)
        else:
            raise ValueError(f"{onnx_path}: outputs {shapes} are none of YOLOX-Nano's, NanoDet-Plus's "
                             "or PicoDet's")
        self.cells, self.strides = _grid(INPUT, strides)

    def _tensor(self, image_bgr: NDArray[np.uint8]) -> NDArray[np.float32]:
        if self.family == "yolox":
            planes = image_bgr.astype(np.float32)
        elif self.family == "nanodet-plus":
            planes = ((image_bgr - NANODET_MEAN_BGR) / NANODET_STD_BGR).astype(np.float32)
        else:
            planes = ((image_bgr[..., ::-1] - IMAGENET_MEAN_RGB) / IMAGENET_STD_RGB).astype(np.float32)
        return np.ascontiguousarray(planes.transpose(2, 0, 1)[None])

    def person_boxes(self, image_bgr: NDArray[np.uint8]) -> tuple[FloatArray, FloatArray]:
        """(416, 416, 3) BGR image -> person boxes (A, 4) `cxcywh` px (pixel centres) and scores (A,)."""
        outputs = [np.asarray(o[0], dtype=np.float64)
                   for o in self.session.run(None, {self.input_name: self._tensor(image_bgr)})]
        if self.family == "yolox":
            out = outputs[0]
            centre = (out[:, :2] + self.cells) * self.strides - 0.5  # YOLOX edge coordinates -> centres
            size = np.exp(out[:, 2:4]) * self.strides
            return np.concatenate([centre, size], axis=1), out[:, 4] * out[:, 5]
        if self.family == "nanodet-plus":
            scores, logits, offset = outputs[0][:, 0], outputs[0][:, 80:], 0.0
        else:
            scores = np.concatenate([o[:, 0] for o in outputs[:4]])
            logits, offset = np.concatenate(outputs[4:]), 0.5
        boxes = _gfl_boxes(logits, (self.cells + offset) * self.strides, self.strides)
        boxes[:, :2] -= 0.5  # edge coordinates -> pixel centres
        return boxes, scores


class RotatedCropsPredictor:
    """`rotations` upright crops per frame through a COCO detector (`CocoPersonNetwork`)."""

    def __init__(self, onnx_path: str | Path, rotations: int = 12, threads: int = 2,
                 default_min_score: float = 0.3, nms_iou: float = 0.6) -> None:
        self.coco = CocoPersonNetwork(onnx_path, threads)
        self.rotations = rotations
        self.default_min_score = default_min_score
        self.nms_iou = nms_iou

    def detect_one(self, rgb: NDArray[np.uint8], camera: FisheyeCamera, min_score: float) -> FrameDetections:
        u0, v0 = (float(c) for c in camera.principal_point)
        side = min(rgb.shape[0], rgb.shape[1]) / 2  # the crop: one radius wide, from the centre up
        scale = INPUT / side
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        sector = math.pi / self.rotations
        boxes, scores = [], []
        for k in range(self.rotations):
            turn = 2 * math.pi * k / self.rotations  # the ray at screen angle -90° + turn points up
            # Affine map frame -> crop: rotate by -turn about the principal point, then put the
            # principal point at the crop's bottom middle and scale one radius to 416 px.
            c, s = math.cos(-turn), math.sin(-turn)
            rotate = np.array([[c, -s, u0 - c * u0 + s * v0], [s, c, v0 - s * u0 - c * v0]])
            shift = np.array([[scale, 0, (-u0 + side / 2) * scale], [0, scale, (-v0 + side) * scale]])
            affine = shift[:, :2] @ rotate
            affine = np.concatenate([affine[:, :2], (shift[:, :2] @ rotate[:, 2:] + shift[:, 2:])], axis=1)
            crop = cv2.warpAffine(bgr, affine, (INPUT, INPUT), flags=cv2.INTER_AREA,
                                  borderValue=(114, 114, 114))
            crop_boxes, crop_scores = self.coco.person_boxes(np.asarray(crop, dtype=np.uint8))
            keep = crop_scores >= min_score
            crop_boxes, crop_scores = crop_boxes[keep], crop_scores[keep]
            # Back to the frame: invert the affine map for the centres; sizes scale by 1 / scale.
            inverse = cv2.invertAffineTransform(affine)
            centres = crop_boxes[:, :2] @ inverse[:, :2].T + inverse[:, 2]
            angle = np.arctan2(centres[:, 1] - v0, centres[:, 0] - u0) - (turn - math.pi / 2)
            inside = np.abs((angle + math.pi) % (2 * math.pi) - math.pi) <= sector
            frame_boxes = np.concatenate([centres, crop_boxes[:, 2:] / scale], axis=1)[inside]
            boxes.append(frame_boxes)
            scores.append(crop_scores[inside])
        all_boxes = np.concatenate(boxes).reshape(-1, 4)
        all_scores = np.concatenate(scores)
        kept = (rotated_nms(all_boxes, all_scores, (u0, v0), self.nms_iou) if len(all_scores)
                else np.zeros(0, dtype=np.int64))
        return FrameDetections(all_boxes[kept].reshape(-1, 4), all_scores[kept], (u0, v0))

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        return [self.detect_one(rgb, camera, min_score)
                for rgb, camera in zip(frames_rgb, cameras, strict=True)]


class LetterboxPredictor:
    """The whole frame letterboxed into a COCO detector's input; upright boxes made radius-aligned."""

    def __init__(self, onnx_path: str | Path, threads: int = 2, default_min_score: float = 0.3,
                 nms_iou: float = 0.6) -> None:
        self.coco = CocoPersonNetwork(onnx_path, threads)
        self.default_min_score = default_min_score
        self.nms_iou = nms_iou

    def detect_one(self, rgb: NDArray[np.uint8], camera: FisheyeCamera, min_score: float) -> FrameDetections:
        u0, v0 = (float(c) for c in camera.principal_point)
        letterbox = Letterbox.fit((rgb.shape[1], rgb.shape[0]), INPUT)
        image = letterbox.apply(np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), dtype=np.uint8), 114)
        boxes, scores = self.coco.person_boxes(np.asarray(image, dtype=np.uint8))
        keep = scores >= min_score
        boxes, scores = letterbox.boxes_input_to_frame(boxes[keep]), scores[keep]
        # The radius-aligned box that bounds an upright w x h box: its extents along and across the ray.
        angle = np.arctan2(boxes[:, 1] - v0, boxes[:, 0] - u0)
        cos, sin = np.abs(np.cos(angle)), np.abs(np.sin(angle))
        radial = boxes[:, 2] * cos + boxes[:, 3] * sin
        tangential = boxes[:, 2] * sin + boxes[:, 3] * cos
        frame_boxes = np.stack([boxes[:, 0], boxes[:, 1], tangential, radial], axis=1)
        kept = (rotated_nms(frame_boxes, scores, (u0, v0), self.nms_iou) if len(scores)
                else np.zeros(0, dtype=np.int64))
        return FrameDetections(frame_boxes[kept].reshape(-1, 4), scores[kept], (u0, v0))

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        return [self.detect_one(rgb, camera, min_score)
                for rgb, camera in zip(frames_rgb, cameras, strict=True)]


def window_starts(length: int, window: int, overlap: int) -> list[int]:
    """Starts of `window`-long windows over `length` px, neighbours sharing `overlap` px, the last
    flush with the end (one window at 0 where `length` <= `window`)."""
    if length <= window:
        return [0]
    step = window - overlap
    starts = list(range(0, length - window, step))
    return [*starts, length - window]


def window_cores(starts: Sequence[int], window: int, length: int) -> list[tuple[float, float]]:
    """Per window, the part of [0, `length`) whose boxes it reports: from halfway into its overlap
    with the window before to halfway into the one after, so every point has one owner."""
    cores = []
    for k, start in enumerate(starts):
        low = 0.0 if k == 0 else (start + starts[k - 1] + window) / 2
        high = float(length) if k == len(starts) - 1 else (starts[k + 1] + start + window) / 2
        cores.append((low, high))
    return cores


class TiledCocoModel:
    """A COCO detector file (`CocoPersonNetwork`, 416² input) read on a FishLoc view of any size as a
    `contract.ContractModel`: the input is cut into 416 px windows overlapping by `overlap` px
    (padded with the view's pad value where it is smaller), each window run alone, and each window
    reports the boxes whose centre lies in its share of the overlaps (`window_cores`). `info` is a
    planned polar model's metadata (the strip it was trained on, its pad value) with this file's
    name and operating point, so the service's planner, mapping, NMS and evaluation run it as they
    run a FishLoc model; it has no foot output (positions from the box side). Boxes in input px as
    the polar view's contract has them (`xyxy`), every candidate from `floor_score`."""

    def __init__(self, onnx_path: str | Path, info: ModelInfo, threads: int = 2, overlap: int = 128,
                 floor_score: float = 0.01) -> None:
        if not info.planned:
            raise ValueError("a tiled COCO model reads a planned view: give it a planned model's metadata")
        if not 0 <= overlap < INPUT // 2:
            raise ValueError(f"overlap must lie in [0, {INPUT // 2}), got {overlap}")
        self.network = CocoPersonNetwork(onnx_path, threads)
        self._info = info
        self.overlap = overlap
        self.floor_score = floor_score

    @property
    def info(self) -> ModelInfo:
        return self._info

    def run(self, image: NDArray[np.uint8]) -> RawOutputs:
        """(H, W, 3) uint8 RGB view -> every window's boxes it owns, best first."""
        height, width = image.shape[:2]
        canvas = image
        if height < INPUT or width < INPUT:
            canvas = np.full((max(height, INPUT), max(width, INPUT), 3), self._info.pad_value, dtype=np.uint8)
            canvas[:height, :width] = image
        bgr = np.ascontiguousarray(canvas[..., ::-1])
        rows, columns = (window_starts(n, INPUT, self.overlap) for n in (height, width))
        boxes, scores = [], []
        for top, (row_low, row_high) in zip(rows, window_cores(rows, INPUT, height), strict=True):
            for left, (col_low, col_high) in zip(columns, window_cores(columns, INPUT, width), strict=True):
                found, score = self.network.person_boxes(bgr[top:top + INPUT, left:left + INPUT])
                cx, cy = found[:, 0] + left, found[:, 1] + top
                own = (score >= self.floor_score) & (cx >= col_low) & (cx < col_high) & (
                    cy >= row_low) & (cy < row_high)
                half_w, half_h = found[own, 2] / 2, found[own, 3] / 2
                boxes.append(np.stack([cx[own] - half_w, cy[own] - half_h, cx[own] + half_w,
                                       cy[own] + half_h], axis=1))
                scores.append(score[own])
        all_boxes, all_scores = np.concatenate(boxes), np.concatenate(scores)
        order = np.argsort(-all_scores, kind="stable")
        return RawOutputs(all_boxes[order].astype(np.float32), all_scores[order].astype(np.float32))

    def run_boxes(self, image: NDArray[np.uint8]) -> RawOutputs:
        return self.run(image)

    @classmethod
    def like(cls, onnx_path: str | Path, planned_model: str | Path, threads: int = 2,
             point: OperatingPoint | None = None) -> TiledCocoModel:
        """The file read on the views of `planned_model` (a planned FishLoc ONNX: its strip, pad value
        and planning), at `point` (default: score 0.3, NMS 0.5) in every layout."""
        reference = OnnxModel(planned_model, SessionThreads(intra_op=1)).info
        point = point or OperatingPoint(0.3, 0.5)
        info = dataclasses.replace(reference, name=Path(onnx_path).stem, version="zero-shot",
                                   default_min_score=point.min_score, nms_iou=point.nms_iou, view_points=(),
                                   trained_on="COCO (tiled zero-shot)", sha256="")
        return cls(onnx_path, info, threads)
