"""Run a FishLoc ONNX model on frames, torch-free: letterbox, infer, map boxes back to the frame.

Runtime dependencies only (numpy, OpenCV, onnxruntime, fisheye), so that evaluation and the service
pre- and post-process frames the same way. The model contract (DESIGN.md): input `image` uint8
(N, S, S, 3) RGB letterboxed; outputs `boxes` (N, K, 4) radius-aligned `cxcywh` in input pixels
(aligned about the input centre) and `scores` (N, K) sorted descending.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from fisheye import Letterbox, rotated_nms

FloatArray = NDArray[np.float64]

REQUIRED_METADATA = (
    "fishloc.input_size",
    "fishloc.pad_value",
    "fishloc.box_format",
    "fishloc.model_name",
    "fishloc.model_version",
    "fishloc.trained_on",
    "fishloc.default_min_score",
)
BOX_FORMAT = "cxcywh_radius_aligned"


class ModelFormatError(ValueError):
    """An ONNX file that does not follow the FishLoc model contract."""


@dataclass(frozen=True)
class ModelMetadata:
    input_size: int
    pad_value: int
    box_format: str
    model_name: str
    model_version: str
    trained_on: str
    default_min_score: float

    @classmethod
    def from_props(cls, props: dict[str, str], source: str) -> ModelMetadata:
        missing = [key for key in REQUIRED_METADATA if key not in props]
        if missing:
            raise ModelFormatError(f"{source} lacks metadata {', '.join(missing)}")
        if props["fishloc.box_format"] != BOX_FORMAT:
            raise ModelFormatError(f"{source} has box format {props['fishloc.box_format']!r}, "
                                   f"expected {BOX_FORMAT!r}")
        try:
            return cls(
                input_size=int(props["fishloc.input_size"]),
                pad_value=int(props["fishloc.pad_value"]),
                box_format=props["fishloc.box_format"],
                model_name=props["fishloc.model_name"],
                model_version=props["fishloc.model_version"],
                trained_on=props["fishloc.trained_on"],
                default_min_score=float(props["fishloc.default_min_score"]),
            )
        except ValueError as error:
            raise ModelFormatError(f"{source} has unreadable metadata: {error}") from None


@dataclass(frozen=True)
class FrameDetections:
    """Detections of one frame: `boxes_cxcywh` (N, 4) frame px radius-aligned about
    `principal_point` (the frame centre mapped from the input centre), `scores` (N,) descending."""

    boxes_cxcywh: FloatArray
    scores: FloatArray
    principal_point: tuple[float, float]

    def __post_init__(self) -> None:
        if self.boxes_cxcywh.shape != (len(self.scores), 4):
            raise ValueError(f"boxes {self.boxes_cxcywh.shape} and scores {self.scores.shape} disagree")


def input_principal_point(input_size: int) -> tuple[float, float]:
    """The input centre, about which the model's boxes are radius-aligned (input px)."""
    centre = (input_size - 1) / 2.0
    return centre, centre


def postprocess(boxes_input: NDArray[np.floating], scores: NDArray[np.floating], letterbox: Letterbox,
                min_score: float, nms_iou: float | None = 0.6) -> FrameDetections:
    """One image's raw outputs (K, 4), (K,) -> FrameDetections in frame px above `min_score`.

    Peaks are already one per cell; the rotated NMS removes the rare second peak on one person.
    """
    keep = scores >= min_score
    boxes = np.asarray(boxes_input[keep], dtype=np.float64)
    kept_scores = np.asarray(scores[keep], dtype=np.float64)
    principal = input_principal_point(letterbox.size)
    if nms_iou is not None and len(boxes) > 1:
        order = rotated_nms(boxes, kept_scores, principal, nms_iou)
        boxes, kept_scores = boxes[order], kept_scores[order]
    frame_pp = letterbox.input_to_frame(np.asarray([principal]))[0]
    return FrameDetections(letterbox.boxes_input_to_frame(boxes).reshape(-1, 4), kept_scores,
                           (float(frame_pp[0]), float(frame_pp[1])))


class OnnxDetector:
    """A FishLoc ONNX model in onnxruntime, with its contract checked on load."""

    def __init__(self, path: str | Path, threads: int | None = None) -> None:
        self.path = Path(path)
        options = ort.SessionOptions()
        if threads is not None:
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own exception types
            raise ModelFormatError(f"cannot load ONNX model {self.path}: {error}") from None
        props = dict(self.session.get_modelmeta().custom_metadata_map)
        self.metadata = ModelMetadata.from_props(props, str(self.path))
        inputs = self.session.get_inputs()
        outputs = {o.name for o in self.session.get_outputs()}
        if len(inputs) != 1 or inputs[0].name != "image" or not {"boxes", "scores"} <= outputs:
            raise ModelFormatError(f"{self.path} must have input 'image' and outputs 'boxes', 'scores'")

    @property
    def input_size(self) -> int:
        return self.metadata.input_size

    def letterbox_for(self, frame_wh: tuple[int, int]) -> Letterbox:
        return Letterbox.fit(frame_wh, self.input_size)

    def prepare(self, frame_rgb: NDArray[np.uint8]) -> tuple[NDArray[np.uint8], Letterbox]:
        """(H, W, 3) uint8 RGB frame -> (S, S, 3) model input and its letterbox."""
        height, width = frame_rgb.shape[:2]
        letterbox = self.letterbox_for((width, height))
        return letterbox.apply(frame_rgb, self.metadata.pad_value), letterbox

    def infer(self, inputs: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """(N, S, S, 3) uint8 -> raw boxes (N, K, 4) input px and scores (N, K)."""
        boxes, scores = self.session.run(["boxes", "scores"], {"image": inputs})
        return np.asarray(boxes, dtype=np.float32), np.asarray(scores, dtype=np.float32)

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], min_score: float | None = None,
               nms_iou: float | None = 0.6) -> list[FrameDetections]:
        """Frames (H, W, 3) uint8 RGB -> one FrameDetections each (frame px, scores ≥ min_score)."""
        if not frames_rgb:
            return []
        threshold = self.metadata.default_min_score if min_score is None else min_score
        prepared = [self.prepare(frame) for frame in frames_rgb]
        boxes, scores = self.infer(np.stack([p[0] for p in prepared]))
        return [postprocess(boxes[i], scores[i], letterbox, threshold, nms_iou)
                for i, (_, letterbox) in enumerate(prepared)]
