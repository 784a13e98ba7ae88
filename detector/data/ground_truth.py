"""Exact ground truth of rendered people from the renderer's id image.

A person's box is the tightest radius-aligned box of its visible silhouette: the silhouette's pixels
are projected on the radial and tangential axes through the box centre, the centre moves to the
middle of those extents, and that repeats until the centre's ray stops turning; the final box is
symmetric about its centre, so it holds every silhouette pixel and is radius-aligned exactly.
Boxes of the whole silhouette (`whole_uv`: each person drawn alone, what hides it ignored) follow
the convention of hand-drawn boxes, which take in a person's hidden legs too (CrowdHuman's full
box beside its visible one); which people count and which are ignored stays the visible
silhouette's decision either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

_ITERATIONS = 4
_PIXEL_HALF = 0.5  # boxes hold whole pixels, not only their centres


@dataclass(frozen=True)
class PersonTruth:
    """One person's ground truth: `rotated_box` (cx, cy, w, h) radius-aligned px, `bbox`
    (x, y, w, h) px, `location_m` (x, y) floor point between the feet, `distance_m` from the
    nadir, `visible_px`, `visible_fraction` of its unoccluded size, and `ignore` when it is too
    hidden to be a fair target (written as `iscrowd: 1`)."""

    person: int
    rotated_box: tuple[float, float, float, float]
    bbox: tuple[float, float, float, float]
    location_m: tuple[float, float]
    distance_m: float
    visible_px: int
    visible_fraction: float
    ignore: bool


def radius_aligned_box(pixels_uv: FloatArray, principal_point: FloatArray) -> FloatArray:
    """(N, 2) silhouette pixel centres -> (4,) the tightest radius-aligned box (cx, cy, w, h) that
    holds all the pixels (each as a square of side 1)."""
    pp = np.asarray(principal_point, dtype=np.float64)
    centre = pixels_uv.mean(axis=0)
    for _ in range(_ITERATIONS):
        radial, tangential = _axes(centre, pp)
        r = (pixels_uv - centre) @ radial
        t = (pixels_uv - centre) @ tangential
        centre = centre + radial * (r.max() + r.min()) / 2 + tangential * (t.max() + t.min()) / 2
    radial, tangential = _axes(centre, pp)
    r = (pixels_uv - centre) @ radial
    t = (pixels_uv - centre) @ tangential
    # A unit pixel square reaches |cos| + |sin| halves along any axis.
    pad = _PIXEL_HALF * (abs(radial[0]) + abs(radial[1]))
    h = 2 * (np.abs(r).max() + pad)
    w = 2 * (np.abs(t).max() + pad)
    return np.array([centre[0], centre[1], w, h])


def _axes(centre: FloatArray, pp: FloatArray) -> tuple[FloatArray, FloatArray]:
    offset = centre - pp
    norm = float(np.hypot(offset[0], offset[1]))
    radial = offset / norm if norm > 1e-9 else np.array([0.0, 1.0])
    return radial, np.array([-radial[1], radial[0]])


def people_truth(person_id: NDArray[np.int32], unoccluded_px: NDArray[np.int64],
                 locations_m: FloatArray, principal_point: tuple[float, float],
                 min_visible_fraction: float, min_visible_px: int,
                 whole_uv: Sequence[FloatArray] | None = None) -> list[PersonTruth]:
    """Ground truth of every person with at least one visible pixel, in person order; with
    `whole_uv` (each person's pixels drawn alone, `RenderOutput.whole_uv`) their boxes are the whole
    silhouette's, not the visible one's."""
    rows, cols = np.nonzero(person_id >= 0)
    ids = person_id[rows, cols]
    order = np.argsort(ids, kind="stable")
    ids, rows, cols = ids[order], rows[order], cols[order]
    starts = np.searchsorted(ids, np.arange(len(unoccluded_px) + 1))
    out = []
    for person in range(len(unoccluded_px)):
        lo, hi = starts[person], starts[person + 1]
        if hi == lo:
            continue
        uv = np.stack([cols[lo:hi], rows[lo:hi]], axis=1).astype(np.float64)
        if whole_uv is not None and len(whole_uv[person]):
            uv = whole_uv[person]
        box = radius_aligned_box(uv, np.asarray(principal_point))
        x_min, y_min = uv.min(axis=0) - _PIXEL_HALF
        x_max, y_max = uv.max(axis=0) + _PIXEL_HALF
        visible = hi - lo
        fraction = min(1.0, visible / max(int(unoccluded_px[person]), 1))
        location = locations_m[person]
        out.append(PersonTruth(
            person=person,
            rotated_box=(float(box[0]), float(box[1]), float(box[2]), float(box[3])),
            bbox=(float(x_min), float(y_min), float(x_max - x_min), float(y_max - y_min)),
            location_m=(float(location[0]), float(location[1])),
            distance_m=float(np.hypot(location[0], location[1])),
            visible_px=int(visible),
            visible_fraction=float(fraction),
            ignore=bool(fraction < min_visible_fraction or visible < min_visible_px),
        ))
    return out
