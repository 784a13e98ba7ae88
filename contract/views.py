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
    NadirPiece,
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

    def box_side_feet(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        """(N,) which boxes take their foot point from the box (`contract.detect.nadir_feet`),
        whatever a `foot` output says (the nadir view's: the network learnt its feet on the strip)."""
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

    def box_side_feet(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        return np.zeros(len(boxes), dtype=bool)


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

    def box_side_feet(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        return np.zeros(len(boxes), dtype=bool)


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


def camera_view(config: ViewPlanConfig, camera: FisheyeCamera, limit: int | None = None) -> ViewPlanConfig:
    """How `camera`'s view is planned: `config` with the camera's own budget (its record's
    `max_view_pixels`) in place of `config`'s, at most `limit` where one is given, and its own
    second look (`second_look_pixels`) and bound on a person's length (`longest_person_ratio`, 0:
    none) in place of `config`'s where its record sets them."""
    own, look, longest = camera.max_view_pixels, camera.second_look_pixels, camera.longest_person_ratio
    if own is not None:
        config = dataclasses.replace(config, max_pixels=own if limit is None else min(own, limit))
    if longest is not None:
        config = dataclasses.replace(config, longest_person_ratio=longest or None)
    return config if look is None else dataclasses.replace(config, second_look_pixels=look)


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
    a planned view, per sample row of its densest band, `ViewPlanConfig.unwrap_samples` a row, and
    per `NADIR_DECODE_SLACK` px of its nadir view)."""
    if info.polar is None:
        return info.input_size
    if info.planned:
        plan = view_plan(info, camera, config)
        nadir = [plan.nadir.scale / NADIR_DECODE_SLACK] if plan.nadir else []
        bands = [g.px_per_radius_px * config.unwrap_samples for g in plan.grids]
        return math.ceil(max(camera.image_size) * max(bands + nadir))
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
                  config: ViewPlanConfig = DEFAULT_VIEW, workers: int = 1
                  ) -> tuple[NDArray[np.uint8], InputMapping]:
    """A frame of `camera` (scaled to the frame's full size), decoded as `rgb` (h, w, 3) at full or
    reduced scale -> the model's input (H, W, 3) uint8 and the mapping of its px to the frame's
    (a planned model's view planned with `config`; a polar unwrap on `workers` threads)."""
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
        samples = config.unwrap_samples
        map_u, map_v = _cached_canvas_maps(plan, scale_xy, samples)
        return unwrap_with_maps(rgb, map_u, map_v, info.pad_value, workers, samples), PlannedInput(plan)
    grid = polar_grid(info, camera)
    map_u, map_v = _cached_maps(grid, scale_xy)
    return unwrap_with_maps(rgb, map_u, map_v, info.pad_value, workers), PolarInput(grid)


@dataclass(frozen=True)
class PlannedInput:
    """A planned view's mapping (`fisheye.view_plan.ViewPlan`): strips of several rings stacked in
    one canvas; a box or point belongs to the piece whose rows hold it (a box: its centre). The
    nadir view's outputs stand right of the canvas, from its `column` on (`contract.detect.
    merge_outputs` puts them there): there a box is an upright `xyxy` of the crop, read as the
    radius-aligned box that bounds the ellipse it holds."""

    plan: ViewPlan

    def _in_nadir(self, columns: NDArray[np.floating]) -> NDArray[np.bool_]:
        nadir = self.plan.nadir
        if nadir is None:
            return np.zeros(len(columns), dtype=bool)
        return np.asarray(columns, dtype=np.float64) >= nadir.column - 0.5

    def _piece_of(self, rows: NDArray[np.floating]) -> NDArray[np.int64]:
        starts = np.asarray(self.plan.row_offsets, dtype=np.float64)
        return np.clip(np.searchsorted(starts, np.asarray(rows, dtype=np.float64) + 0.5, side="right") - 1,
                       0, len(starts) - 1).astype(np.int64)

    def parts(self, boxes: NDArray[np.floating]) -> NDArray[np.int64]:
        """(N,) the part of the view each of (N, 4) canvas boxes belongs to: 0 the nadir view,
        1 + k band k (by its centre, as the mapping reads it)."""
        xyxy = np.asarray(boxes, dtype=np.float64)
        band_of_piece = np.asarray([k for k, band in enumerate(self.plan.bands) for _ in range(band.pieces)])
        part = band_of_piece[self._piece_of((xyxy[:, 1] + xyxy[:, 3]) / 2)] + 1
        part[self._in_nadir((xyxy[:, 0] + xyxy[:, 2]) / 2)] = 0
        return np.asarray(part, dtype=np.int64)

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

    def _nadir_local(self, points: NDArray[np.floating]) -> FloatArray:
        """(N, 2) px right of the canvas -> (N, 2) px of the nadir view itself."""
        assert self.plan.nadir is not None
        return np.asarray(points, dtype=np.float64) - (self.plan.nadir.column, 0.0)

    def boxes_to_frame(self, boxes: NDArray[np.floating]) -> FloatArray:
        xyxy = np.asarray(boxes, dtype=np.float64)
        nadir = self._in_nadir((xyxy[:, 0] + xyxy[:, 2]) / 2)
        out = np.zeros((len(xyxy), 4), dtype=np.float64)
        strip = ~nadir
        centre_rows = (xyxy[strip, 1] + xyxy[strip, 3]) / 2
        out[strip] = self._each_piece(xyxy[strip], centre_rows, [1, 3], PolarGrid.polar_to_radius_aligned, 4)
        if nadir.any():
            assert self.plan.nadir is not None
            out[nadir] = upright_to_radius_aligned(self.plan.nadir, self._nadir_local(
                xyxy[nadir].reshape(-1, 2)).reshape(-1, 4))
        return out

    def points_to_frame(self, points: NDArray[np.floating]) -> FloatArray:
        uv = np.asarray(points, dtype=np.float64)
        nadir = self._in_nadir(uv[:, 0])
        out = np.zeros((len(uv), 2), dtype=np.float64)
        # A point in the padding below a piece belongs to it: feet lie at the bottom of their boxes.
        out[~nadir] = self._each_piece(uv[~nadir], uv[~nadir, 1], [1], PolarGrid.strip_to_frame, 2)
        if nadir.any():
            assert self.plan.nadir is not None
            out[nadir] = self.plan.nadir.input_to_frame(self._nadir_local(uv[nadir]))
        return out

    def usable(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        sized = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        xyxy = np.asarray(boxes, dtype=np.float64)
        nadir = self._in_nadir((xyxy[:, 0] + xyxy[:, 2]) / 2)
        centre_rows = (xyxy[:, 1] + xyxy[:, 3]) / 2
        piece = self._piece_of(centre_rows)
        offsets = np.asarray(self.plan.row_offsets, dtype=np.float64)[piece]
        owned = np.zeros(len(boxes), dtype=bool)
        for index in np.unique(piece[~nadir]):
            chosen = (piece == index) & ~nadir
            centre_px = self.plan.grids[index].row_to_radius_px(centre_rows[chosen] - offsets[chosen])
            low, high = self.plan.owned_px[index]
            owned[chosen] = (centre_px >= low) & (centre_px < high)
        if nadir.any():
            owned[nadir] = self._nadir_owned(xyxy[nadir])
        return sized & owned

    def _nadir_owned(self, xyxy: FloatArray) -> NDArray[np.bool_]:
        """Nadir-view boxes (canvas px) centred within its owned disc and clear of its edges (a
        person cut by the crop's edge is read whole by the strip)."""
        nadir = self.plan.nadir
        assert nadir is not None
        local = self._nadir_local(xyxy.reshape(-1, 2)).reshape(-1, 4)
        far_edge = nadir.side - 1 - NADIR_EDGE_PX
        inside = (local[:, :2] > NADIR_EDGE_PX).all(axis=1) & (local[:, 2:] < far_edge).all(axis=1)
        centre = nadir.input_to_frame((local[:, :2] + local[:, 2:]) / 2)
        offset = centre - np.asarray(nadir.centre_px)
        return inside & (np.hypot(offset[:, 0], offset[:, 1]) < nadir.owned_px)

    def presuppress(self, boxes: NDArray[np.floating], scores: NDArray[np.floating],
                    iou_threshold: float) -> NDArray[np.int64]:
        return strip_nms(boxes, scores, iou_threshold)  # the nadir view's boxes never meet the strip's

    def overlaps(self, boxes: NDArray[np.floating], others: NDArray[np.floating]) -> FloatArray | None:
        return strip_iou(boxes, others)

    def box_side_feet(self, boxes: NDArray[np.floating]) -> NDArray[np.bool_]:
        xyxy = np.asarray(boxes, dtype=np.float64)
        return self._in_nadir((xyxy[:, 0] + xyxy[:, 2]) / 2)


NADIR_EDGE_PX = 2.0  # a nadir-view box this near the crop's edge is a person the crop cuts
# The nadir view may upsample a reduced decode up to this factor rather than make the frame's decode
# larger: a 2952 px frame decoded at full size costs 40 ms more end to end than at half size (its
# nadir view then upsamples 1.1x). At 2x, Lunch3's nadir view (1.6x) brought two false people:
# precision 0.95 -> 0.87 (docs/DETECTOR.md, "The nadir view and a faster graph").
NADIR_DECODE_SLACK = 1.5


def mapping_layout(mapping: InputMapping) -> str | None:
    """The layout of a planned view (`ViewPlan.layout`); None for the fixed views."""
    return mapping.plan.layout if isinstance(mapping, PlannedInput) else None


def upright_to_radius_aligned(nadir: NadirPiece, xyxy: NDArray[np.floating]) -> FloatArray:
    """(N, 4) upright `xyxy` boxes of the nadir view (its own px) -> (N, 4) radius-aligned
    `cxcywh` frame px: the box about the same centre that bounds the ellipse the upright box holds
    (a person seen from above is round more than square; the box bounding the upright box's
    corners would be up to 1.4x too large on a diagonal ray)."""
    boxes = np.asarray(xyxy, dtype=np.float64)
    centre = nadir.input_to_frame((boxes[:, :2] + boxes[:, 2:]) / 2)
    half_w = (boxes[:, 2] - boxes[:, 0]) / 2 / nadir.scale
    half_h = (boxes[:, 3] - boxes[:, 1]) / 2 / nadir.scale
    angle = np.arctan2(centre[:, 1] - nadir.centre_px[1], centre[:, 0] - nadir.centre_px[0])
    along = 2 * np.hypot(half_w * np.cos(angle), half_h * np.sin(angle))
    across = 2 * np.hypot(half_w * np.sin(angle), half_h * np.cos(angle))
    return np.stack([centre[:, 0], centre[:, 1], across, along], axis=1)


def nadir_input(nadir: NadirPiece, rgb: NDArray[np.uint8], frame_wh: tuple[int, int],
                pad_value: int, workers: int = 1) -> NDArray[np.uint8]:
    """The nadir view `nadir` of a frame of `frame_wh` px decoded as `rgb` (full or reduced scale),
    sampled on `workers` threads."""
    scale_xy = (rgb.shape[1] / frame_wh[0], rgb.shape[0] / frame_wh[1])
    map_u, map_v = _cached_nadir_maps(nadir, scale_xy)
    return unwrap_with_maps(rgb, map_u, map_v, pad_value, workers)


@functools.lru_cache(maxsize=32)
def _cached_nadir_maps(nadir: NadirPiece, scale_xy: tuple[float, float]) -> tuple[NDArray[Any], NDArray[Any]]:
    """The nadir view's sampling maps (fixed-point) for a frame resized by `scale_xy`."""
    ticks = np.arange(nadir.side, dtype=np.float64)
    columns, rows = np.meshgrid(ticks, ticks)
    uv = nadir.input_to_frame(np.stack([columns.ravel(), rows.ravel()], axis=1))
    map_u = ((uv[:, 0] + 0.5) * scale_xy[0] - 0.5).reshape(nadir.side, nadir.side).astype(np.float32)
    map_v = ((uv[:, 1] + 0.5) * scale_xy[1] - 0.5).reshape(nadir.side, nadir.side).astype(np.float32)
    fixed_uv, fraction = cv2.convertMaps(map_u, map_v, cv2.CV_16SC2)
    return np.asarray(fixed_uv), np.asarray(fraction)


@functools.lru_cache(maxsize=32)
def _cached_canvas_maps(plan: ViewPlan, scale_xy: tuple[float, float], samples: int = 1
                        ) -> tuple[NDArray[Any], NDArray[Any]]:
    """The canvas's sampling maps (fixed-point; `samples` per px along each axis), every piece at
    its rows, the gaps outside the frame."""
    width, height = plan.canvas_wh
    map_u = np.full((height * samples, width * samples), -1e4, dtype=np.float32)
    map_v = np.full((height * samples, width * samples), -1e4, dtype=np.float32)
    for grid, offset in zip(plan.grids, plan.row_offsets, strict=True):
        piece_u, piece_v = grid.sampling_maps(scale_xy, samples)
        rows, columns = piece_u.shape
        map_u[offset * samples:offset * samples + rows, :columns] = piece_u
        map_v[offset * samples:offset * samples + rows, :columns] = piece_v
    fixed_uv, fraction = cv2.convertMaps(map_u, map_v, cv2.CV_16SC2)
    return np.asarray(fixed_uv), np.asarray(fraction)
