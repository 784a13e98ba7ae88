"""The one core function of every front end: (encoded frame, camera) -> who stands where.

decode (reduced-scale JPEG where the model input allows) -> the model's view of the frame
(letterbox or polar unwrap, `contract.views`) -> ONNX model -> score threshold, boxes back to frame
pixels and rotated NMS about the camera's own principal point (`contract.detect`), where the view
has it the second look at the small, uncertain detections (`contract.second_look`) -> foot points ->
floor and site positions -> the camera's masks (a foot point inside one drops its detection).
Torch-free: only numpy, OpenCV, onnxruntime, `fisheye` and `contract`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contract import (
    FrameDetections,
    InputMapping,
    ModelInfo,
    OnnxModel,
    OperatingPoint,
    RawOutputs,
    min_decoded_side,
    run_view,
    view_inputs,
)
from contract import select_detections as select_raw
from contract.detect import looks_again, select_looking
from contract.views import DEFAULT_VIEW, camera_view, mapping_layout, view_plan, view_reference
from fisheye import FisheyeCamera, cxcywh_to_corners, foot_points, radial_angles_rad
from fisheye.view_plan import ViewPlan, ViewPlanConfig, ViewPlanError, may_have_nadir, nadir_side
from service.frame_decode import DecodedFrame, FrameError, check_frame_size, decode_frame, read_header
from service.result import DetectionResult, Detections

FloatArray = NDArray[np.float64]

log = logging.getLogger(__name__)


class ViewBudgetError(ViewPlanError):
    """A camera record asking for a view budget over the server's limit."""


@dataclass(frozen=True)
class PipelineConfig:
    """Post-processing and safety limits of the pipeline."""

    nms_iou: float | None = None  # None: the model's own (`fishloc.nms_iou`)
    max_detections: int = 300
    max_pixels: int = 40_000_000
    min_frame_side_px: int = 16  # smaller frames cannot show a person; refused, not guessed at
    view: ViewPlanConfig = DEFAULT_VIEW  # how a planned model's views are planned (its budget)
    # the largest budget a camera's record may set for its own view (None: any)
    max_camera_view_pixels: int | None = None

    def __post_init__(self) -> None:
        if self.nms_iou is not None and not 0.0 < self.nms_iou <= 1.0:
            raise ValueError(f"nms_iou must be in (0, 1], got {self.nms_iou}")
        if self.max_detections < 1 or self.max_pixels < 1:
            raise ValueError("max_detections and max_pixels must be positive")
        if self.max_camera_view_pixels is not None and self.max_camera_view_pixels < 1:
            raise ValueError("max_camera_view_pixels must be positive")


def localize(boxes_frame: FloatArray, scores: FloatArray, camera: FisheyeCamera,
             foot_px: FloatArray | None = None) -> Detections:
    """Radius-aligned boxes (N, 4) frame px with scores (N,) -> Detections for `camera`, which must
    already be scaled to the frame's resolution. People stand at the model's own floor-contact
    points `foot_px` (N, 2) when it predicts them, else at their boxes' foot points."""
    pp = np.asarray(camera.principal_point, dtype=np.float64)
    foot = foot_points(boxes_frame, pp) if foot_px is None else np.asarray(foot_px, dtype=np.float64)
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


def drop_masked(detections: Detections, camera: FisheyeCamera) -> tuple[Detections, int]:
    """The detections whose foot point lies outside every mask of `camera` (already scaled to the
    frame), and how many were dropped: people seen in mirrors, posters and screens stand nowhere."""
    if not camera.masks_px or len(detections) == 0:
        return detections, 0
    inside = camera.masked(detections.foot_px)
    return detections.take(~inside), int(inside.sum())


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
        blank = self.model.blank_input()
        # the nadir view's session too (made on first use), at its input's size, where the budget
        # gives cameras the view
        reference = view_reference(self.info) if self.info.planned else None
        side = (nadir_side(reference, self.config.view)
                if reference is not None and may_have_nadir(reference, self.config.view) else None)
        nadir = None if side is None else np.full((side, side, 3), self.info.pad_value, dtype=np.uint8)
        for _ in range(runs):
            self.model.warm_up(blank, nadir)

    def detect(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None = None,
               frame_id: str | None = None) -> DetectionResult:
        """Encoded frame bytes of `camera` -> DetectionResult. Raises FrameError for bad frames."""
        return self.detect_frame(data, camera, min_score=min_score, frame_id=frame_id)[0]

    def detect_frame(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None = None,
                     frame_id: str | None = None) -> tuple[DetectionResult, DecodedFrame]:
        """Like `detect`, and also the decoded frame (for drawing the result on it)."""
        if min_score is not None and not 0.0 <= float(min_score) <= 1.0:
            raise ValueError(f"min_score must be within [0, 1], got {min_score}")
        with self.model.frame():  # in flight from its decode on (the model's spinning policy)
            return self._detect_frame(data, camera, min_score, frame_id)

    def _detect_frame(self, data: bytes, camera: FisheyeCamera, min_score: float | None,
                      frame_id: str | None) -> tuple[DetectionResult, DecodedFrame]:
        start = time.perf_counter()
        header = read_header(data)
        check_frame_size(header, self.config.max_pixels, self.config.min_frame_side_px)
        try:
            frame_camera = camera.scaled_to(header.size_wh)
        except ValueError as error:
            raise FrameError("frame_size_mismatch", str(error)) from None
        view = self.view_config(camera)
        try:
            smallest_side = min_decoded_side(self.info, frame_camera, view)
        except ViewPlanError as error:
            raise FrameError("view_unplannable", f"camera {camera.id}: {error}") from None
        frame = decode_frame(data, smallest_side, self.config.max_pixels, header)
        decoded = time.perf_counter()

        images, mapping = view_inputs(self.info, frame.rgb, frame_camera, view, self.model.frame_threads())
        preprocessed = time.perf_counter()

        raw = run_view(self.model, images, mapping)
        threshold = self.point(mapping_layout(mapping)).min_score if min_score is None else float(min_score)
        if looks_again(mapping):
            # the second look's patches run on the model too: their time counts as inference
            kept = self.select(raw, mapping, threshold, frame_camera, frame.rgb, frame.scale_xy)
            inferred = time.perf_counter()
        else:
            inferred = time.perf_counter()
            kept = self.select(raw, mapping, threshold, frame_camera)
        detections, masked = drop_masked(
            localize(kept.boxes_cxcywh, kept.scores, frame_camera, kept.foot_px), frame_camera)
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
            detections=detections, timing_ms=timing_ms, masked=masked,
        )
        log.debug("frame %s of %s: %d detections in %.1f ms", frame_id, camera.id, len(detections.scores),
                  timing_ms["total"], extra={"camera_id": camera.id, "frame_id": frame_id})
        return result, frame

    def plan(self, camera: FisheyeCamera) -> ViewPlan | None:
        """The view planned for `camera`'s frames at its own image size (None: the model's view is
        fixed). ViewPlanError when none can be made."""
        if not self.info.planned:
            return None
        return view_plan(self.info, camera, self.view_config(camera))

    def view_config(self, camera: FisheyeCamera) -> ViewPlanConfig:
        """How `camera`'s view is planned: the configured view with the camera's own budget where
        its record sets one, at most `max_camera_view_pixels` (a record written before that limit
        was lowered is planned at the limit)."""
        return camera_view(self.config.view, camera, self.config.max_camera_view_pixels)

    def admit(self, camera: FisheyeCamera) -> ViewPlan | None:
        """The view planned for a camera about to be written to the registry (None: the model's
        view is fixed). ViewPlanError when its record asks for a budget over the limit or no view
        can be made: nothing is written then."""
        own, limit = camera.max_view_pixels, self.config.max_camera_view_pixels
        if own is not None and limit is not None and own > limit:
            raise ViewBudgetError(f"its max_view_pixels {own} is over this server's limit {limit} "
                                  f"(--max-camera-view-pixels)")
        return self.plan(camera)

    def point(self, layout: str | None) -> OperatingPoint:
        """The operating point of a view of `layout` (`ViewPlan.layout`; None: a fixed view): the
        model's own for it (`ModelInfo.point_for`), with the configured NMS IoU where one is set."""
        return self.info.point_for(layout, self.config.nms_iou)

    def select(self, raw: RawOutputs, mapping: InputMapping, threshold: float, camera: FisheyeCamera,
               image: NDArray[np.uint8] | None = None, scale_xy: tuple[float, float] = (1.0, 1.0)
               ) -> FrameDetections:
        """Model outputs -> the kept detections in frame px: score threshold, finite positive boxes,
        rotated NMS about `camera`'s principal point (at the view's operating point's IoU), at most
        max_detections; with the decoded frame `image` (at `scale_xy` of the frame's size), the
        second look of a view that has it (`contract.detect.select_looking`)."""
        pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
        nms_iou = self.point(mapping_layout(mapping)).nms_iou
        if image is None:
            return select_raw(raw, mapping, pp, threshold, nms_iou, self.config.max_detections)
        return select_looking(self.model, raw, mapping, image, scale_xy, pp, threshold, nms_iou,
                              self.config.max_detections)
