"""The second look's geometry: which of a frame's detections are looked at again, the patch each is
seen in, and which of a patch's detections it adds (`contract.detect.second_look` runs them).

The first look sees a seated person at the rim of a 1 MP frame ~30 x 20 px in its band, near what
a stride-8 level finds at all: such people come out with low scores, loose boxes, or beside a
neighbour's box. The second look takes the frame's small, uncertain detections (score below
`BELOW_SCORE`, fewer than `MAX_ALONG_PX` band rows along the ray, not over the principal point),
the `patches` highest-scoring of them, and unwraps a patch about each: the same polar unwrap as the
detection's band at `zoom` times its rows and columns (more for a far person, to bring it to
`target_rows` rows: `ViewPlan.second_look_zoom_for`), three times the box's size each way (within
`fisheye.view_plan.SECOND_LOOK_PATCH_PX`), sampled from the decoded frame; as many as fit in the
look's own budget of input px (`ViewPlan.second_look_pixels`: 0, no look, by default). A frame's
patches are packed into one input (`pack`, `Canvas`) and run at once: a run each paid the runs'
overhead once per patch.
A patch adds the people it finds whole, away from its edges, no longer than a looked-at person may
be, and not mostly inside a first-look detection that was not looked at again (a part of a larger
person); they join the first look's detections before the NMS runs again, and one the first look
found too stands at the first look's foot point. The people of the nadir view's disc, which no
patch looks at, keep the threshold of the view without the look (`nadir_scores`).
docs/DETECTOR.md, "A second look", has the designs measured and the figures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from contract.model import RawOutputs
from fisheye.polar import PolarGrid
from fisheye.view_plan import SECOND_LOOK_PATCH_PX, ViewPlan

FloatArray = NDArray[np.float64]

BELOW_SCORE = 0.7  # detections from this score on are sure enough (chosen on validation renders over 0.5)
MAX_ALONG_PX = 64.0  # band rows along the ray: longer people are big enough for the first look (over 96)
PATCH_EXTENT = 3.0  # a patch spans this many times its detection's box each way
EDGE_MARGIN = 0.15  # a patch's people centre at least this fraction of its side from its edges
PART_OF = 0.6  # a patch box this much (of its own area) inside a detection not looked at is a part of it
# A patch's person overlapping a first-look detection this much is that person: it keeps the first
# look's foot point (the validation renders' mPE is the same either way, 0.1705 m; the unseen ones'
# 0.179 with the patches' feet, 0.170 with the first look's).
SAME_PERSON_IOU = 0.5
FIRST_LOOK_FLOOR = 0.05  # the first look's detections the second one may look at score at least this
# Pad-value px between the patches packed into one input (`pack`): one stride-32 cell, so that every
# patch starts at a multiple of 32 as it does alone and its people's boxes cannot reach a neighbour.
GUTTER_PX = 32


@dataclass(frozen=True)
class Patch:
    """One patch: its grid (frame px; `strip_wh` the model input), the band grid it zooms, and the
    index of the detection it looks at."""

    grid: PolarGrid
    band: PolarGrid
    detection: int


def band_grids(plan: ViewPlan) -> list[PolarGrid]:
    """The grid of each band's first piece (every piece of a band has its radii and columns)."""
    firsts, index = [], 0
    for band in plan.bands:
        firsts.append(plan.grids[index])
        index += band.pieces
    return firsts


def band_of(plan: ViewPlan, radii: FloatArray) -> NDArray[np.int64]:
    """(N,) the band whose reported radii hold each of `radii` (frame px)."""
    starts = np.array([band.owned_px[0] for band in plan.bands], dtype=np.float64)
    return np.clip(np.searchsorted(starts, radii, side="right") - 1, 0, len(starts) - 1).astype(np.int64)


def _side(length: float) -> int:
    low, high = SECOND_LOOK_PATCH_PX
    return int(max(low, min(high, 32 * math.ceil(length / 32))))


def plan_patches(plan: ViewPlan, boxes_cxcywh: FloatArray, scores: FloatArray,
                 principal_point: tuple[float, float]) -> list[Patch]:
    """The patches of a frame's first-look detections (radius-aligned frame px, scores descending):
    at most `plan.second_look_patches`, each about one small, uncertain detection, within
    `plan.second_look_pixels` in all (a patch that would pass them is left out)."""
    if not plan.second_look_patches or not len(scores):
        return []
    pp = np.asarray(principal_point, dtype=np.float64)
    radii = np.hypot(*(boxes_cxcywh[:, :2] - pp).T)
    grids = band_grids(plan)
    bands = band_of(plan, radii)
    patches: list[Patch] = []
    left = plan.second_look_pixels
    for index in np.flatnonzero((scores < BELOW_SCORE) & (radii > boxes_cxcywh[:, 3] / 2)):
        band = grids[int(bands[index])]
        x1, y1, x2, y2 = band.radius_aligned_to_polar(boxes_cxcywh[index:index + 1])[0]
        if y2 - y1 >= MAX_ALONG_PX:
            continue
        zoom = plan.second_look_zoom_for(y2 - y1)
        rows_per_px = band.px_per_radius_px * zoom
        width = round(band.width * zoom)
        height, span = _side(PATCH_EXTENT * (y2 - y1) * zoom), _side(PATCH_EXTENT * (x2 - x1) * zoom)
        outer = min(radii[index] + height / 2 / rows_per_px, band.radius_px)
        inner = max(outer - height / rows_per_px, 0.0)
        angle = math.atan2(boxes_cxcywh[index, 1] - pp[1], boxes_cxcywh[index, 0] - pp[0])
        grid = PolarGrid((float(pp[0]), float(pp[1])), radius_px=inner + height / rows_per_px, height=height,
                         width=width, start_rad=angle - span / 2 * 2 * math.pi / width, inner_radius_px=inner,
                         span=min(span, width))
        if height * span > left:  # over what is left of its budget: a smaller patch may still fit
            continue
        left -= height * span
        patches.append(Patch(grid, band, int(index)))
        if len(patches) == plan.second_look_patches:
            break
    return patches


def patch_keeps(patch: Patch, boxes_cxcywh: FloatArray) -> NDArray[np.bool_]:
    """(N,) which of a patch's detections (radius-aligned frame px) it may add: whole inside it,
    centred away from its edges, and no longer along the ray than 1.5 `MAX_ALONG_PX` band rows."""
    width, height = patch.grid.strip_wh
    inside = patch.grid.radius_aligned_to_polar(boxes_cxcywh)
    centre_x, centre_y = (inside[:, 0] + inside[:, 2]) / 2, (inside[:, 1] + inside[:, 3]) / 2
    whole = ((inside[:, 0] >= 1) & (inside[:, 2] <= width - 2)
             & (inside[:, 1] >= 1) & (inside[:, 3] <= height - 2))
    central = ((centre_x > EDGE_MARGIN * width) & (centre_x < (1 - EDGE_MARGIN) * width)
               & (centre_y > EDGE_MARGIN * height) & (centre_y < (1 - EDGE_MARGIN) * height))
    in_band = patch.band.radius_aligned_to_polar(boxes_cxcywh)
    short = in_band[:, 3] - in_band[:, 1] < 1.5 * MAX_ALONG_PX
    return np.asarray(whole & central & short, dtype=bool)


def parts_of(band: PolarGrid, boxes_cxcywh: FloatArray, others_cxcywh: FloatArray) -> NDArray[np.bool_]:
    """(N,) which of `boxes_cxcywh` lie `PART_OF` or more (of their own area) inside one of
    `others_cxcywh` (M), both read in `band`'s strip."""
    if not len(boxes_cxcywh) or not len(others_cxcywh):
        return np.zeros(len(boxes_cxcywh), dtype=bool)
    a, b = band.radius_aligned_to_polar(boxes_cxcywh), band.radius_aligned_to_polar(others_cxcywh)
    def overlap(low: int, high: int) -> FloatArray:
        return np.clip(np.minimum(a[:, None, high], b[None, :, high])
                       - np.maximum(a[:, None, low], b[None, :, low]), 0, None)

    across, along = overlap(0, 2), overlap(1, 3)
    area = np.maximum((a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1]), 1e-6)
    return np.asarray((across * along / area[:, None]).max(axis=1) >= PART_OF, dtype=bool)


def nadir_scores(plan: ViewPlan, boxes_cxcywh: FloatArray, scores: FloatArray,
                 principal_point: tuple[float, float], threshold: float, nadir_threshold: float
                 ) -> FloatArray:
    """(N,) the scores of a view with the look put on its one `threshold` (its operating point's):
    a person centred in the nadir view's disc (`NadirPiece.owned_px`), where no patch looks, is held
    to `nadir_threshold`, the point of the same view without the look. That point was chosen for the
    disc's people and the first look's; the look's point is higher for its patches' people in the
    bands. Scores in the disc are mapped piecewise linearly, 0 to 0, `nadir_threshold` to
    `threshold` and 1 to 1: the disc's order stays, and the disc's people pass `threshold` where they
    pass `nadir_threshold`. Other scores, and every score of a view without a nadir view or of
    thresholds equal or at 0 or 1 (no scale to map between), are unchanged."""
    mapped = np.asarray(scores, dtype=np.float64).copy()
    if (plan.nadir is None or not len(mapped) or threshold == nadir_threshold
            or not (0.0 < threshold < 1.0 and 0.0 < nadir_threshold < 1.0)):
        return mapped
    pp = np.asarray(principal_point, dtype=np.float64)
    inside = np.hypot(*(boxes_cxcywh[:, :2] - pp).T) < plan.nadir.owned_px
    low = mapped * threshold / nadir_threshold
    high = threshold + (mapped - nadir_threshold) * (1.0 - threshold) / (1.0 - nadir_threshold)
    mapped[inside] = np.where(mapped <= nadir_threshold, low, high)[inside]
    return mapped


@dataclass(frozen=True)
class Canvas:
    """The one model input a frame's patches are packed into: `size_wh` px, each patch's top-left
    corner at `offsets` (x, y) and its size `sizes_wh`, in the order they were given."""

    size_wh: tuple[int, int]
    offsets: tuple[tuple[int, int], ...]
    sizes_wh: tuple[tuple[int, int], ...]

    def paste(self, images: Sequence[NDArray[np.uint8]], pad_value: int) -> NDArray[np.uint8]:
        """(H, W, 3) the canvas: `images` (each of its `sizes_wh`) at their offsets, `pad_value` between."""
        width, height = self.size_wh
        canvas = np.full((height, width, 3), pad_value, dtype=np.uint8)
        for (x, y), (w, h), image in zip(self.offsets, self.sizes_wh, images, strict=True):
            canvas[y:y + h, x:x + w] = image
        return canvas

    def split(self, raw: RawOutputs) -> list[RawOutputs]:
        """The canvas's outputs (`xyxy` input px) -> each patch's, in its own px: the candidates
        centred inside it, moved by its offset (those centred in a gutter belong to none)."""
        centre_x = (raw.boxes[:, 0] + raw.boxes[:, 2]) / 2
        centre_y = (raw.boxes[:, 1] + raw.boxes[:, 3]) / 2
        pieces = []
        for (x, y), (w, h) in zip(self.offsets, self.sizes_wh, strict=True):
            inside = (centre_x >= x) & (centre_x < x + w) & (centre_y >= y) & (centre_y < y + h)
            shift = np.array([x, y], dtype=np.float32)
            pieces.append(RawOutputs(raw.boxes[inside] - np.tile(shift, 2), raw.scores[inside],
                                     None if raw.foot is None else raw.foot[inside] - shift))
        return pieces


def pack(sizes_wh: Sequence[tuple[int, int]]) -> Canvas:
    """The smallest canvas (in px) that holds patches of `sizes_wh` (multiples of 32) `GUTTER_PX`
    apart, packed in shelves (tallest first, left to right, a new shelf below where the next would
    pass the canvas's width) or in columns (the same, turned), each width (height) from the widest
    patch to one shelf of all tried. One run of it costs about what its px do, where a run per
    patch paid ~2.5 ms of overhead each time."""
    if not sizes_wh:
        raise ValueError("no patches to pack")
    shelves = _shelves(sizes_wh)
    turned = _shelves([(h, w) for w, h in sizes_wh])
    columns = Canvas((turned.size_wh[1], turned.size_wh[0]), tuple((y, x) for x, y in turned.offsets),
                     tuple(sizes_wh))
    return min((shelves, columns), key=lambda canvas: canvas.size_wh[0] * canvas.size_wh[1])


def _shelves(sizes_wh: Sequence[tuple[int, int]]) -> Canvas:
    """`pack`'s shelves alone: the smallest canvas of those the widths tried give."""
    order = sorted(range(len(sizes_wh)), key=lambda i: (-sizes_wh[i][1], -sizes_wh[i][0]))
    limits, row = {max(w for w, _ in sizes_wh)}, -GUTTER_PX
    for i in order:
        row += GUTTER_PX + sizes_wh[i][0]
        limits.add(row)
    best: Canvas | None = None
    for limit in sorted(limits):
        offsets: dict[int, tuple[int, int]] = {}
        x = y = shelf = used = 0
        for i in order:
            w, h = sizes_wh[i]
            if x and x + w > limit:
                x, y, shelf = 0, y + shelf + GUTTER_PX, 0
            offsets[i] = (x, y)
            used, shelf, x = max(used, x + w), max(shelf, h), x + w + GUTTER_PX
        canvas = Canvas((used, y + shelf), tuple(offsets[i] for i in range(len(sizes_wh))), tuple(sizes_wh))
        if best is None or canvas.size_wh[0] * canvas.size_wh[1] < best.size_wh[0] * best.size_wh[1]:
            best = canvas
    assert best is not None
    return best


def fit(patches: Sequence[Patch], max_pixels: int) -> tuple[list[Patch], Canvas]:
    """The patches (best first) whose canvas (`pack`) takes at most `max_pixels` px, gutters
    included, and that canvas: the last patch left out while it takes more. The first patch alone
    always fits (`plan_patches` gave it no more px than the budget)."""
    kept = list(patches)
    canvas = pack([patch.grid.strip_wh for patch in kept])
    while len(kept) > 1 and canvas.size_wh[0] * canvas.size_wh[1] > max_pixels:
        kept.pop()
        canvas = pack([patch.grid.strip_wh for patch in kept])
    return kept, canvas
