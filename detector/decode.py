"""Dense head predictions -> radius-aligned boxes and scores (torch; exports into the ONNX graph).

Boxes are `cxcywh` in input pixels (pixel centres at integers); radius alignment is about the input
centre ((S - 1) / 2, (S - 1) / 2), the principal point of the letterboxed frame. Peaks are the cells
whose probability is the maximum of their 3x3 neighbourhood; the top K of them come out sorted by
score, descending.
"""

from __future__ import annotations

import torch
from torch import Tensor
from torch.nn import functional

from detector.model import (
    HEATMAP,
    LOG_H,
    LOG_W,
    OFFSET_RADIAL,
    OFFSET_TANGENTIAL,
    STRIDE,
    polar_channels,
)

# exp() of a log size is clamped to this range so that an untrained head never overflows.
_LOG_SIZE_RANGE = (-3.0, 9.0)


def dense_boxes(predictions: Tensor, input_size: int) -> Tensor:
    """(B, 5, h, w) head output -> (B, 4, h, w) box `cxcywh` (input px) predicted at every cell."""
    h, w = predictions.shape[2:]  # predictions: (B, 5, h, w)
    polar = polar_channels(h, w, input_size, predictions)  # (1, 3, h, w): cos φ, sin φ, radius
    cos_phi, sin_phi = polar[:, 0], polar[:, 1]  # (1, h, w)
    ys = torch.arange(h, dtype=predictions.dtype, device=predictions.device) * STRIDE + (STRIDE - 1) / 2
    xs = torch.arange(w, dtype=predictions.dtype, device=predictions.device) * STRIDE + (STRIDE - 1) / 2
    cell_y = ys[:, None].expand(h, w)[None]
    cell_x = xs[None, :].expand(h, w)[None]
    radial = predictions[:, OFFSET_RADIAL] * STRIDE  # (B, h, w) px along the ray
    tangential = predictions[:, OFFSET_TANGENTIAL] * STRIDE  # px across it (ray turned +90° on screen)
    cx = cell_x + radial * cos_phi - tangential * sin_phi
    cy = cell_y + radial * sin_phi + tangential * cos_phi
    box_w = torch.exp(torch.clamp(predictions[:, LOG_W], *_LOG_SIZE_RANGE))
    box_h = torch.exp(torch.clamp(predictions[:, LOG_H], *_LOG_SIZE_RANGE))
    return torch.stack([cx, cy, box_w, box_h], dim=1)  # (B, 4, h, w)


def peak_scores(predictions: Tensor) -> Tensor:
    """(B, 5, h, w) -> (B, h*w) person probability at local maxima, 0 elsewhere."""
    B = predictions.shape[0]
    heat = torch.sigmoid(predictions[:, HEATMAP:HEATMAP + 1])  # (B, 1, h, w)
    pooled = functional.max_pool2d(heat, kernel_size=3, stride=1, padding=1)
    peaks = heat * (heat >= pooled).to(heat.dtype)
    return peaks.reshape(B, -1)


def decode(predictions: Tensor, input_size: int, max_detections: int) -> tuple[Tensor, Tensor]:
    """(B, 5, h, w) head output -> boxes (B, K, 4) input px and scores (B, K), sorted descending."""
    B, _, h, w = predictions.shape  # (B, 5, h, w)
    k = min(max_detections, h * w)
    scores, index = torch.topk(peak_scores(predictions), k, dim=1)  # (B, K)
    boxes = dense_boxes(predictions, input_size).reshape(B, 4, h * w)
    picked = torch.gather(boxes, 2, index[:, None, :].expand(B, 4, k))  # (B, 4, K)
    return picked.permute(0, 2, 1), scores
