"""How a decoded frame becomes a model's input, and how the model's outputs map back to the frame.

- `fisheye` view: the frame letterboxed into a square (`fisheye.Letterbox`); boxes come back as
  radius-aligned `cxcywh` in input px.
- `polar` view: the frame unwrapped about the camera's principal point (`fisheye.polar.PolarGrid`);
  boxes come back as `xyxy` in strip px, each the ring segment whose bounding radius-aligned box is
  the detection. The sampling maps are cached per grid and decoded size, so a camera's frames pay
  for them once.

A frame may arrive decoded at a reduced scale (a JPEG decoded at 1/2, 1/4 or 1/8): the input is
made from the reduced image, and every mapping goes to the full frame's pixels.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from contract.metadata import ModelInfo
from fisheye import FisheyeCamera, Letterbox
from fisheye.polar import PolarGrid, unwrap_with_maps
from fisheye.view_plan import (
    ViewPlan,
    ViewPlanConfig,
    ViewReference,
    farthest_corner_px,
    plan_view,
    ring_radius_px,
)

FloatArray = NDArray[np.float64]
DEFAULT_VIEW = ViewPlanConfig()  # how a planned model's views are planned unless the caller says


class InputMapping(Protocol):
    """Model-input coordinates -> frame px."""

    def boxes_to_frame(self, boxes: NDArray[np.floating]) -> FloatArray:
        """(N, 4) boxes in the view's format -> (N, 4) radius-aligned `cxcywh` frame px."""
        ...

    def points_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        """(N, 2) input px -> (N, 2) frame px."""
        ...

    def usable(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        """(N,) which of (N, 4) finite boxes in the view's format have a positive size and stand
        where the view reads them (a planned view: centred in the radii their band owns)."""
        ...

    def presuppress(self, boxes: NDArray[np.floating], scores: NDArray[np.floating],
                    iou_threshold: float) -> NDArray[np.int64]:
        """Indices of (N, 4) boxes left by a cheap NMS in input px before the rotated NMS in the
        frame (which costs O(N²) polygon clips), best first; all of them where there is none."""
        ...

    def overlaps(self, boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray | None:
        """(N, M) IoU in input px of (N, 4) and (M, 4) boxes where the view measures it cheaply
        (the polar strip), else None."""
        ...


@dataclass(frozen=True)
class FisheyeInput:
    """The `fisheye` view's mapping: a letterbox of the full frame."""

    letterbox: Letterbox

    def boxes_to_frame(self, boxes: NDArray[np.floating]) -> FloatArray:
        return self.letterbox.boxes_input_to_frame(boxes).reshape(-1, 4)

    def points_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        return self.letterbox.input_to_frame(points).reshape(-1, 2)

    def usable(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        return (boxes[:, 2] > 0) & (boxes[:, 3] > 0)

    def presuppress(self, boxes: NDArray[np.floating], scores: NDArray[np.floating],
                    iou_threshold: float) -> NDArray[np.int64]:
        return np.argsort(-np.asarray(scores), kind="stable")

    def overlaps(self, boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray | None:
        return None  # radius-aligned boxes turn with their position: their IoU is the frame's polygon one


@dataclass(frozen=True)
class PolarInput:
    """The `polar` view's mapping: the strip's grid in full-frame px."""

    grid: PolarGrid

    def boxes_to_frame(self, boxes: NDArray[np.floating]) -> FloatArray:
        return self.grid.polar_to_radius_aligned(boxes).reshape(-1, 4)

    def points_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        return self.grid.strip_to_frame(points).reshape(-1, 2)

    def usable(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        return (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])

    def presuppress(self, boxes: NDArray[np.floating], scores: NDArray[np.floating],
                    iou_threshold: float) -> NDArray[np.int64]:
        return strip_nms(boxes, scores, iou_threshold)

    def overlaps(self, boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray | None:
        return strip_iou(boxes, others)


def strip_nms(boxes: NDArray[np.floating], scores: NDArray[np.floating], iou_threshold: float
              ) -> NDArray[np.int64]:
    """Indices of (N, 4) `xyxy` strip boxes left by greedy axis-aligned NMS, best first.

    The strip boxes of one person overlap there as their ring segments do in the frame. The frame's
    rotated NMS then only merges what the strip cannot see, the copies of a person in the overlap
    columns (and, in a planned view, in two bands). A box is dropped when its IoU with a better
    kept box exceeds `iou_threshold`. While many candidates are left, each kept box is compared with
    the survivors only; the last `NMS_MATRIX` are finished on their IoU matrix, so memory stays
    bounded and a frame's few dozen candidates cost one matrix."""
    order = np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable")
    ranked = np.asarray(boxes, dtype=np.float64)[order]
    keep: list[int] = []
    while len(order) > NMS_MATRIX:
        keep.append(int(order[0]))
        survivors = strip_iou(ranked[:1], ranked[1:])[0] <= iou_threshold
        order, ranked = order[1:][survivors], ranked[1:][survivors]
    overlapping = strip_iou(ranked, ranked) > iou_threshold
    suppressed = np.zeros(len(order), dtype=bool)
    for row in range(len(order)):
        if not suppressed[row]:
            keep.append(int(order[row]))
            suppressed |= overlapping[row]
    return np.asarray(keep, dtype=np.int64)


NMS_MATRIX = 256  # candidates `strip_nms` finishes on a full IoU matrix


def strip_iou(boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray:
    """(N, M) IoU of (N, 4) and (M, 4) `xyxy` strip boxes."""
    a, b = np.asarray(boxes, dtype=np.float64)[:, None, :], np.asarray(others, dtype=np.float64)[None]
    width = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0.0, None)
    height = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0.0, None)
    inter = width * height
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    return np.asarray(inter / np.maximum(area_a + area_b - inter, 1e-12), dtype=np.float64)


def polar_radius_px(camera: FisheyeCamera, max_theta_deg: float) -> float:
    """Frame px from the principal point to the ring θ = min(`max_theta_deg`, the camera's field),
    at most the distance to the frame's farthest corner (nothing lies beyond it)."""
    return min(ring_radius_px(camera, min(max_theta_deg, camera.theta_max_deg)), farthest_corner_px(camera))


def polar_grid(info: ModelInfo, camera: FisheyeCamera) -> PolarGrid:
    """The strip of a polar model for frames of `camera` (already scaled to the frame)."""
    if info.polar is None:
        raise ValueError(f"model {info.name} has the {info.view} view, not polar")
    return PolarGrid(principal_point=(float(camera.principal_point[0]), float(camera.principal_point[1])),
                     radius_px=polar_radius_px(camera, info.polar.max_theta_deg),
                     height=info.input_size, width=info.polar.width, overlap=info.polar.overlap)


def view_reference(info: ModelInfo) -> ViewReference:
    """The strip a planned model was trained on."""
    if info.polar is None:
        raise ValueError(f"model {info.name} has the {info.view} view, not polar")
    return ViewReference(rows=info.input_size, turn_columns=info.polar.width, overlap=info.polar.overlap,
                         max_theta_deg=info.polar.max_theta_deg)


@functools.lru_cache(maxsize=256)
def _cached_plan(reference: ViewReference, camera_json: str, config: ViewPlanConfig) -> ViewPlan:
    return plan_view(FisheyeCamera.model_validate_json(camera_json), reference, config)


def view_plan(info: ModelInfo, camera: FisheyeCamera, config: ViewPlanConfig = DEFAULT_VIEW) -> ViewPlan:
    """The planned view of a planned model for frames of `camera` (at the frames' size), made once
    per camera, model and budget. `fisheye.view_plan.ViewPlanError` when none can be made."""
    return _cached_plan(view_reference(info), camera.model_dump_json(), config)


def min_decoded_side(info: ModelInfo, camera: FisheyeCamera, config: ViewPlanConfig = DEFAULT_VIEW) -> int:
    """The smallest long side (px) a reduced decode of `camera`'s frame may have for this model:
    the letterbox's side, or for a polar strip one frame pixel per strip row along the radius (for
    a planned view, per row of its densest band)."""
    if info.polar is None:
        return info.input_size
    if info.planned:
        plan = view_plan(info, camera, config)
        return math.ceil(max(camera.image_size) * max(g.px_per_radius_px for g in plan.grids))
    grid = polar_grid(info, camera)
    return math.ceil(max(camera.image_size) * grid.height / grid.radius_px)


@functools.lru_cache(maxsize=32)
def _cached_maps(grid: PolarGrid, scale_xy: tuple[float, float]) -> tuple[NDArray[Any], NDArray[Any]]:
    """`grid`'s sampling maps in OpenCV's fixed-point form (4.5 MB for a 416 × 1792 strip, a quarter
    less than float maps, and the same samples): one entry per camera geometry and frame size."""
    map_u, map_v = grid.sampling_maps(scale_xy)
    fixed_uv, fraction = cv2.convertMaps(map_u, map_v, cv2.CV_16SC2)
    return np.asarray(fixed_uv), np.asarray(fraction)


def prepare_input(info: ModelInfo, rgb: NDArray[np.uint8], camera: FisheyeCamera,
                  config: ViewPlanConfig = DEFAULT_VIEW) -> tuple[NDArray[np.uint8], InputMapping]:
    """A frame of `camera` (scaled to the frame's full size), decoded as `rgb` (h, w, 3) at full or
    reduced scale -> the model's input (H, W, 3) uint8 and the mapping of its px to the frame's
    (a planned model's view planned with `config`)."""
    frame_wh = camera.image_size
    decoded_wh = (rgb.shape[1], rgb.shape[0])
    if info.polar is None:
        letterbox = Letterbox.fit(frame_wh, info.input_size)
        # A reduced decode keeps the letterbox of the full frame: its pixels map the same way.
        image = dataclasses.replace(letterbox, frame_wh=decoded_wh).apply(rgb, info.pad_value)
        return image, FisheyeInput(letterbox)
    scale_xy = (decoded_wh[0] / frame_wh[0], decoded_wh[1] / frame_wh[1])
    if info.planned:
        plan = view_plan(info, camera, config)
        map_u, map_v = _cached_canvas_maps(plan, scale_xy)
        return unwrap_with_maps(rgb, map_u, map_v, info.pad_value), PlannedInput(plan)
    grid = polar_grid(info, camera)
    map_u, map_v = _cached_maps(grid, scale_xy)
    return unwrap_with_maps(rgb, map_u, map_v, info.pad_value), PolarInput(grid)


@dataclass(frozen=True)
class PlannedInput:
    """A planned view's mapping (`fisheye.view_plan.ViewPlan`): strips of several rings stacked in
    one canvas; a box or point belongs to the piece whose rows hold it (a box: its centre)."""

    plan: ViewPlan

    def _piece_of(self, rows: NDArray[np.floating]) -> NDArray[np.int64]:
        starts = np.asarray(self.plan.row_offsets, dtype=np.float64)
        return np.clip(np.searchsorted(starts, np.asarray(rows, dtype=np.float64) + 0.5, side="right") - 1,
                       0, len(starts) - 1).astype(np.int64)

    def _each_piece(self, values: NDArray[np.floating], rows: NDArray[np.floating], row_columns: list[int],
                    convert: Callable[[PolarGrid, FloatArray], FloatArray], width: int) -> FloatArray:
        """(N, C) canvas values, each mapped by `convert` through the piece that holds its `rows`
        (the canvas rows of `row_columns` moved into that piece, clipped to it) -> (N, width)."""
        out = np.zeros((len(values), width), dtype=np.float64)
        piece = self._piece_of(rows)
        for index in np.unique(piece):
            grid, offset = self.plan.grids[index], self.plan.row_offsets[index]
            chosen = piece == index
            local = np.asarray(values[chosen], dtype=np.float64).copy()
            local[:, row_columns] = np.clip(local[:, row_columns] - offset, -0.5, grid.height - 0.5)
            out[chosen] = convert(grid, local)
        return out

    def boxes_to_frame(self, boxes: NDArray[np.floating]) -> FloatArray:
        centre_rows = (np.asarray(boxes)[:, 1] + np.asarray(boxes)[:, 3]) / 2
        return self._each_piece(boxes, centre_rows, [1, 3], PolarGrid.polar_to_radius_aligned, 4)

    def points_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        # A point in the padding below a piece belongs to it: feet lie at the bottom of their boxes.
        return self._each_piece(points, np.asarray(points)[:, 1], [1], PolarGrid.strip_to_frame, 2)

    def usable(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        sized = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        xyxy = np.asarray(boxes, dtype=np.float64)
        centre_rows = (xyxy[:, 1] + xyxy[:, 3]) / 2
        piece = self._piece_of(centre_rows)
        offsets = np.asarray(self.plan.row_offsets, dtype=np.float64)[piece]
        owned = np.zeros(len(boxes), dtype=bool)
        for index in np.unique(piece):
            chosen = piece == index
            centre_px = self.plan.grids[index].row_to_radius_px(centre_rows[chosen] - offsets[chosen])
            low, high = self.plan.owned_px[index]
            owned[chosen] = (centre_px >= low) & (centre_px < high)
        return sized & owned

    def presuppress(self, boxes: NDArray[np.floating], scores: NDArray[np.floating],
                    iou_threshold: float) -> NDArray[np.int64]:
        return strip_nms(boxes, scores, iou_threshold)

    def overlaps(self, boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray | None:
        return strip_iou(boxes, others)


@functools.lru_cache(maxsize=32)
def _cached_canvas_maps(plan: ViewPlan, scale_xy: tuple[float, float]) -> tuple[NDArray[Any], NDArray[Any]]:
    """The canvas's sampling maps (fixed-point), every piece at its rows, the gaps outside the frame."""
    width, height = plan.canvas_wh
    map_u = np.full((height, width), -1e4, dtype=np.float32)
    map_v = np.full((height, width), -1e4, dtype=np.float32)
    for grid, offset in zip(plan.grids, plan.row_offsets, strict=True):
        piece_u, piece_v = grid.sampling_maps(scale_xy)
        rows, columns = piece_u.shape
        map_u[offset:offset + rows, :columns] = piece_u
        map_v[offset:offset + rows, :columns] = piece_v
    fixed_uv, fraction = cv2.convertMaps(map_u, map_v, cv2.CV_16SC2)
    return np.asarray(fixed_uv), np.asarray(fraction)
