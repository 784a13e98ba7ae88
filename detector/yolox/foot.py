"""Where the feet touch the floor: a third branch of the YOLOX head (polar view).

The box-side foot point (the middle of a box's side nearest the principal point) is the edge of the
visible silhouette, not the feet: shoulders, a leaning torso, a chair. A network with
`YoloxConfig.foot` has a third branch beside the class and box branches of its head: two 3x3
convolutions on the level's stem output (started as a copy of the box branch, so it starts from
features that already find a person's extent) and a 1x1 prediction. Each cell predicts the contact
point as two offsets from its own box, in box sizes:

    foot_x = cx + a · w,    foot_y = y2 + b · h        (strip px, xyxy box, y2 the bottom side)

In the polar strip the bottom side is the one nearest the principal point (radius grows upwards),
so `a = b = 0` is exactly the box-side foot point; the branch's last convolution starts at zero, so
an untrained branch answers what the box side answers.

Two later parts read finer or better-suited features: `FootRefiner` corrects each coarse point from
the stride-8 features sampled about it, and `FootNeck` gives the branch its own copy of the neck
and stems, so that the features it reads learn for the foot while the detector's, which the boxes
read, stay frozen (the frozen features were learnt for boxes: on them the branch fitted the
training renders no better than the validation ones).

Training targets come from the renders' `location_m`, projected into the frame by the camera and
into the strip by the polar grid (`strip_feet`). The loss is L1 in strip pixels times the metres
one strip row spans at the target (`metres_per_px`), so far people, with few pixels per metre,
count in metres, not pixels. The weight stops at `MAX_METRES_PER_PX` (by default; `fishloc train
--foot-metres-cap` sets it): near the horizon one row spans half a metre and more, where a person's
feet are a pixel or two and their error is mostly noise no offset can learn; uncapped, those few
people outweighed the near ones twenty to one and the near band, where most people stand, hardly
learnt (measured: docs/DETECTOR.md, "Foot point").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor, nn

from detector.yolox.blocks import conv_block
from fisheye import FisheyeCamera
from fisheye.polar import PolarGrid

FloatArray = NDArray[np.float64]
FOOT_CHANNELS = 2  # a, b of the module docstring
MAX_METRES_PER_PX = 0.1  # cap of the loss weight (module docstring)
REFINE_STRIDE = 8  # the refiner reads the finest level's stem output
REFINE_SIDE = 5  # samples per side of the patch it reads about a coarse foot point
REFINE_STEP_PX = 4.0  # strip px between two samples (half a stride-8 cell)
REFINE_SCALE_PX = 8.0  # strip px per unit of its output
# Candidates scoring below this keep their coarse foot point in the contract graph (`refine_scored`):
# the lowest score evaluation counts (detector.evaluate.EVAL_MIN_SCORE) and far below any operating
# threshold, so every detection a figure or a user sees at those scores is refined.
REFINE_MIN_SCORE = 0.05


class FootNeck(nn.Module):
    """The foot's own copy of the neck and the head's stems: backbone features (strides 8, 16,
    32) -> (B, width, h_i, w_i) per level, what the foot branch reads in place of the head's stem
    outputs. The detector's features were learnt for boxes and stay frozen so that its boxes stay
    the shipped ones; this copy, started from them, learns for the foot loss alone."""

    def __init__(self, neck: nn.Module, stems: nn.ModuleList) -> None:
        super().__init__()
        self.neck = neck
        self.stems = stems

    def forward(self, features: Sequence[Tensor]) -> list[Tensor]:
        return [stem(x) for x, stem in zip(self.neck(features), self.stems, strict=True)]


class FootHead(nn.Module):
    """The head's stem outputs of the 3 levels (B, width, h_i, w_i) -> offsets (B, 2, h_i, w_i);
    with a `FootNeck` (`features`), that neck's outputs in their place."""

    def __init__(self, width: int, levels: int, depthwise: bool, refine: bool = False,
                 refine_steps: int = 1, features: FootNeck | None = None) -> None:
        super().__init__()
        self.features = features
        self.refiner = FootRefiner(width) if refine else None
        self.refine_steps = refine_steps
        self.convs = nn.ModuleList([nn.Sequential(conv_block(width, width, 3, 1, depthwise),
                                                  conv_block(width, width, 3, 1, depthwise))
                                    for _ in range(levels)])
        self.preds = nn.ModuleList([nn.Conv2d(width, FOOT_CHANNELS, 1) for _ in range(levels)])
        for pred in self.preds:
            assert isinstance(pred, nn.Conv2d) and pred.bias is not None
            nn.init.zeros_(pred.weight)
            nn.init.zeros_(pred.bias)

    def forward(self, stem_features: Sequence[Tensor]) -> list[Tensor]:
        return [pred(conv(x)) for x, conv, pred in zip(stem_features, self.convs, self.preds, strict=True)]

    def passes(self, fine_features: Tensor, points: Tensor) -> list[Tensor]:
        """(B, K, 2) coarse foot points and the (B, width, H/8, W/8) features the refiner reads ->
        the points after each of its `refine_steps` passes, each about the previous answer (none
        without a refiner)."""
        passes: list[Tensor] = []
        for _ in range(self.refine_steps if self.refiner is not None else 0):
            assert self.refiner is not None
            points = self.refiner(fine_features, points)
            passes.append(points)
        return passes

    def refine(self, fine_features: Tensor, points: Tensor) -> Tensor:
        """(B, K, 2) coarse foot points -> the last pass's (the same points without a refiner)."""
        passes = self.passes(fine_features, points)
        return passes[-1] if passes else points

    def refine_scored(self, fine_features: Tensor, points: Tensor, scores: Tensor,
                      min_score: float = REFINE_MIN_SCORE) -> Tensor:
        """`refine` of the (B, K, 2) coarse points of the candidates whose (B, K) `scores`,
        descending, reach `min_score`; the others keep their coarse point.

        The graph's top K (300) are mostly cells no threshold keeps: 20-40 of them score 0.05 or
        more on a render, at most about 120. The refiner samples 25 points about each candidate and
        runs its MLP on them, so refining the scored prefix alone saves most of its time
        (docs/DETECTOR.md, "A faster graph"). The prefix has one length for the batch, the longest
        image's: another image's lower candidates within it are refined too, as `refine` would."""
        count = int((scores >= min_score).sum(dim=1).max().item()) if scores.numel() else 0
        torch._check(count >= 0)  # a data-dependent length in the exported graph
        torch._check(count <= points.shape[1])
        return torch.cat([self.refine(fine_features, points[:, :count]), points[:, count:]], dim=1)


class FootRefiner(nn.Module):
    """A second stage: the finest level's stem output (B, width, H/8, W/8) sampled on a
    `REFINE_SIDE`² patch about each coarse foot point (B, K, 2) px -> a correction of that point.

    The coarse point comes from a cell of the level that owns the person, for a near person a
    stride-32 cell whose regression is a few pixels coarse; the patch reads the stride-8 features
    at the point itself (bilinear: `sample_bilinear`). Its last layer starts at zero: an untrained
    refiner returns the coarse point."""

    def __init__(self, width: int, hidden: int = 128) -> None:
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(width * REFINE_SIDE ** 2, hidden), nn.SiLU(), nn.Linear(hidden, 2))
        last = self.mlp[-1]
        assert isinstance(last, nn.Linear)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        ticks = (torch.arange(REFINE_SIDE, dtype=torch.float32) - (REFINE_SIDE - 1) / 2) * REFINE_STEP_PX
        rows, cols = torch.meshgrid(ticks, ticks, indexing="ij")
        self.register_buffer("pattern", torch.stack([cols, rows], dim=-1).reshape(-1, 2), persistent=False)

    def patches(self, fine_features: Tensor, points: Tensor) -> Tensor:
        """(B, C, h, w) stride-8 features, (B, K, 2) px points -> (B, K, C, S²) samples about them."""
        pattern = self.get_buffer("pattern")  # (S², 2) px about the point
        where = points[:, :, None, :] + pattern  # (B, K, S², 2) px, YOLOX edge coordinates
        return sample_bilinear(fine_features, where, REFINE_STRIDE).transpose(2, 3)

    def forward(self, fine_features: Tensor, points: Tensor) -> Tensor:
        batch, count = points.shape[:2]
        samples = fine_features.shape[1] * REFINE_SIDE ** 2  # named: K may be 0 (`refine_scored`)
        flat = self.patches(fine_features, points).reshape(batch, count, samples)  # (B, K, C S²)
        return points + self.mlp(flat) * REFINE_SCALE_PX


def sample_bilinear(features: Tensor, points: Tensor, stride: int) -> Tensor:
    """(B, C, h, w) features of a level of `stride`, (B, K, S, 2) points (x, y) in input px (YOLOX
    edge coordinates: cell i spans [i s, (i + 1) s), its value at its centre) -> (B, K, S, C), each
    the bilinear mix of the four cells about the point; past the map's last centres a point reads
    its border (`grid_sample(..., padding_mode="border", align_corners=False)`, the same numbers).

    Four row gathers from the features laid out (B h w, C): onnxruntime runs them 2.5-3x faster
    than its GridSample, which recomputes each point's weights for every channel (measured at
    300 x 25 points of 64 channels: 2.3 against 7.4 ms)."""
    batch, channels, height, width = features.shape
    # Sizes as tensors, so that an export of any height and width keeps them symbolic.
    one = points.new_ones(())
    last_x, last_y, row = one * (width - 1), one * (height - 1), one * width
    x = (points[..., 0] / stride - 0.5).clamp(min=0.0 * one, max=last_x)  # cell index, centres at integers
    y = (points[..., 1] / stride - 0.5).clamp(min=0.0 * one, max=last_y)
    x0, y0 = x.floor(), y.floor()
    x1, y1 = torch.minimum(x0 + 1, last_x), torch.minimum(y0 + 1, last_y)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]  # (B, K, S, 1)
    rows = features.permute(0, 2, 3, 1).reshape(-1, channels)  # (B h w, C)
    first = (torch.arange(batch, device=features.device, dtype=points.dtype) * (one * height) * row
             ).reshape(-1, 1, 1)  # (B, 1, 1) the row of each image's first cell

    def at(cell_y: Tensor, cell_x: Tensor) -> Tensor:
        index = (first + cell_y * row + cell_x).long().reshape(-1)
        return rows[index].reshape(*points.shape[:-1], channels)

    return (at(y0, x0) * ((1 - fx) * (1 - fy)) + at(y0, x1) * (fx * (1 - fy))
            + at(y1, x0) * ((1 - fx) * fy) + at(y1, x1) * (fx * fy))


def foot_from_offsets(offsets: Tensor, cxcywh: Tensor) -> Tensor:
    """(..., 2) offsets a, b and (..., 4) `cxcywh` boxes -> (..., 2) foot points, same px."""
    centre_x, _, width, height = cxcywh.unbind(-1)
    bottom = cxcywh[..., 1] + height / 2
    return torch.stack([centre_x + offsets[..., 0] * width, bottom + offsets[..., 1] * height], dim=-1)


def foot_loss(offsets: Tensor, boxes_xyxy: Tensor, targets: Tensor,
              refine: tuple[Tensor, FootHead] | None = None,
              max_metres_per_px: float = MAX_METRES_PER_PX, coarse_weight: float = 1.0
              ) -> tuple[Tensor, int]:
    """Sum over positives of metres-weighted L1 and their count (with `refine`, the image's
    (1, width, H/8, W/8) features and the head whose refiner reads them: the mean of the coarse
    point's loss, weighted `coarse_weight`, and every pass's); each person's weight stops at
    `max_metres_per_px`.

    offsets (P, 2) predicted a, b; boxes_xyxy (P, 4) the cells' decoded boxes (the foot is read off
    the box the model itself predicts, as at inference); targets (P, 3) foot x, y (px) and metres
    per px, NaN where the person's floor point is unknown."""
    valid = torch.isfinite(targets).all(dim=1)
    if not bool(valid.any()):
        return offsets.new_zeros(()), 0
    boxes = boxes_xyxy[valid].detach()
    cxcywh = torch.cat([(boxes[:, :2] + boxes[:, 2:]) / 2, boxes[:, 2:] - boxes[:, :2]], dim=1)
    predicted = foot_from_offsets(offsets[valid], cxcywh)  # (V, 2) px
    weight = targets[valid, 2].clamp(max=max_metres_per_px)
    error = (predicted - targets[valid, :2]).abs().sum(dim=1)  # (V,) px
    if refine is not None:
        fine, head = refine
        passes = head.passes(fine, predicted[None])
        error = error * coarse_weight
        for refined in passes:
            error = error + (refined[0] - targets[valid, :2]).abs().sum(dim=1)
        error = error / (coarse_weight + len(passes))
    return (error * weight).sum(), int(valid.sum())


def metres_per_px(grid: PolarGrid, camera: FisheyeCamera, strip_xy: FloatArray) -> FloatArray:
    """(N,) floor metres between each strip point (N, 2) and the point one row nearer the centre:
    how much a pixel of radial error costs there (NaN where either has no floor point)."""
    if len(strip_xy) == 0:
        return np.zeros(0)
    here = camera.pixels_to_floor(grid.strip_to_frame(strip_xy))
    inward = camera.pixels_to_floor(grid.strip_to_frame(strip_xy + np.array([0.0, 1.0])))
    return np.asarray(np.linalg.norm(here - inward, axis=1), dtype=np.float64)


def strip_feet(grid: PolarGrid, camera: FisheyeCamera, locations_m: FloatArray, boxes_xyxy: FloatArray
               ) -> FloatArray:
    """Floor points (N, 2) m of the people of strip boxes (N, 4) -> (N, 3) targets: the foot in
    strip px (in the same turn as its box's centre) and `metres_per_px` there; NaN rows where the
    floor point is unknown or has no pixel."""
    if len(locations_m) == 0:
        return np.zeros((0, 3))
    feet = np.full((len(locations_m), 3), np.nan)
    known = np.all(np.isfinite(locations_m), axis=1)
    if not known.any():
        return feet
    strip = grid.frame_to_strip(camera.floor_to_pixels(locations_m[known]))  # (K, 2), first turn
    centre_x = (boxes_xyxy[known, 0] + boxes_xyxy[known, 2]) / 2
    strip[:, 0] += np.round((centre_x - strip[:, 0]) / grid.width) * grid.width
    feet[known, :2] = strip
    feet[known, 2] = metres_per_px(grid, camera, strip)
    return np.where(np.all(np.isfinite(feet), axis=1, keepdims=True), feet, np.nan)
