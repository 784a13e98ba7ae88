"""Raw NanoDet-Plus head maps -> person boxes in input pixels and the top K of them.

Cells are those of the strides 8, 16, 32, 64 in that order, each level row-major. NanoDet places a
cell's centre at (col, row) x stride (no half-cell offset) and predicts each side's distance from
it as a distribution over 0 .. 7 strides. Grids come from the maps' shapes, so the graph exports
with dynamic height and width.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor, nn

from detector.nanodet.head import distances
from detector.nanodet.network import STRIDES, NanoDetPlus
from detector.yolox.decode import cell_grid, flatten_maps


def decode(maps: Sequence[Tensor], num_classes: int, strides: Sequence[int] = STRIDES) -> Tensor:
    """Raw maps -> (B, A, 4 + C): box `cxcywh` in input px (edge coordinates: pixel i spans
    [i, i + 1)), then class probabilities (sigmoid)."""
    levels: list[Tensor] = []
    for m, stride in zip(maps, strides, strict=True):
        _, _, h, w = m.shape  # (B, C + 32, h, w)
        flat = m.flatten(2).transpose(1, 2)  # (B, h w, C + 32)
        ltrb = distances(flat[..., num_classes:]) * stride  # (B, h w, 4) px
        centre = cell_grid(h, w, m) * stride  # (h w, 2) px
        top_left, bottom_right = centre - ltrb[..., :2], centre + ltrb[..., 2:]
        cxcywh = torch.cat([(top_left + bottom_right) / 2, bottom_right - top_left], dim=-1)
        levels.append(torch.cat([cxcywh, flat[..., :num_classes].sigmoid()], dim=-1))
    return torch.cat(levels, dim=1)  # (B, A, 4 + C)


def peak_cells(maps: Sequence[Tensor]) -> Tensor:
    """Raw maps -> (B, A) bool: the cells whose person probability is the highest of their 3 x 3
    neighbourhood on their own level (as `detector.yolox.decode.peak_cells`)."""
    peaks: list[Tensor] = []
    for m in maps:
        score = m[:, :1].sigmoid()  # (B, 1, h, w) person
        peaks.append(score >= nn.functional.max_pool2d(score, 3, stride=1, padding=1))
    return flatten_maps(peaks)[..., 0]  # (B, A)


def top_people(net: NanoDetPlus, image: Tensor, max_detections: int, peaks: bool = False
               ) -> tuple[Tensor, Tensor]:
    """(N, H, W, 3) uint8 RGB images -> the `max_detections` cells of highest p(person) (with
    `peaks`, among peak cells only): boxes (N, K, 4) `cxcywh` in edge coordinates and scores (N, K)
    descending; what `detector.yolox.decode.top_people` gives for YOLOX (NanoDet has no foot)."""
    bgr = image.permute(0, 3, 1, 2).flip(1).float()  # (N, 3, H, W) BGR 0-255
    maps = net(bgr)
    decoded = decode(maps, net.config.num_classes)  # (N, A, 4 + C)
    scores = decoded[..., 4]  # (N, A) person: the first class
    if peaks:
        scores = torch.where(peak_cells(maps), scores, torch.zeros_like(scores))
    k = min(max_detections, scores.shape[1])
    top_scores, top = torch.topk(scores, k, dim=1)  # (N, K)
    cxcywh = torch.gather(decoded[..., :4], 1, top[..., None].expand(-1, -1, 4))  # (N, K, 4)
    return cxcywh, top_scores
