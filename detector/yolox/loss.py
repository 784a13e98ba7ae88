"""The fine-tuning loss of the polar YOLOX: YOLOX's detection terms plus distillation from the
frozen COCO network (learning without forgetting).

Label assignment (a centre prior, after YOLOX's geometry constraint, without SimOTA): a cell of
stride s, centre ((col + 0.5)·s, (row + 0.5)·s), is a positive of a label when

- its centre lies inside the label's box and within `centre_radius`·s of the box's centre on both axes,
- and the level fits the box: its longer side lies in `LEVEL_RANGES_PX[level]` (overlapping ranges,
  so a box at a boundary has positives on two levels).

A cell claimed by several labels goes to the smallest box. A label that gets no cell this way (a box
smaller than its stride) takes the cell nearest its centre on the finest level that fits it.

Terms, each summed and divided by the number of positives (as YOLOX does):
`iou` 1 − GIoU of the decoded boxes of positives, `objectness` BCE of every cell (1 at positives),
`class` BCE of the person logit at positives against the (detached) IoU of the prediction, and
`distill` the binary KL divergence KL(teacher ‖ student) of objectness·p(person) on every cell that
is not inside a label's box: zero exactly when the student scores every such cell as the frozen
COCO network does. For a network with a foot branch, `foot` is the metres-weighted L1 error of the
positives' foot points (`detector.yolox.foot.foot_loss`) divided by the positives that have a floor
point. `total` = iou_weight·iou + objectness + class + distill_weight·distill + foot_weight·foot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor
from torch.nn import functional

from detector.yolox.decode import cell_grid, flatten_maps
from detector.yolox.foot import MAX_METRES_PER_PX, FootHead, foot_loss
from detector.yolox.head import CLASSES_START, OBJECTNESS
from detector.yolox.network import STRIDES

LEVEL_RANGES_PX = ((0.0, 96.0), (48.0, 192.0), (96.0, float("inf")))  # longer box side per stride 8, 16, 32
EPS = 1e-7


@dataclass(frozen=True)
class PolarLossConfig:
    iou_weight: float = 5.0
    distill_weight: float = 1.0  # λ of the distillation term
    foot_weight: float = 1.0  # of the foot term (per metre of error)
    foot_max_metres_per_px: float = MAX_METRES_PER_PX  # where a person's foot weight stops (foot_loss)
    foot_coarse_weight: float = 1.0  # of the coarse point against each refiner pass (foot_loss)
    centre_radius: float = 2.5  # strides


@dataclass(frozen=True)
class Anchors:
    """Every cell of a strip's maps, levels in order: `centres_xy` (A, 2) px, `strides` (A,),
    `levels` (A,), `cells_xy` (A, 2) col, row."""

    centres_xy: Tensor
    strides: Tensor
    levels: Tensor
    cells_xy: Tensor


def anchors_of(maps: Sequence[Tensor], strides_of_levels: Sequence[int] = STRIDES,
               centre_offset: float = 0.5) -> Anchors:
    """The cells of `maps` (one per level of `strides_of_levels`); a cell's centre is (col, row) +
    `centre_offset`, times its stride (YOLOX: half a cell; NanoDet: none)."""
    centres, strides, levels, cells = [], [], [], []
    for level, (m, stride) in enumerate(zip(maps, strides_of_levels, strict=True)):
        _, _, h, w = m.shape
        grid = cell_grid(h, w, m)  # (h w, 2)
        cells.append(grid)
        centres.append((grid + centre_offset) * stride)
        strides.append(torch.full((h * w,), float(stride), dtype=m.dtype, device=m.device))
        levels.append(torch.full((h * w,), level, dtype=torch.long, device=m.device))
    return Anchors(torch.cat(centres), torch.cat(strides), torch.cat(levels), torch.cat(cells))


def assign(anchors: Anchors, labels_xyxy: Tensor, centre_radius: float,
           level_ranges_px: Sequence[tuple[float, float]] = LEVEL_RANGES_PX) -> Tensor:
    """(A,) index of the label each cell is a positive of, −1 for negatives (module docstring);
    `level_ranges_px` the longer box sides each level takes."""
    count = len(anchors.strides)
    if len(labels_xyxy) == 0:
        return torch.full((count,), -1, dtype=torch.long, device=anchors.strides.device)
    x, y = anchors.centres_xy[:, 0:1], anchors.centres_xy[:, 1:2]  # (A, 1)
    x1, y1, x2, y2 = labels_xyxy.T[:, None, :].unbind(0)  # (1, G) each
    inside = (x > x1) & (x < x2) & (y > y1) & (y < y2)  # (A, G)
    radius = centre_radius * anchors.strides[:, None]
    near = ((x - (x1 + x2) / 2).abs() < radius) & ((y - (y1 + y2) / 2).abs() < radius)
    longer = torch.maximum(x2 - x1, y2 - y1)  # (1, G)
    ranges = torch.tensor(level_ranges_px, dtype=labels_xyxy.dtype, device=labels_xyxy.device)
    low, high = ranges[anchors.levels, 0:1], ranges[anchors.levels, 1:2]  # (A, 1)
    fits = (longer >= low) & (longer < high)  # (A, G)
    candidate = inside & near & fits
    # Labels without a cell: the cell nearest their centre on the finest fitting level.
    orphans = ~candidate.any(dim=0)
    if orphans.any():
        distance = (x - (x1 + x2) / 2) ** 2 + (y - (y1 + y2) / 2) ** 2  # (A, G)
        penalty = anchors.levels[:, None].to(distance.dtype) * 1e12  # finer levels first
        distance = torch.where(fits, distance + penalty, torch.full_like(distance, float("inf")))
        nearest = distance.argmin(dim=0)  # (G,)
        orphan_index = orphans.nonzero().squeeze(1)
        candidate[nearest[orphan_index], orphan_index] = True
    area = ((x2 - x1) * (y2 - y1)).expand_as(candidate)
    area = torch.where(candidate, area, torch.full_like(area, float("inf")))
    best_area, best = area.min(dim=1)  # (A,)
    return torch.where(torch.isfinite(best_area), best, torch.full_like(best, -1))


def decode_boxes(flat: Tensor, anchors: Anchors) -> Tensor:
    """(B, A, 5 + C) raw rows -> (B, A, 4) xyxy px (YOLOX's decode)."""
    centre = (flat[..., 0:2] + anchors.cells_xy) * anchors.strides[:, None]
    half = flat[..., 2:4].clamp(max=12.0).exp() * anchors.strides[:, None] / 2
    return torch.cat([centre - half, centre + half], dim=-1)


def giou(boxes_a: Tensor, boxes_b: Tensor) -> tuple[Tensor, Tensor]:
    """(N, 4) xyxy pairs -> IoU (N,) and generalised IoU (N,)."""
    top_left = torch.maximum(boxes_a[:, :2], boxes_b[:, :2])
    bottom_right = torch.minimum(boxes_a[:, 2:], boxes_b[:, 2:])
    overlap = (bottom_right - top_left).clamp(min=0).prod(dim=1)
    area_a = (boxes_a[:, 2:] - boxes_a[:, :2]).clamp(min=0).prod(dim=1)
    area_b = (boxes_b[:, 2:] - boxes_b[:, :2]).clamp(min=0).prod(dim=1)
    union = area_a + area_b - overlap + EPS
    iou = overlap / union
    hull = (torch.maximum(boxes_a[:, 2:], boxes_b[:, 2:]) - torch.minimum(boxes_a[:, :2], boxes_b[:, :2]))
    hull_area = hull.clamp(min=0).prod(dim=1) + EPS
    return iou, iou - (hull_area - union) / hull_area


def person_log_probs(flat: Tensor) -> tuple[Tensor, Tensor]:
    """(..., 5 + C) raw rows -> log p and log(1 − p) of p = objectness · p(person), stably."""
    log_p = functional.logsigmoid(flat[..., OBJECTNESS]) + functional.logsigmoid(flat[..., CLASSES_START])
    log_not_p = torch.log(-torch.expm1(log_p.clamp(max=-EPS)))
    return log_p, log_not_p


def feature_distillation(student: Sequence[Tensor], teacher: Sequence[Tensor]) -> Tensor:
    """Feature pyramids held to the teacher's (`--distill-features`): per level, the mean
    squared difference over the teacher's mean square, averaged over the levels. Zero exactly where
    the student's pyramid is the teacher's; a level's scale does not weigh it; 1 for a student whose
    features are all zero."""
    if len(student) != len(teacher) or not student:
        raise ValueError(f"feature distillation needs the same levels, got {len(student)} and {len(teacher)}")
    terms = [functional.mse_loss(s, t.detach()) / (t.detach().square().mean() + EPS)
             for s, t in zip(student, teacher, strict=True)]
    return torch.stack(terms).mean()


def binary_kl(teacher: Tensor, student: Tensor) -> Tensor:
    """Element-wise KL(Bernoulli(p_t) ‖ Bernoulli(p_s)) of raw rows (teacher's, student's)."""
    log_t, log_not_t = person_log_probs(teacher)
    log_s, log_not_s = person_log_probs(student)
    p_t = log_t.exp()
    return p_t * (log_t - log_s) + (1 - p_t) * (log_not_t - log_not_s)


class PolarDetectionLoss:
    """(student maps, teacher maps or None, labels) -> named terms (module docstring)."""

    def __init__(self, config: PolarLossConfig | None = None) -> None:
        self.config = config or PolarLossConfig()

    def __call__(self, maps: Sequence[Tensor], labels_xyxy: Sequence[Tensor],
                 teacher_maps: Sequence[Tensor] | None = None, foot_offsets: Sequence[Tensor] | None = None,
                 feet: Sequence[Tensor] | None = None,
                 refine: tuple[Tensor, FootHead] | None = None) -> dict[str, Tensor]:
        """`foot_offsets` the foot branch's maps and `feet` (N_i, 3) per image (targets of
        `detector.yolox.foot.foot_loss`) add the `foot` term; both or neither."""
        if (foot_offsets is None) != (feet is None):
            raise ValueError("the foot term needs both the foot maps and the feet")
        flat = flatten_maps(maps)  # (B, A, 5 + C)
        offsets = None if foot_offsets is None else flatten_maps(foot_offsets)  # (B, A, 2)
        B, A, _ = flat.shape
        anchors = anchors_of(maps)
        boxes = decode_boxes(flat, anchors)  # (B, A, 4)
        objectness_target = torch.zeros(B, A, dtype=flat.dtype, device=flat.device)
        distill_mask = torch.ones(B, A, dtype=torch.bool, device=flat.device)
        iou_sum = flat.new_zeros(())
        class_sum = flat.new_zeros(())
        foot_sum = flat.new_zeros(())
        positives = foot_count = 0
        for b, labels in enumerate(labels_xyxy):
            labels = labels.to(flat.device, flat.dtype)
            owner = assign(anchors, labels, self.config.centre_radius)  # (A,)
            fg = owner >= 0
            if len(labels):
                x, y = anchors.centres_xy[:, 0:1], anchors.centres_xy[:, 1:2]
                x1, y1, x2, y2 = labels.T[:, None, :].unbind(0)
                in_any = ((x > x1) & (x < x2) & (y > y1) & (y < y2)).any(dim=1)
                distill_mask[b] = ~(in_any | fg)
            count = int(fg.sum())
            if count == 0:
                continue
            positives += count
            objectness_target[b, fg] = 1.0
            iou, generalised = giou(boxes[b, fg], labels[owner[fg]])
            iou_sum = iou_sum + (1.0 - generalised).sum()
            class_target = iou.detach().clamp(min=0.0)
            class_sum = class_sum + functional.binary_cross_entropy_with_logits(
                flat[b, fg, CLASSES_START], class_target, reduction="sum")
            if offsets is not None and feet is not None:
                targets = feet[b].to(flat.device, flat.dtype)[owner[fg]]  # (P, 3)
                image_refine = None if refine is None else (refine[0][b:b + 1], refine[1])
                image_sum, image_count = foot_loss(offsets[b, fg], boxes[b, fg], targets, image_refine,
                                                   self.config.foot_max_metres_per_px,
                                                   self.config.foot_coarse_weight)
                foot_sum, foot_count = foot_sum + image_sum, foot_count + image_count
        norm = float(max(positives, 1))
        objectness = functional.binary_cross_entropy_with_logits(flat[..., OBJECTNESS], objectness_target,
                                                        reduction="sum") / norm
        if teacher_maps is not None:
            teacher = flatten_maps(teacher_maps).detach()
            distill = (binary_kl(teacher, flat) * distill_mask).sum() / norm
        else:
            distill = flat.new_zeros(())
        terms = {"iou": iou_sum / norm, "objectness": objectness, "class": class_sum / norm,
                 "distill": distill, "foot": foot_sum / float(max(foot_count, 1))}
        terms["total"] = (self.config.iou_weight * terms["iou"] + terms["objectness"] + terms["class"]
                          + self.config.distill_weight * terms["distill"]
                          + self.config.foot_weight * terms["foot"])
        return terms
