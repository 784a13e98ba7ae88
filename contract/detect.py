"""A model's raw outputs -> the kept detections of one frame, in frame px.

Score threshold, finite and positive boxes, mapping back to the frame through the view, rotated
NMS about the camera's principal point, at most `max_detections`. `ModelRunner` chains it with
`view_inputs` (the view's inputs: `views.prepare_input`, and a planned view's nadir view) and
`merge_outputs`, and the second look (`second_look`, `contract.second_look`) for callers that hold
decoded frames (evaluation, benchmarks); the service's pipeline calls the same functions between
its own decode and localisation.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol, TypeGuard

import cv2
import numpy as np
from numpy.typing import NDArray

from contract import second_look as look
from contract.metadata import ModelInfo, OperatingPoint
from contract.model import RawOutputs
from contract.views import (
    DEFAULT_VIEW,
    InputMapping,
    PlannedInput,
    PolarInput,
    camera_view,
    mapping_layout,
    min_decoded_side,
    nadir_input,
    prepare_input,
)
from fisheye import FisheyeCamera, foot_points, rotated_iou, rotated_nms
from fisheye.view_plan import LongestPerson, ViewPlanConfig, view_layout

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrameDetections:
    """Kept detections of one frame: `boxes_cxcywh` (N, 4) frame px radius-aligned about
    `principal_point`, `scores` (N,) descending, `foot_px` (N, 2) frame px of the model's own
    floor-contact points or None when the model predicts none; `view_point` the operating point of
    the view they were found in (`ModelInfo.point_for`), when known."""

    boxes_cxcywh: FloatArray
    scores: FloatArray
    principal_point: tuple[float, float]
    foot_px: FloatArray | None = None
    view_point: OperatingPoint | None = None

    def __post_init__(self) -> None:
        n = len(self.scores)
        if self.boxes_cxcywh.shape != (n, 4) or (self.foot_px is not None and self.foot_px.shape != (n, 2)):
            raise ValueError(f"boxes {self.boxes_cxcywh.shape}, scores {self.scores.shape} and foot "
                             f"{None if self.foot_px is None else self.foot_px.shape} disagree")


@dataclass(frozen=True)
class Candidates:
    """A frame's candidates before the rotated NMS: boxes (N, 4) radius-aligned `cxcywh` frame px,
    scores (N,) and foot points (N, 2) frame px or None, after the view's cheap NMS in input px."""

    boxes_cxcywh: FloatArray
    scores: FloatArray
    foot_px: FloatArray | None


def frame_candidates(raw: RawOutputs, mapping: InputMapping, principal_point: tuple[float, float],
                     min_score: float, presuppress_iou: float | None, longest: LongestPerson | None = None
                     ) -> Candidates:
    """One image's RawOutputs -> its candidates in frame px: score ≥ `min_score`, finite and usable
    boxes, none longer than `longest` allows (a model with feet; None: no bound), the view's NMS in
    input px at `presuppress_iou` (None: none), each foot point the score-weighted median of its
    cluster's (`fused_feet`; with a presuppression only), people of the nadir view standing where
    their box puts them (`nadir_feet`)."""
    boxes = raw.boxes.astype(np.float64)
    scores = raw.scores.astype(np.float64)
    valid = np.isfinite(scores) & np.all(np.isfinite(boxes), axis=1)
    valid[valid] = mapping.usable(boxes[valid])
    feet = None if raw.foot is None else raw.foot.astype(np.float64)
    if feet is not None:
        valid &= np.all(np.isfinite(feet), axis=1)
        if longest is not None:
            valid[valid] = ~too_long(longest, mapping, boxes[valid], feet[valid], principal_point)
    keep = valid & (scores >= min_score)
    order = (mapping.presuppress(boxes[keep], scores[keep], presuppress_iou) if presuppress_iou is not None
             else np.arange(int(keep.sum())))
    kept_boxes, kept_scores = boxes[keep][order], scores[keep][order]
    foot = None
    if feet is not None:
        kept_feet = feet[keep][order]
        if presuppress_iou is not None:
            kept_feet = fused_feet(mapping, kept_boxes, kept_scores, kept_feet,
                                   boxes[valid], scores[valid], feet[valid])
        foot = mapping.points_to_frame(kept_feet)
    boxes_frame = mapping.boxes_to_frame(kept_boxes)
    if foot is not None:
        side = mapping.box_side_feet(kept_boxes)
        foot[side] = nadir_feet(boxes_frame[side], principal_point)
    return Candidates(boxes_frame, kept_scores, foot)


def too_long(longest: LongestPerson, mapping: InputMapping, boxes: FloatArray, feet: FloatArray,
             principal_point: tuple[float, float]) -> NDArray[np.bool_]:
    """(N,) which of (N, 4) input boxes with (N, 2) input feet run longer along the ray than
    `longest` allows where their feet stand; the nadir view's (whose feet come from the box) are
    never judged."""
    judged = ~mapping.box_side_feet(boxes)
    found = np.zeros(len(boxes), dtype=bool)
    if judged.any():
        found[judged] = longest.too_long(mapping.boxes_to_frame(boxes[judged]),
                                         mapping.points_to_frame(feet[judged]), principal_point)
    return found


def longest_person(mapping: InputMapping) -> LongestPerson | None:
    """The bound a planned view's plan sets on its candidates' lengths (`fisheye.view_plan.
    LongestPerson`); None for other views and plans without one."""
    return mapping.plan.longest_person if isinstance(mapping, PlannedInput) else None


def select_detections(raw: RawOutputs, mapping: InputMapping, principal_point: tuple[float, float],
                      min_score: float, nms_iou: float | None = 0.6, max_detections: int = 300
                      ) -> FrameDetections:
    """One image's RawOutputs -> FrameDetections with score ≥ `min_score`, in frame px.

    With NMS (`nms_iou` not None), each kept detection's foot point is the score-weighted median of
    those of its cluster (`fused_feet`); without, every output is passed through as it is. People
    of the nadir view stand where their box puts them (`nadir_feet`)."""
    found = frame_candidates(raw, mapping, principal_point, min_score, nms_iou, longest_person(mapping))
    if nms_iou is not None and len(found.scores) > 1:
        kept = rotated_nms(found.boxes_cxcywh, found.scores, principal_point, nms_iou)[:max_detections]
    else:
        kept = np.arange(min(len(found.scores), max_detections))
    return FrameDetections(found.boxes_cxcywh[kept], found.scores[kept], principal_point,
                           None if found.foot_px is None else found.foot_px[kept])


def above(detections: FrameDetections, min_score: float) -> FrameDetections:
    """The detections scoring at least `min_score` (scores are descending)."""
    keep = detections.scores >= min_score
    return dataclasses.replace(detections, boxes_cxcywh=detections.boxes_cxcywh[keep],
                               scores=detections.scores[keep],
                               foot_px=None if detections.foot_px is None else detections.foot_px[keep])


def looks_again(mapping: InputMapping) -> TypeGuard[PlannedInput]:
    """Whether frames seen through `mapping` get the second look (a planned view that has it)."""
    return isinstance(mapping, PlannedInput) and mapping.plan.second_look_patches > 0


def select_looking(model: ContractModel, raw: RawOutputs, mapping: InputMapping, image: NDArray[np.uint8],
                   scale_xy: tuple[float, float], principal_point: tuple[float, float], min_score: float,
                   nms_iou: float | None, max_detections: int = 300) -> FrameDetections:
    """`select_detections` with the second look (`second_look`) of a view that has it: the first
    look's detections from `look.FIRST_LOOK_FLOOR` (or `min_score`, where lower) looked at again in
    `image`, the decoded frame at `scale_xy` of the frame's size; the scores of the nadir view's
    disc put on the look's threshold (`look.nadir_scores`), then `min_score` applied. The service's
    pipeline and `ModelRunner` both select so, that what is evaluated is what is served."""
    if not looks_again(mapping):
        return select_detections(raw, mapping, principal_point, min_score, nms_iou, max_detections)
    first = select_detections(raw, mapping, principal_point, min(min_score, look.FIRST_LOOK_FLOOR), nms_iou,
                              max_detections)
    looked = second_look(model, image, scale_xy, mapping, first, nms_iou, max_detections)
    plan = mapping.plan
    without_look = view_layout(len(plan.bands), plan.nadir is not None)
    scores = look.nadir_scores(plan, looked.boxes_cxcywh, looked.scores, principal_point,
                               model.info.point_for(plan.layout).min_score,
                               model.info.point_for(without_look).min_score)
    order = np.argsort(-scores, kind="stable")
    return above(dataclasses.replace(looked, boxes_cxcywh=looked.boxes_cxcywh[order],
                                     scores=scores[order].astype(looked.scores.dtype),
                                     foot_px=None if looked.foot_px is None else looked.foot_px[order]),
                 min_score)


def look_input(info: ModelInfo, image: NDArray[np.uint8], scale_xy: tuple[float, float],
               mapping: InputMapping, first: FrameDetections
               ) -> tuple[list[look.Patch], look.Canvas, NDArray[np.uint8]] | None:
    """The second look's one model input for a frame seen through `mapping`: the patches about the
    first look's detections (`first`, from `look.FIRST_LOOK_FLOOR` on) that fit its budget, their
    canvas, and the canvas image, unwrapped from `image` (the decoded frame, `scale_xy` of the
    frame's size) with `info`'s pad value; None where the view has no look or no detection gets a
    patch."""
    if not looks_again(mapping):
        return None
    patches = look.plan_patches(mapping.plan, first.boxes_cxcywh, first.scores, first.principal_point)
    if not patches:
        return None
    patches, canvas = look.fit(patches, mapping.plan.second_look_pixels)
    inputs = [patch.grid.unwrap(image, scale_xy, border_value=info.pad_value) for patch in patches]
    return patches, canvas, canvas.paste(inputs, info.pad_value)


def second_look(model: ContractModel, image: NDArray[np.uint8], scale_xy: tuple[float, float],
                mapping: InputMapping, first: FrameDetections, nms_iou: float | None,
                max_detections: int = 300) -> FrameDetections:
    """The first look's detections (`first`, from `look.FIRST_LOOK_FLOOR` on) with what the
    second look adds (`contract.second_look`): each patch about a small, uncertain detection run
    through `model`, unwrapped from `image` (the decoded frame, `scale_xy` of the frame's size), its
    people read back to frame px and kept where `look.patch_keeps` and `look.parts_of` allow; then
    the rotated NMS again. A view without the second look returns `first` as it is."""
    looking = look_input(model.info, image, scale_xy, mapping, first)
    if looking is None:
        return first
    patches, canvas, canvas_image = looking
    pp = first.principal_point
    looked = {patch.detection for patch in patches}
    others = first.boxes_cxcywh[[i for i in range(len(first.scores)) if i not in looked]]
    boxes, scores = [first.boxes_cxcywh], [first.scores]
    feet: list[FloatArray | None] = [first.foot_px]
    raws = canvas.split(model.run(canvas_image))
    for patch, raw in zip(patches, raws, strict=True):
        # The strip's own NMS is the patch's: one band's piece has no overlap columns for the
        # rotated one to merge, and that runs over every look's people below.
        found = frame_candidates(raw, PolarInput(patch.grid), pp, look.FIRST_LOOK_FLOOR, nms_iou,
                                 longest_person(mapping))
        keep = look.patch_keeps(patch, found.boxes_cxcywh)
        keep[keep] = ~look.parts_of(patch.band, found.boxes_cxcywh[keep], others)
        boxes.append(found.boxes_cxcywh[keep])
        scores.append(found.scores[keep])
        feet.append(None if found.foot_px is None else found.foot_px[keep])
    all_boxes, all_scores = np.concatenate(boxes), np.concatenate(scores)
    known = [f for f in feet if f is not None]
    all_feet = np.concatenate(known) if len(known) == len(feet) else None
    kept = (np.argsort(-all_scores, kind="stable") if nms_iou is None
            else rotated_nms(all_boxes, all_scores, pp, nms_iou))[:max_detections]
    kept_feet = None
    if all_feet is not None and first.foot_px is not None:
        # A patch's person whom the first look found too stands where the first look put them: the
        # foot branch was trained at the bands' scales, not at the patches' twice that.
        # The first look's own detections keep their feet: only a patch's people are matched.
        kept_feet = all_feet[kept]
        from_patch = np.flatnonzero(kept >= len(first.scores))
        if len(from_patch):
            overlap = rotated_iou(all_boxes[kept[from_patch]], first.boxes_cxcywh, pp)
            best = overlap.argmax(axis=1)
            same = overlap[np.arange(len(from_patch)), best] >= look.SAME_PERSON_IOU
            kept_feet[from_patch[same]] = first.foot_px[best[same]]
    return dataclasses.replace(first, boxes_cxcywh=all_boxes[kept], scores=all_scores[kept],
                               foot_px=kept_feet)


FOOT_FUSION_IOU = 0.65  # a candidate votes on a kept detection's foot from this IoU (input px) on
FOOT_FUSION_SCORE = 0.3  # ... and from this fraction of the kept detection's score
# The nadir view's people stand this fraction of the way from their box-side foot point to their box
# centre (`nadir_feet`).
NADIR_FOOT_TOWARD_CENTRE = 0.5


def fused_feet(mapping: InputMapping, boxes: FloatArray, scores: FloatArray, feet: FloatArray,
               candidate_boxes: FloatArray, candidate_scores: FloatArray, candidate_feet: FloatArray
               ) -> FloatArray:
    """(N, 2) input-px foot points of the kept `boxes` (N, 4) with `scores` (N,) and their own
    `feet` (N, 2): each the score-weighted median, coordinate by coordinate, of the feet of the
    candidates (M, the kept ones among them) that overlap it by `FOOT_FUSION_IOU` and score at
    least `FOOT_FUSION_SCORE` times it.

    The cells around a person each predict the foot from their own view of it. Their score-weighted
    mean was steadier than the best cell's alone for 0.3.1 (validation renders: mean position error
    0.263 -> 0.254 m); since the foot refiner (0.4.0) the mean is worse than each detection's own
    foot (0.6.2 on the validation renders: 0.163 against 0.159 m), as one cell that reads a
    neighbour's feet pulls it. The median leaves such a cell out: 0.157 m there, and 0.162 -> 0.159 m
    on the unseen renders (docs/DETECTOR.md, "Foot point"). Boxes are not fused: that lowered real-frame AP75
    from 0.19 to 0.01. A view without a cheap IoU (the letterboxed fisheye view) keeps each
    detection's own foot."""
    overlap = mapping.overlaps(boxes, candidate_boxes) if len(boxes) else None
    if overlap is None:
        return feet
    votes = (overlap >= FOOT_FUSION_IOU) & (candidate_scores[None, :] >= FOOT_FUSION_SCORE * scores[:, None])
    kept, voter = np.nonzero(votes)  # a kept box votes for itself
    fused = np.asarray(feet, dtype=np.float64).copy()
    for axis in range(2):
        median = weighted_medians(kept, candidate_feet[voter, axis], candidate_scores[voter], len(boxes))
        fused[:, axis] = np.where(np.isnan(median), fused[:, axis], median)
    return fused


def weighted_medians(groups: NDArray[np.integer], values: FloatArray, weights: FloatArray, count: int
                     ) -> FloatArray:
    """(`count`,) the weighted median of the `values` (P,) of each group 0 .. count-1 (`groups`
    (P,)): the smallest value at which the group's cumulative weight reaches half its total; NaN
    for a group with no values or no weight."""
    result = np.full(count, np.nan)
    if len(values) == 0:
        return result
    order = np.lexsort((values, groups))
    groups, values, weights = groups[order], values[order], weights[order]
    totals = np.bincount(groups, weights, minlength=count)
    cumulative = np.cumsum(weights)
    starts = np.searchsorted(groups, np.arange(count))
    before = np.concatenate([[0.0], cumulative])[starts]  # weight of the groups ahead of each
    reached = np.flatnonzero(cumulative - before[groups] >= totals[groups] / 2)
    group_of, first = np.unique(groups[reached], return_index=True)
    answered = totals[group_of] > 0
    result[group_of[answered]] = values[reached[first]][answered]
    return result


def nadir_feet(boxes: FloatArray, principal_point: tuple[float, float]) -> FloatArray:
    """(N, 2) frame px where people the nadir view found stand, from their radius-aligned boxes
    (N, 4): `NADIR_FOOT_TOWARD_CENTRE` of the way from the box-side foot point to the box centre.

    Seen from above, a person's box runs from the body's near side (or the principal point, for one
    below the lens) to the head, which the lens throws outwards: the feet lie between. On the
    validation renders with the nadir view (`--max-view-pixels 1000000`) the box side put those
    people 0.19 m too near the nadir on average, the centre 0.18 m too far; the midpoint takes the
    view's mean position error from 0.162 to 0.156 m (fractions 0.4–0.6 are within 0.001 m of it),
    and on the unseen renders from 0.166 to 0.158 m (docs/DETECTOR.md, "Foot point")."""
    side = foot_points(boxes, principal_point).reshape(-1, 2)
    return side + NADIR_FOOT_TOWARD_CENTRE * (np.asarray(boxes, dtype=np.float64)[:, :2] - side)


def merge_outputs(raws: Sequence[RawOutputs], mapping: InputMapping) -> RawOutputs:
    """The outputs of a view's inputs (`view_inputs`) as one: the nadir view's boxes and points
    moved right of the canvas, to where the planned mapping reads them; scores descending."""
    if len(raws) == 1:
        return raws[0]
    if len(raws) != 2 or not isinstance(mapping, PlannedInput) or mapping.plan.nadir is None:
        raise ValueError(f"{len(raws)} outputs for a view of one input")
    canvas, nadir = raws
    shift = np.float32(mapping.plan.nadir.column)
    boxes = np.concatenate([canvas.boxes, nadir.boxes + np.array([shift, 0, shift, 0], dtype=np.float32)])
    scores = np.concatenate([canvas.scores, nadir.scores])
    foot = None
    if canvas.foot is not None:
        # the nadir view's people stand where their box puts them (`nadir_feet`): where it was run
        # without the foot branch (`run_view`), its boxes' bottom centres hold the place
        nadir_foot = nadir.foot if nadir.foot is not None else np.stack(
            [(nadir.boxes[:, 0] + nadir.boxes[:, 2]) / 2, nadir.boxes[:, 3]], axis=1)
        foot = np.concatenate([canvas.foot, nadir_foot + np.array([shift, 0], dtype=np.float32)])
    order = np.argsort(-scores, kind="stable")
    return RawOutputs(boxes[order], scores[order], None if foot is None else foot[order])


def run_view(model: ContractModel, images: Sequence[NDArray[np.uint8]], mapping: InputMapping) -> RawOutputs:
    """Run a view's inputs (`view_inputs`) and merge their outputs (`merge_outputs`): the nadir
    view without the foot branch (`ContractModel.run_boxes`), its people placed by their box
    (`nadir_feet`)."""
    return merge_outputs([model.run(images[0]), *(model.run_boxes(image) for image in images[1:])], mapping)


def view_inputs(info: ModelInfo, rgb: NDArray[np.uint8], camera: FisheyeCamera,
                config: ViewPlanConfig = DEFAULT_VIEW, workers: int = 1
                ) -> tuple[list[NDArray[np.uint8]], InputMapping]:
    """Every input a frame of `camera` (decoded as `rgb`, full or reduced scale) makes for the
    model, each one run, and the mapping of their merged outputs (`merge_outputs`): the view's
    input (`views.prepare_input`, its unwrap on `workers` threads), then its nadir view where the
    plan has one."""
    image, mapping = prepare_input(info, rgb, camera, config, workers)
    if isinstance(mapping, PlannedInput) and mapping.plan.nadir is not None:
        nadir = nadir_input(mapping.plan.nadir, rgb, camera.image_size, info.pad_value, workers)
        return [image, nadir], mapping
    return [image], mapping


def reduce_like_decode(rgb: NDArray[np.uint8], min_long_side: int) -> NDArray[np.uint8]:
    """A full-size frame shrunk by the largest factor of 2, 4, 8 that divides both sides and keeps
    the long side ≥ `min_long_side` (what the service's reduced JPEG decode gives, area-averaged)."""
    height, width = rgb.shape[:2]
    for factor in (8, 4, 2):
        if width % factor == 0 and height % factor == 0 and max(width, height) // factor >= min_long_side:
            small = cv2.resize(rgb, (width // factor, height // factor), interpolation=cv2.INTER_AREA)
            return np.asarray(small, dtype=np.uint8)
    return rgb


@dataclass(frozen=True)
class FrameOutputs:
    """One frame's raw model outputs and how they map back to it."""

    raw: RawOutputs
    mapping: InputMapping
    principal_point: tuple[float, float]
    # the decoded frame and its scale over the frame's size, where the view has the second look
    image: NDArray[np.uint8] | None = None
    scale_xy: tuple[float, float] = (1.0, 1.0)


class ContractModel(Protocol):
    """What runs a model of the contract: an `OnnxModel`, or a torch module wrapped alike."""

    @property
    def info(self) -> ModelInfo: ...

    def run(self, image: NDArray[np.uint8]) -> RawOutputs: ...

    def run_boxes(self, image: NDArray[np.uint8]) -> RawOutputs:
        """Boxes and scores alone (`foot` None); a model may skip its foot branch for them."""
        ...


class ModelRunner:
    """Decoded full-size frames with their cameras -> FrameDetections, as the service computes them."""

    def __init__(self, model: ContractModel, nms_iou: float | None = None, max_detections: int = 300,
                 view: ViewPlanConfig = DEFAULT_VIEW) -> None:
        self.model = model
        self.nms_iou = nms_iou  # None: the operating point's of each frame's view
        self.max_detections = max_detections
        self.view = view  # how a planned model's views are planned

    @property
    def default_min_score(self) -> float:
        return self.model.info.default_min_score

    def point(self, mapping: InputMapping) -> OperatingPoint:
        """The operating point a frame seen through `mapping` runs at: its view's own
        (`ModelInfo.point_for`), with this runner's NMS IoU where one was given."""
        return self.model.info.point_for(mapping_layout(mapping), self.nms_iou)

    def outputs(self, frames_rgb: Iterable[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera]
                ) -> list[FrameOutputs]:
        """Frames (H, W, 3) uint8 RGB and each one's camera (at the frame's size) -> the model's raw
        outputs, from the input the service would make of each (reduced decode, the model's view).
        The frames may come one at a time (a generator): only the outputs are kept."""
        info = self.model.info
        found = []
        for rgb, camera in zip(frames_rgb, cameras, strict=True):
            view = camera_view(self.view, camera)  # a camera's record may set its own budget
            reduced = reduce_like_decode(rgb, min_decoded_side(info, camera, view))
            images, mapping = view_inputs(info, reduced, camera, view)
            pp = (float(camera.principal_point[0]), float(camera.principal_point[1]))
            raw = run_view(self.model, images, mapping)
            scale = (reduced.shape[1] / rgb.shape[1], reduced.shape[0] / rgb.shape[0])
            found.append(FrameOutputs(raw, mapping, pp, reduced if looks_again(mapping) else None, scale))
        return found

    def select(self, outputs: Sequence[FrameOutputs], min_score: float, nms_iou: float | None = None
               ) -> list[FrameDetections]:
        """Raw outputs -> detections at `min_score` and `nms_iou` (default: each view's point's)."""
        found = []
        for o in outputs:
            point = self.point(o.mapping)
            iou = point.nms_iou if nms_iou is None else nms_iou
            if o.image is None:
                detections = select_detections(o.raw, o.mapping, o.principal_point, min_score, iou,
                                               self.max_detections)
            else:
                detections = select_looking(self.model, o.raw, o.mapping, o.image, o.scale_xy,
                                            o.principal_point, min_score, iou, self.max_detections)
            found.append(dataclasses.replace(detections, view_point=point))
        return found

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        """Frames (H, W, 3) uint8 RGB and each one's camera (at the frame's size) -> detections."""
        return self.select(self.outputs(frames_rgb, cameras), min_score)
