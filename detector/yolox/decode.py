"""Raw YOLOX head maps -> the released ONNX's output layout, or boxes in input pixels.

Anchors are the cells of the strides 8, 16, 32 in that order, each level row-major, so a (B, 3,
H, W) input has A = sum over s of (H / s) (W / s) of them (3549 at 416 x 416). Grids are built from
the maps' shapes, never from a fixed input size, so this exports into an ONNX graph with dynamic
height and width.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from detector.yolox.foot import REFINE_MIN_SCORE, foot_from_offsets
from detector.yolox.head import CLASSES_START, OBJECTNESS
from detector.yolox.network import STRIDES, YoloxNano


def flatten_maps(maps: Sequence[Tensor]) -> Tensor:
    """[(B, K, h_i, w_i) per level] -> (B, A, K): the cells of each level row-major, levels in order."""
    return torch.cat([m.flatten(2).transpose(1, 2) for m in maps], dim=1)


def to_onnx_layout(maps: Sequence[Tensor]) -> Tensor:
    """Raw maps -> (B, A, 5 + C) exactly as the `output` of YOLOX's ONNX export: x, y offsets
    (cells) and log w, log h as predicted, then objectness and class probabilities (sigmoid)."""
    flat = flatten_maps(maps)  # (B, A, 5 + C)
    return torch.cat([flat[..., :OBJECTNESS], flat[..., OBJECTNESS:].sigmoid()], dim=-1)


def cell_grid(height: int, width: int, like: Tensor) -> Tensor:
    """(h * w, 2) `col, row` of every cell of an h x w map, row-major, in `like`'s dtype and device."""
    rows = torch.arange(height, dtype=like.dtype, device=like.device)
    cols = torch.arange(width, dtype=like.dtype, device=like.device)
    grid_rows, grid_cols = torch.meshgrid(rows, cols, indexing="ij")  # (h, w) each
    return torch.stack([grid_cols, grid_rows], dim=-1).reshape(-1, 2)


def decode(maps: Sequence[Tensor], strides: Sequence[int] = STRIDES) -> Tensor:
    """Raw maps -> (B, A, 5 + C): box `cxcywh` in input px, objectness, class probabilities.

    cx, cy = (offset + cell) x stride; w, h = exp(log size) x stride (YOLOX's decode_outputs).
    """
    levels: list[Tensor] = []
    for m, stride in zip(maps, strides, strict=True):
        _, _, h, w = m.shape  # (B, 5 + C, h, w)
        flat = m.flatten(2).transpose(1, 2)  # (B, h w, 5 + C)
        centre_xy = (flat[..., 0:2] + cell_grid(h, w, m)) * stride  # (B, h w, 2) px
        size_wh = flat[..., 2:4].exp() * stride  # (B, h w, 2) px
        probabilities = flat[..., OBJECTNESS:].sigmoid()  # (B, h w, 1 + C)
        levels.append(torch.cat([centre_xy, size_wh, probabilities], dim=-1))
    return torch.cat(levels, dim=1)  # (B, A, 5 + C)


def class_scores(decoded: Tensor) -> Tensor:
    """(B, A, 5 + C) decoded (or ONNX-layout) rows -> (B, A, C) objectness x class probability."""
    return decoded[..., OBJECTNESS:CLASSES_START] * decoded[..., CLASSES_START:]


def peak_cells(maps: Sequence[Tensor]) -> Tensor:
    """Raw maps -> (B, A) bool: the cells whose person score is the highest of their 3 x 3
    neighbourhood on their own level (CenterNet's max-pool peaks).

    A person lights up a blob of cells on each level; keeping one per blob before the top K lets
    the K slots hold K people's candidates instead of the strongest few people's neighbours.
    """
    peaks: list[Tensor] = []
    for m in maps:
        score = m[:, OBJECTNESS:OBJECTNESS + 1].sigmoid() * m[:, CLASSES_START:CLASSES_START + 1].sigmoid()
        peaks.append(score >= nn.functional.max_pool2d(score, 3, stride=1, padding=1))  # (B, 1, h, w)
    return flatten_maps(peaks)[..., 0]  # (B, A)


def top_people(net: nn.Module, image: Tensor, max_detections: int, peaks: bool = False,
               refine_min_score: float = REFINE_MIN_SCORE) -> tuple[Tensor, Tensor, Tensor | None]:
    """(N, H, W, 3) uint8 RGB images -> the `max_detections` cells of highest objectness x
    p(person) (with `peaks`, among the cells that are peaks of their level: `peak_cells`): boxes
    (N, K, 4) `cxcywh` in YOLOX's edge coordinates (pixel i spans [i, i + 1)), scores (N, K)
    descending and, for a network with a foot branch, their foot points (N, K, 2) in the same
    coordinates (else None), refined where they score `refine_min_score` or more
    (`FootHead.refine_scored`). What both views' ONNX graphs compute before their own box layout."""
    bgr = image.permute(0, 3, 1, 2).flip(1).float()  # (N, 3, H, W) BGR 0-255, as YOLOX was trained
    offsets: list[Tensor] | None = None
    if isinstance(net, YoloxNano) and net.foot is not None:
        maps, offsets, fine = net.forward_with_foot(bgr)
    else:
        maps = net(bgr)
    decoded = decode(maps)  # (N, A, 5 + C): cxcywh px, objectness, classes
    scores = class_scores(decoded)[..., 0]  # (N, A) person
    if peaks:
        scores = torch.where(peak_cells(maps), scores, torch.zeros_like(scores))
    k = min(max_detections, scores.shape[1])
    top_scores, top = torch.topk(scores, k, dim=1)  # (N, K)
    cxcywh = torch.gather(decoded[..., :4], 1, top[..., None].expand(-1, -1, 4))  # (N, K, 4)
    if offsets is None:
        return cxcywh, top_scores, None
    ab = torch.gather(flatten_maps(offsets), 1, top[..., None].expand(-1, -1, 2))  # (N, K, 2)
    assert isinstance(net, YoloxNano) and net.foot is not None
    coarse = foot_from_offsets(ab, cxcywh)
    return cxcywh, top_scores, net.foot.refine_scored(fine, coarse, top_scores, refine_min_score)
