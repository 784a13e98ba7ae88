"""The one core function of every front end: (encoded frame, camera) -> who stands where.

decode (reduced-scale JPEG where the model input allows) -> letterbox -> ONNX model -> score
threshold and rotated NMS -> boxes back to frame pixels, their angle from the camera's own principal
point -> foot points -> floor and site positions. Torch-free: only numpy, OpenCV, onnxruntime and
the `fisheye` geometry.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fisheye import FisheyeCamera, Letterbox, cxcywh_to_corners, foot_points, radial_angles_rad, rotated_nms
from service.frame_decode import DecodedFrame, FrameError, check_frame_size, decode_frame, read_header
from service.onnx_model import ModelInfo, OnnxModel
from service.result import DetectionResult, Detections

FloatArray = NDArray[np.float64]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PipelineConfig:
    """Post-processing and safety limits of the pipeline."""

    nms_iou: float = 0.6
    max_detections: int = 300
    max_pixels: int = 40_000_000
    min_frame_side_px: int = 16  # smaller frames cannot show a person; refused, not guessed at

    def __post_init__(self) -> None:
        if not 0.0 < self.nms_iou <= 1.0:
            raise ValueError(f"nms_iou must be in (0, 1], got {self.nms_iou}")
        if self.max_detections < 1 or self.max_pixels < 1:
            raise ValueError("max_detections and max_pixels must be positive")


def localize(boxes_frame: FloatArray, scores: FloatArray, camera: FisheyeCamera) -> Detections:
    """Radius-aligned boxes (N, 4) frame px with scores (N,) -> Detections for `camera`, which must
    already be scaled to the frame's resolution."""
    pp = np.asarray(camera.principal_point, dtype=np.float64)
    foot = foot_points(boxes_frame, pp)
    floor = camera.floor_positions(foot)
    return Detections(
        scores=np.asarray(scores, dtype=np.float64),
        cxcywh=boxes_frame,
        angle_deg=np.degrees(radial_angles_rad(boxes_frame[:, :2], pp)),
        corners_xy=cxcywh_to_corners(boxes_frame, pp).reshape(-1, 4, 2),
        foot_px=foot,
        position_m=floor.xy_m,
        distance_m=floor.distance_m,
        site_position_m=camera.floor_to_site(floor.xy_m),
    )


class Pipeline:
    """A loaded model and its post-processing; `detect` is safe to call from several threads."""

    def __init__(self, model: OnnxModel, config: PipelineConfig | None = None) -> None:
        self.model = model
        self.config = config or PipelineConfig()

    @property
    def info(self) -> ModelInfo:
        return self.model.info

    def warm_up(self, runs: int = 2) -> None:
        """Run the model on blank inputs so the first real frame does not pay for lazy set-up."""
        size = self.info.input_size
        blank = np.full((size, size, 3), self.info.pad_value, dtype=np.uint8)
        for _ in range(runs):
            self.model.run(blank)

    def detect(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None = None,
               frame_id: str | None = None) -> DetectionResult:
        """Encoded frame bytes of `camera` -> DetectionResult. Raises FrameError for bad frames."""
        return self.detect_frame(data, camera, min_score=min_score, frame_id=frame_id)[0]

    def detect_frame(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None = None,
                     frame_id: str | None = None) -> tuple[DetectionResult, DecodedFrame]:
        """Like `detect`, and also the decoded frame (for drawing the result on it)."""
        threshold = self.info.default_min_score if min_score is None else float(min_score)
        if not 0.0 <= threshold <= 1.0:
            raise ValueError(f"min_score must be within [0, 1], got {threshold}")
        start = time.perf_counter()
        header = read_header(data)
        check_frame_size(header, self.config.max_pixels, self.config.min_frame_side_px)
        try:
            frame_camera = camera.scaled_to(header.size_wh)
        except ValueError as error:
            raise FrameError("frame_size_mismatch", str(error)) from None
        frame = decode_frame(data, self.info.input_size, self.config.max_pixels, header)
        decoded = time.perf_counter()

        letterbox = Letterbox.fit(frame.frame_wh, self.info.input_size)
        # A reduced decode keeps the letterbox of the full frame: its pixels map the same way.
        decoded_letterbox = dataclasses.replace(letterbox, frame_wh=frame.decoded_wh)
        image = decoded_letterbox.apply(frame.rgb, self.info.pad_value)
        preprocessed = time.perf_counter()

        boxes_input, scores = self.model.run(image)
        inferred = time.perf_counter()

        detections = self._postprocess(boxes_input, scores, threshold, letterbox, frame_camera)
        done = time.perf_counter()
        timing_ms = {
            "decode": (decoded - start) * 1e3,
            "preprocess": (preprocessed - decoded) * 1e3,
            "inference": (inferred - preprocessed) * 1e3,
            "postprocess": (done - inferred) * 1e3,
            "total": (done - start) * 1e3,
        }
        result = DetectionResult(
            camera_id=camera.id, frame_id=frame_id, image_wh=frame.frame_wh,
            model_name=self.info.name, model_version=self.info.version,
            detections=detections, timing_ms=timing_ms,
        )
        log.debug("frame %s of %s: %d detections in %.1f ms", frame_id, camera.id, len(detections.scores),
                  timing_ms["total"], extra={"camera_id": camera.id, "frame_id": frame_id})
        return result, frame

    def _postprocess(self, boxes_input: NDArray[np.float32], scores: NDArray[np.float32], threshold: float,
                     letterbox: Letterbox, camera: FisheyeCamera) -> Detections:
        return localize(*self.select(boxes_input, scores, threshold, letterbox, camera), camera)

    def select(self, boxes_input: NDArray[np.float32], scores: NDArray[np.float32], threshold: float,
               letterbox: Letterbox, camera: FisheyeCamera) -> tuple[FloatArray, FloatArray]:
        """Model outputs -> the kept boxes (M, 4) in frame px and their scores (M,): score threshold,
        finite positive boxes, rotated NMS about `camera`'s principal point, at most max_detections."""
        boxes = boxes_input.astype(np.float64)
        score = scores.astype(np.float64)
        keep = (
            np.isfinite(score) & (score >= threshold)
            & np.all(np.isfinite(boxes), axis=1) & (boxes[:, 2] > 0) & (boxes[:, 3] > 0)
        )
        boxes_frame = letterbox.boxes_input_to_frame(boxes[keep])
        score = score[keep]
        pp = np.asarray(camera.principal_point, dtype=np.float64)
        kept = rotated_nms(boxes_frame, score, pp, self.config.nms_iou)[: self.config.max_detections]
        return boxes_frame[kept], score[kept]

