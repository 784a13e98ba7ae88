"""The fine-tuning loss of the polar NanoDet-Plus: its own detection terms (generalised focal loss)
plus distillation from the frozen COCO network, as `detector.yolox.loss` is for YOLOX.

Label assignment is YOLOX's centre prior (`detector.yolox.loss.assign`) on NanoDet's four levels:
a cell (centre (col, row)·s, NanoDet's convention) is a positive of a label when its centre lies
inside the box, within `centre_radius`·s of the box's centre on both axes, and the box's longer
side lies in the level's range of `LEVEL_RANGES_PX`; a label with no such cell takes the nearest one
on the finest level that fits it. (NanoDet-Plus trains with a dynamic assigner guided by an
auxiliary head; the fixed prior needs no second head and keeps both networks' training alike.)

Terms, each summed and divided by the number of positives:
`quality` quality focal loss (Li et al., NeurIPS 2020) of the person logit on every cell against the
(detached) IoU of the cell's box at positives and 0 elsewhere; `iou` 1 − GIoU of the positives'
decoded boxes; `dfl` distribution focal loss of each side's distance bins at positives (the two bins
around the true distance, weighted by nearness); `distill` the binary KL divergence KL(teacher ‖
student) of p(person) on every cell not inside a label's box. `total` = quality + iou_weight·iou
+ dfl_weight·dfl + distill_weight·distill (NanoDet's weights: 1, 2, 0.25).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor
from torch.nn import functional

from detector.nanodet.head import BINS, distances
from detector.nanodet.network import STRIDES
from detector.yolox.decode import flatten_maps
from detector.yolox.loss import anchors_of, assign, giou

LEVEL_RANGES_PX = ((0.0, 64.0), (32.0, 128.0), (64.0, 256.0), (128.0, float("inf")))  # per stride 8..64


@dataclass(frozen=True)
class NanoDetLossConfig:
    iou_weight: float = 2.0
    dfl_weight: float = 0.25
    distill_weight: float = 1.0  # λ of the distillation term
    centre_radius: float = 2.5  # strides
    quality_beta: float = 2.0


def quality_focal(logits: Tensor, targets: Tensor, beta: float) -> Tensor:
    """Element-wise QFL of logits against soft targets in [0, 1]: BCE scaled by |σ(x) − t|^β."""
    scale = (logits.sigmoid() - targets).abs().pow(beta)
    return functional.binary_cross_entropy_with_logits(logits, targets, reduction="none") * scale


def distribution_focal(bin_logits: Tensor, target: Tensor) -> Tensor:
    """(P, 4, BINS) logits, (P, 4) distances in bins -> (P, 4) DFL: cross-entropy with the two bins
    around each distance, weighted by how near the distance lies to each."""
    target = target.clamp(0.0, BINS - 1 - 0.01)
    left = target.floor().long()
    right_weight = target - left.to(target.dtype)
    log_p = bin_logits.log_softmax(dim=-1)  # (P, 4, BINS)
    at_left = log_p.gather(-1, left[..., None])[..., 0]
    at_right = log_p.gather(-1, (left + 1)[..., None])[..., 0]
    return -(at_left * (1.0 - right_weight) + at_right * right_weight)


def binary_kl_logits(teacher: Tensor, student: Tensor) -> Tensor:
    """Element-wise KL(Bernoulli(σ(t)) ‖ Bernoulli(σ(s))) of person logits."""
    p_t = teacher.sigmoid()
    log_t, log_not_t = functional.logsigmoid(teacher), functional.logsigmoid(-teacher)
    log_s, log_not_s = functional.logsigmoid(student), functional.logsigmoid(-student)
    return p_t * (log_t - log_s) + (1 - p_t) * (log_not_t - log_not_s)


class NanoDetDetectionLoss:
    """(student maps, labels xyxy strip px per image, teacher maps or None) -> named terms."""

    def __init__(self, config: NanoDetLossConfig | None = None) -> None:
        self.config = config or NanoDetLossConfig()

    def __call__(self, maps: Sequence[Tensor], labels_xyxy: Sequence[Tensor],
                 teacher_maps: Sequence[Tensor] | None = None) -> dict[str, Tensor]:
        flat = flatten_maps(maps)  # (B, A, 1 + 4 * BINS)
        B, A, channels = flat.shape
        if channels != 1 + 4 * BINS:
            raise ValueError(f"maps of {channels} channels: the loss trains a person-only NanoDet "
                             f"(1 + {4 * BINS})")
        anchors = anchors_of(maps, STRIDES, centre_offset=0.0)
        strides = anchors.strides[:, None]  # (A, 1)
        ltrb = distances(flat[..., 1:]) * strides  # (B, A, 4) px
        boxes = torch.cat([anchors.centres_xy - ltrb[..., :2], anchors.centres_xy + ltrb[..., 2:]], dim=-1)
        quality_target = torch.zeros(B, A, dtype=flat.dtype, device=flat.device)
        distill_mask = torch.ones(B, A, dtype=torch.bool, device=flat.device)
        iou_sum, dfl_sum = flat.new_zeros(()), flat.new_zeros(())
        positives = 0
        for b, labels in enumerate(labels_xyxy):
            labels = labels.to(flat.device, flat.dtype)
            owner = assign(anchors, labels, self.config.centre_radius, LEVEL_RANGES_PX)  # (A,)
            fg = owner >= 0
            if len(labels):
                x, y = anchors.centres_xy[:, 0:1], anchors.centres_xy[:, 1:2]
                x1, y1, x2, y2 = labels.T[:, None, :].unbind(0)
                in_any = ((x >= x1) & (x <= x2) & (y >= y1) & (y <= y2)).any(dim=1)
                distill_mask[b] = ~(in_any | fg)
            count = int(fg.sum())
            if count == 0:
                continue
            positives += count
            targets = labels[owner[fg]]  # (P, 4) xyxy
            iou, generalised = giou(boxes[b, fg], targets)
            iou_sum = iou_sum + (1.0 - generalised).sum()
            quality_target[b, fg] = iou.detach().clamp(min=0.0)
            centres = anchors.centres_xy[fg]
            true_ltrb = torch.cat([centres - targets[:, :2], targets[:, 2:] - centres], dim=1) / strides[fg]
            bins = flat[b, fg, 1:].unflatten(-1, (4, BINS))  # (P, 4, BINS)
            dfl_sum = dfl_sum + distribution_focal(bins, true_ltrb).mean(dim=1).sum()
        norm = float(max(positives, 1))
        quality = quality_focal(flat[..., 0], quality_target, self.config.quality_beta).sum() / norm
        if teacher_maps is not None:
            teacher = flatten_maps(teacher_maps).detach()[..., 0]
            distill = (binary_kl_logits(teacher, flat[..., 0]) * distill_mask).sum() / norm
        else:
            distill = flat.new_zeros(())
        terms = {"quality": quality, "iou": iou_sum / norm, "dfl": dfl_sum / norm, "distill": distill}
        config = self.config
        terms["total"] = (quality + config.iou_weight * terms["iou"] + config.dfl_weight * terms["dfl"]
                          + config.distill_weight * distill)
        return terms
