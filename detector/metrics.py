"""Detection and localisation metrics of LOAF, on radius-aligned boxes or a dataset's own (numpy).

- AP: COCO-style, 101-point interpolated, greedy matching by score with rotated-box IoU; `mAP` is the
  mean over IoU 0.50:0.05:0.95, `AP50`, `AP75` single thresholds; `AP10`, `AP30` below it say how
  much of what AP50 misses is found with a box that fits badly (the model's box fit against the
  annotators'), not missed.
- AP_near / AP_mid / AP_far: AP50 restricted to people 0–10, 10–20 and > 20 m from the nadir (GT
  distance). As COCO does for area ranges, people outside the range are ignored (detections matched
  to them count neither way) and so are unmatched detections whose own floor distance (foot point)
  lies outside it.
- PE: Euclidean floor error (m) of detections matched at IoU 0.5 to people with known positions,
  placed by their foot point (`mPE`, `PE_near/mid/far` by GT distance): the model's own `foot`
  output where it has one, else the box-side foot point; by the box-side foot point alone
  (`mPE_box_side`, ...) and by their box centre (`mPE_center`, ...), all on the same matches.
  These matches take every detection from the evaluation's lowest score (0.05), as AP does;
  `mPE_reported` (and `PE_matches_reported`) keeps those at or above the threshold of precision and
  recall: the people the service reports, whose floor positions users get. `common_errors` gives
  several models' `mPE_common` over the people all of them match, their feet compared alike.
- precision / recall at one score threshold, matched at IoU 0.5; `recall_nadir` the recall of the
  people below the lens (box centre within 0.2 of the image circle's radius), seen from above.

Crowd boxes (people marked `iscrowd`, too hidden to count) are ignore regions: a detection that
matches no person but overlaps a crowd box at the IoU threshold counts neither way.

Frames that carry a dataset's own boxes (CEPDOF/WEPDTOF `bbox`, as corners `gt_corners`) are scored
against those, as DESIGN.md asks: the IoU is that of the detection's corners with the file box's
corners. The radius-aligned scoring of the same frames is reported beside it, under the keys
`mAP_radius_aligned`, `AP50_radius_aligned`, `AP75_radius_aligned`, `precision_radius_aligned` and
`recall_radius_aligned` (only when some frame has file boxes; other frames are scored the same way in
both). A frame whose camera is assumed (`camera_assumed`) has no floor truth: its detections get no
floor distance and no localisation error from that camera.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fisheye import FisheyeCamera, cxcywh_to_corners, foot_points, polygon_iou, rotated_iou

FloatArray = NDArray[np.float64]
IOU_THRESHOLDS = np.round(np.arange(0.5, 0.951, 0.05), 2)
DISTANCE_BINS_M: dict[str, tuple[float, float]] = {
    "near": (0.0, 10.0), "mid": (10.0, 20.0), "far": (20.0, math.inf)}
RECALL_POINTS = np.linspace(0.0, 1.0, 101)
MAX_DETECTIONS = 100
NADIR_FRACTION = 0.2  # of the image circle's radius: people there are seen from above
RADIUS_ALIGNED = "_radius_aligned"  # key suffix of the radius-aligned scoring of file-box frames


@dataclass(frozen=True)
class EvalFrame:
    """Ground truth and detections of one frame, all boxes in frame px about `principal_point`.

    `gt_corners` (G, 4, 2) and `crowd_corners` (M, 4, 2) px, when given, are the dataset's own boxes
    of the same people and crowd boxes (what the frame is scored against); `camera_assumed` marks a
    camera that is no calibration, whose floor positions must not be taken for measurements."""

    gt_boxes: FloatArray  # (G, 4)
    gt_locations_m: FloatArray  # (G, 2), NaN when unknown
    gt_distances_m: FloatArray  # (G,), NaN when unknown
    det_boxes: FloatArray  # (D, 4)
    det_scores: FloatArray  # (D,)
    principal_point: tuple[float, float]
    camera: FisheyeCamera | None = None
    split: str = ""
    crowd_boxes: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    gt_corners: FloatArray | None = None  # (G, 4, 2)
    crowd_corners: FloatArray | None = None  # (M, 4, 2)
    camera_assumed: bool = False
    det_foot_px: FloatArray | None = None  # (D, 2): the model's foot points, when it predicts them
    min_score: float | None = None  # the threshold of the operating point its view runs at

    def __post_init__(self) -> None:
        g, d = len(self.gt_boxes), len(self.det_boxes)
        if (self.gt_boxes.shape != (g, 4) or self.gt_locations_m.shape != (g, 2)
                or self.gt_distances_m.shape != (g,) or self.det_boxes.shape != (d, 4)
                or self.det_scores.shape != (d,)):
            raise ValueError("EvalFrame arrays disagree in shape")
        if self.det_foot_px is not None and self.det_foot_px.shape != (d, 2):
            raise ValueError(f"EvalFrame det_foot_px {self.det_foot_px.shape} must be ({d}, 2)")
        if self.gt_corners is not None and self.gt_corners.shape != (g, 4, 2):
            raise ValueError(f"EvalFrame gt_corners {self.gt_corners.shape} must be ({g}, 4, 2)")
        m = len(self.crowd_boxes)
        if self.crowd_corners is not None and self.crowd_corners.shape != (m, 4, 2):
            raise ValueError(f"EvalFrame crowd_corners {self.crowd_corners.shape} must be ({m}, 4, 2)")

    @property
    def floor_camera(self) -> FisheyeCamera | None:
        """The camera whose floor positions count as measurements: None when it is assumed."""
        return None if self.camera_assumed else self.camera


@dataclass
class FrameMatch:
    """One frame's detections sorted by descending score (`order`), their IoU with the people
    `iou` (D, G) and their largest IoU with any crowd box `crowd_iou` (D,)."""

    order: NDArray[np.int64]
    iou: FloatArray
    crowd_iou: FloatArray

    def ignored(self, matched: NDArray[np.int64], threshold: float) -> NDArray[np.bool_]:
        """(D,) unmatched detections that sit on a crowd box."""
        return (matched < 0) & (self.crowd_iou >= threshold)


def greedy_match(iou: FloatArray, threshold: float, gt_ignore: NDArray[np.bool_] | None = None
                 ) -> NDArray[np.int64]:
    """(D, G) IoU of score-sorted detections -> (D,) matched GT index or -1 (COCO's greedy rule:
    each detection takes the unmatched, non-ignored GT of highest IoU ≥ threshold, falling back to
    an ignored GT only when no regular one fits)."""
    D, G = iou.shape
    ignore = np.zeros(G, dtype=bool) if gt_ignore is None else gt_ignore
    taken = np.zeros(G, dtype=bool)
    matched = np.full(D, -1, dtype=np.int64)
    for d in range(D):
        best, best_iou = -1, threshold - 1e-12
        for pass_ignored in (False, True):
            for g in range(G):
                if taken[g] or ignore[g] != pass_ignored or iou[d, g] < best_iou:
                    continue
                best, best_iou = g, iou[d, g]
            if best >= 0:
                break
        if best >= 0:
            matched[d] = best
            taken[best] = True
    return matched


def average_precision(scores: FloatArray, true_positive: NDArray[np.bool_], num_gt: int) -> float:
    """COCO 101-point interpolated AP; NaN when there is no ground truth."""
    if num_gt == 0:
        return float("nan")
    order = np.argsort(-scores, kind="stable")
    tp = true_positive[order].astype(np.float64)
    tp_cum, fp_cum = np.cumsum(tp), np.cumsum(1.0 - tp)
    recall = tp_cum / num_gt
    precision = tp_cum / np.maximum(tp_cum + fp_cum, np.finfo(np.float64).eps)
    envelope = np.maximum.accumulate(precision[::-1])[::-1] if len(precision) else precision
    index = np.searchsorted(recall, RECALL_POINTS, side="left")
    sampled = np.array([envelope[i] if i < len(envelope) else 0.0 for i in index])
    return float(sampled.mean())


def prepare_match(frame: EvalFrame, file_boxes: bool = True) -> FrameMatch:
    """Match data of a frame against its file boxes when it has them and `file_boxes` is set,
    else against its radius-aligned boxes."""
    order = np.argsort(-frame.det_scores, kind="stable")[:MAX_DETECTIONS]
    if file_boxes and frame.gt_corners is not None:
        det_corners = cxcywh_to_corners(frame.det_boxes[order], frame.principal_point)
        crowd_corners = (frame.crowd_corners if frame.crowd_corners is not None
                         else cxcywh_to_corners(frame.crowd_boxes, frame.principal_point))
        iou = polygon_iou(det_corners, frame.gt_corners)
        crowd = polygon_iou(det_corners, crowd_corners)
    else:
        iou = rotated_iou(frame.det_boxes[order], frame.gt_boxes, frame.principal_point)
        crowd = rotated_iou(frame.det_boxes[order], frame.crowd_boxes, frame.principal_point)
    crowd_iou = crowd.max(axis=1) if crowd.size else np.zeros(len(order))
    return FrameMatch(order=order, iou=iou.reshape(len(order), len(frame.gt_boxes)), crowd_iou=crowd_iou)


def _det_distances(frame: EvalFrame, order: NDArray[np.int64]) -> FloatArray:
    camera = frame.floor_camera
    if camera is None:
        return np.full(len(order), np.nan)
    feet = foot_points(frame.det_boxes[order], camera.principal_point)
    return camera.floor_positions(feet).distance_m


def _ap_at(frames: Sequence[EvalFrame], prepared: Sequence[FrameMatch], threshold: float,
           distance_range: tuple[float, float] | None = None) -> float:
    scores, positives, num_gt = [], [], 0
    for frame, match in zip(frames, prepared, strict=True):
        if distance_range is None:
            ignore = np.zeros(len(frame.gt_boxes), dtype=bool)
        else:
            low, high = distance_range
            d = frame.gt_distances_m
            ignore = ~((d >= low) & (d < high))  # unknown distances are ignored too
        matched = greedy_match(match.iou, threshold, ignore)
        keep = ~match.ignored(matched, threshold)
        keep[matched >= 0] = ~ignore[matched[matched >= 0]]
        if distance_range is not None:
            distances = _det_distances(frame, match.order)
            outside = ~((distances >= distance_range[0]) & (distances < distance_range[1]))
            keep &= ~((matched < 0) & outside)
        scores.append(frame.det_scores[match.order][keep])
        positives.append((matched >= 0)[keep])
        num_gt += int((~ignore).sum())
    if not scores:
        return float("nan")
    return average_precision(np.concatenate(scores), np.concatenate(positives), num_gt)


def _ap_summary(frames: Sequence[EvalFrame], prepared: Sequence[FrameMatch]) -> dict[str, float]:
    """`mAP` (IoU 0.50:0.05:0.95), `AP50` and `AP75` of matched frames, and `AP10`, `AP30`."""
    per_threshold = [_ap_at(frames, prepared, float(t)) for t in IOU_THRESHOLDS]
    return {"mAP": float(np.mean(per_threshold)), "AP50": per_threshold[0], "AP75": per_threshold[5],
            "AP10": _ap_at(frames, prepared, 0.1), "AP30": _ap_at(frames, prepared, 0.3)}


FOOT, BOX_SIDE, CENTRE = "foot", "box_side", "center"  # how a detection is placed on the floor
PLACEMENT_SUFFIX = {FOOT: "", BOX_SIDE: "_box_side", CENTRE: "_center"}  # of the PE keys


def placement_points(frame: EvalFrame, det_index: NDArray[np.int64], placement: str) -> FloatArray:
    """(M, 2) frame px where the detections `det_index` stand, by `placement` (FOOT falls back to
    the box side for a model without a foot output)."""
    boxes = frame.det_boxes[det_index]
    if placement == FOOT and frame.det_foot_px is not None:
        return frame.det_foot_px[det_index].reshape(-1, 2)
    if placement == CENTRE:
        return boxes[:, :2]
    return foot_points(boxes, frame.principal_point).reshape(-1, 2)


def _localisation_errors(frame: EvalFrame, match: FrameMatch
                         ) -> tuple[dict[str, FloatArray], FloatArray, FloatArray, NDArray[np.int64]]:
    """Errors (M,) m by each placement, GT distances (M,) m, detection scores (M,) and the people's
    indices (M,) in the frame of the IoU-0.5 matches with known positions; a match without a floor
    point by any placement is left out of every one."""
    camera = frame.floor_camera
    if camera is None:
        return ({p: np.zeros(0) for p in PLACEMENT_SUFFIX}, np.zeros(0), np.zeros(0),
                np.zeros(0, dtype=np.int64))
    matched = greedy_match(match.iou, 0.5)
    det_index = match.order[matched >= 0]
    gt_index = matched[matched >= 0]
    truth = frame.gt_locations_m[gt_index]
    errors = {p: np.linalg.norm(camera.pixels_to_floor(placement_points(frame, det_index, p)) - truth, axis=1)
              for p in PLACEMENT_SUFFIX}
    valid = np.all(np.isfinite(np.stack(list(errors.values()))), axis=0)
    return ({p: e[valid] for p, e in errors.items()}, frame.gt_distances_m[gt_index][valid],
            frame.det_scores[det_index][valid], gt_index[valid].astype(np.int64))


def _localisation(frames: Sequence[EvalFrame], prepared: Sequence[FrameMatch], min_score: float | None = None
                  ) -> tuple[FloatArray, dict[str, FloatArray], NDArray[np.bool_]]:
    """GT distance (M,) of every IoU-0.5 match with a floor point over the frames, its error (M,) m
    by each placement, and (M,) whether its detection scores at least `min_score` (None: each
    frame's own threshold; all False where a frame has neither)."""
    found = [_localisation_errors(f, m) for f, m in zip(frames, prepared, strict=True)]
    reported = [scores >= _threshold_or_inf(frame, min_score)
                for frame, (_, _, scores, _) in zip(frames, found, strict=True)]
    distances = np.concatenate([d for _, d, _, _ in found]) if found else np.zeros(0)
    return (distances, {p: np.concatenate([e[p] for e, _, _, _ in found]) if found else np.zeros(0)
                        for p in PLACEMENT_SUFFIX},
            np.concatenate(reported) if reported else np.zeros(0, dtype=bool))


PersonKey = tuple[int, int]  # (frame index in its set, person index in its frame)


def person_errors(frames: Sequence[EvalFrame]) -> dict[PersonKey, tuple[float, float]]:
    """Each person the `mPE` matches hold (IoU 0.5, a floor point), keyed by frame and person index:
    (foot error m, GT distance m). Two models' dictionaries on the same frames compare the feet of
    the people both found (`common_errors`)."""
    people: dict[PersonKey, tuple[float, float]] = {}
    for index, frame in enumerate(frames):
        errors, distances, _, gt_index = _localisation_errors(frame, prepare_match(frame))
        for person, error, distance in zip(gt_index, errors[FOOT], distances, strict=True):
            people[(index, int(person))] = (float(error), float(distance))
    return people


def common_errors(models: dict[str, dict[PersonKey, tuple[float, float]]]) -> dict[str, dict[str, float]]:
    """For each model (its `person_errors` on the same frames), the foot error over the people that
    every model matches: `mPE_common`, `PE_near_common`, ... by GT distance, and their count
    `PE_matches_common`. `mPE` averages over the people each model finds, so a model that finds
    more of the far people, whose feet are the hardest, scores a higher `mPE` with feet no worse
    than another's; over the same people the feet themselves are compared."""
    keys = sorted(set.intersection(*(set(people) for people in models.values()))) if models else []
    result: dict[str, dict[str, float]] = {}
    for name, people in models.items():
        errors = np.array([people[key][0] for key in keys], dtype=np.float64)
        distances = np.array([people[key][1] for key in keys], dtype=np.float64)
        figures = {"mPE_common": _mean(errors), "PE_matches_common": float(len(keys))}
        for bin_name, (low, high) in DISTANCE_BINS_M.items():
            figures[f"PE_{bin_name}_common"] = _mean(errors[(distances >= low) & (distances < high)])
        result[name] = figures
    return result


def _threshold_or_inf(frame: EvalFrame, min_score: float | None) -> float:
    """`frame_threshold`, or infinity for a frame that has none (no match of it counts as reported)."""
    return math.inf if min_score is None and frame.min_score is None else frame_threshold(frame, min_score)


def _mean(values: FloatArray) -> float:
    return float(values.mean()) if len(values) else float("nan")


def frame_threshold(frame: EvalFrame, min_score: float | None) -> float:
    """`min_score`, or where it is None the frame's own operating threshold."""
    if min_score is not None:
        return min_score
    if frame.min_score is None:
        raise ValueError("a frame without its own operating threshold needs a min_score")
    return frame.min_score


def precision_recall_at(frames: Sequence[EvalFrame], prepared: Sequence[FrameMatch], min_score: float | None
                        ) -> tuple[float, float]:
    """Precision and recall (IoU 0.5) at `min_score` (None: each frame's own threshold)."""
    true_pos = n_det = n_gt = 0
    for frame, match in zip(frames, prepared, strict=True):
        matched = greedy_match(match.iou, 0.5)
        threshold = frame_threshold(frame, min_score)
        above = (frame.det_scores[match.order] >= threshold) & ~match.ignored(matched, 0.5)
        true_pos += int((matched[above] >= 0).sum())
        n_det += int(above.sum())
        n_gt += len(frame.gt_boxes)
    precision = true_pos / n_det if n_det else float("nan")
    recall = true_pos / n_gt if n_gt else float("nan")
    return precision, recall


def nadir_recall(frames: Sequence[EvalFrame], prepared: Sequence[FrameMatch], min_score: float | None
                 ) -> float:
    """Recall at `min_score` (IoU 0.5; None: each frame's own threshold) of the people below the
    lens: box centre within NADIR_FRACTION of the image circle's radius, seen from above (frames of
    calibrated cameras; NaN when there are none)."""
    found = total = 0
    for frame, match in zip(frames, prepared, strict=True):
        if frame.camera is None or frame.camera_assumed or len(frame.gt_boxes) == 0:
            continue
        offset = frame.gt_boxes[:, :2] - np.asarray(frame.camera.principal_point)
        below = np.hypot(offset[:, 0], offset[:, 1]) < NADIR_FRACTION * frame.camera.image_circle_radius_px()
        matched = greedy_match(match.iou, 0.5)
        above = frame.det_scores[match.order] >= frame_threshold(frame, min_score)
        hit = np.zeros(len(frame.gt_boxes), dtype=bool)
        hit[matched[above & (matched >= 0)]] = True
        found += int((hit & below).sum())
        total += int(below.sum())
    return found / total if total else float("nan")


def pr_curve(frames: Sequence[EvalFrame]) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Precision, recall and score thresholds (each (D,)) at IoU 0.5 over all detections."""
    scores, positives, num_gt = [], [], 0
    for frame in frames:
        match = prepare_match(frame)
        matched = greedy_match(match.iou, 0.5)
        keep = ~match.ignored(matched, 0.5)
        scores.append(frame.det_scores[match.order][keep])
        positives.append(matched[keep] >= 0)
        num_gt += len(frame.gt_boxes)
    all_scores = np.concatenate(scores) if scores else np.zeros(0)
    order = np.argsort(-all_scores, kind="stable")
    tp = np.concatenate(positives)[order].astype(np.float64) if scores else np.zeros(0)
    tp_cum = np.cumsum(tp)
    precision = tp_cum / np.arange(1, len(tp) + 1)
    recall = tp_cum / max(num_gt, 1)
    return precision, recall, all_scores[order]


def compute_metrics(frames: Sequence[EvalFrame], min_score: float | None) -> dict[str, float]:
    """Every metric of the module docstring for one set of frames (NaN where undefined); precision
    and recall at `min_score`, or where it is None at each frame's own threshold (`min_score`)."""
    prepared = [prepare_match(frame) for frame in frames]
    result: dict[str, float] = _ap_summary(frames, prepared)
    for name, distance_range in DISTANCE_BINS_M.items():
        result[f"AP_{name}"] = _ap_at(frames, prepared, 0.5, distance_range)
    distances, by_placement, reported = _localisation(frames, prepared, min_score)
    result["mPE_reported"] = _mean(by_placement[FOOT][reported])
    result["PE_matches_reported"] = float(reported.sum())
    for placement, suffix in PLACEMENT_SUFFIX.items():
        errors = by_placement[placement]
        result[f"mPE{suffix}"] = _mean(errors)
        for name, (low, high) in DISTANCE_BINS_M.items():
            result[f"PE_{name}{suffix}"] = _mean(errors[(distances >= low) & (distances < high)])
        result[f"PE_matches{suffix}"] = float(len(errors))
    result["precision"], result["recall"] = precision_recall_at(frames, prepared, min_score)
    result["recall_nadir"] = nadir_recall(frames, prepared, min_score)
    result["num_frames"] = float(len(frames))
    result["num_gt"] = float(sum(len(f.gt_boxes) for f in frames))
    if any(frame.gt_corners is not None for frame in frames):
        aligned = [prepare_match(frame, file_boxes=False) for frame in frames]
        for key, value in _ap_summary(frames, aligned).items():
            result[f"{key}{RADIUS_ALIGNED}"] = value
        precision, recall = precision_recall_at(frames, aligned, min_score)
        result[f"precision{RADIUS_ALIGNED}"], result[f"recall{RADIUS_ALIGNED}"] = precision, recall
    return result


def localisation_points(frames: Sequence[EvalFrame]) -> tuple[FloatArray, dict[str, FloatArray]]:
    """GT distance (M,) of every IoU-0.5 match with a floor point, and its error (M,) m by each
    placement (FOOT, BOX_SIDE, CENTRE)."""
    distances, by_placement, _ = _localisation(frames, [prepare_match(frame) for frame in frames])
    return distances, by_placement
