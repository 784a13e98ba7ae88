"""Zero-shot baselines: the COCO YOLOX-Nano ONNX (416 px, person class) read on views of the frame
that need no training, as points of comparison for FishLoc's detectors (README, "Detector").

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

import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from contract import FrameDetections
from fisheye import FisheyeCamera, Letterbox, rotated_nms

FloatArray = NDArray[np.float64]
INPUT = 416
STRIDES = (8, 16, 32)


def _grid(size: int) -> tuple[FloatArray, FloatArray]:
    cells, strides = [], []
    for stride in STRIDES:
        side = size // stride
        rows, cols = np.mgrid[0:side, 0:side]
        cells.append(np.stack([cols.ravel(), rows.ravel()], axis=1))
        strides.append(np.full(side * side, stride))
    return np.concatenate(cells).astype(np.float64), np.concatenate(strides).astype(np.float64)[:, None]


class CocoYolox:
    """The COCO YOLOX-Nano ONNX of `models/pretrained/` (416 px, BGR 0-255), person class."""

    def __init__(self, onnx_path: str | Path, threads: int = 2) -> None:
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        self.session = ort.InferenceSession(str(onnx_path), options, providers=["CPUExecutionProvider"])
        self.input_name = self.session.get_inputs()[0].name
        self.cells, self.strides = _grid(INPUT)

    def person_boxes(self, image_bgr: NDArray[np.uint8]) -> tuple[FloatArray, FloatArray]:
        """(416, 416, 3) BGR image -> person boxes (A, 4) `cxcywh` px and scores (A,)."""
        tensor = image_bgr.transpose(2, 0, 1)[None].astype(np.float32)
        out = np.asarray(self.session.run(None, {self.input_name: tensor})[0][0], dtype=np.float64)
        centre = (out[:, :2] + self.cells) * self.strides - 0.5  # YOLOX edge coordinates -> centres
        size = np.exp(out[:, 2:4]) * self.strides
        return np.concatenate([centre, size], axis=1), out[:, 4] * out[:, 5]


class RotatedCropsPredictor:
    """`rotations` upright crops per frame through the COCO YOLOX-Nano."""

    def __init__(self, onnx_path: str | Path, rotations: int = 12, threads: int = 2,
                 default_min_score: float = 0.3, nms_iou: float = 0.6) -> None:
        self.coco = CocoYolox(onnx_path, threads)
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
    """The whole frame letterboxed into the COCO YOLOX-Nano's input; upright boxes made radius-aligned."""

    def __init__(self, onnx_path: str | Path, threads: int = 2, default_min_score: float = 0.3,
                 nms_iou: float = 0.6) -> None:
        self.coco = CocoYolox(onnx_path, threads)
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
