"""Mask polygons of a camera (`masks_px`): image regions where people are seen but never stand
(mirrors, posters, screens, glass). Pure functions on arrays; polygons are (M, 2) px, u right, v down.

A mask must be a simple polygon: at least three corners, a non-zero area, and no edge crossing or
touching another edge (a bow-tie or a polygon that doubles back on itself is refused, since which side
is "inside" would be a guess).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.arrays import as_points

FloatArray = NDArray[np.float64]

MAX_MASKS = 64
MAX_CORNER_PX = 1e6  # |u|, |v| of a mask corner
MAX_MASK_CORNERS = 256
_MIN_AREA_PX2 = 1.0  # a mask thinner than a pixel masks nothing a detector could place a foot in


def polygon_area_px2(polygon_px: ArrayLike) -> float:
    """Signed area (px²) of an (M, 2) polygon by the shoelace formula; positive when its corners run
    clockwise on screen (counter-clockwise in u, v)."""
    points = as_points(polygon_px, 2, "polygon_px")
    u, v = points[:, 0], points[:, 1]
    return float(0.5 * np.sum(u * np.roll(v, -1) - np.roll(u, -1) * v))


def _orientation(p: FloatArray, q: FloatArray, r: FloatArray) -> FloatArray:
    """Sign of the cross product (q − p) × (r − p), row-wise for (K, 2) arrays."""
    cross = (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])
    return np.sign(cross)


def _on_segment(p: FloatArray, q: FloatArray, r: FloatArray) -> NDArray[np.bool_]:
    """Whether r, known to be collinear with p and q, lies within the segment's bounding box."""
    return ((np.minimum(p[:, 0], q[:, 0]) <= r[:, 0]) & (r[:, 0] <= np.maximum(p[:, 0], q[:, 0]))
            & (np.minimum(p[:, 1], q[:, 1]) <= r[:, 1]) & (r[:, 1] <= np.maximum(p[:, 1], q[:, 1])))


def segments_meet(a0: FloatArray, a1: FloatArray, b0: FloatArray, b1: FloatArray) -> NDArray[np.bool_]:
    """(K,) whether segment a0–a1 and segment b0–b1 cross or touch, row-wise for (K, 2) endpoints."""
    o1, o2 = _orientation(a0, a1, b0), _orientation(a0, a1, b1)
    o3, o4 = _orientation(b0, b1, a0), _orientation(b0, b1, a1)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)
    touching = (((o1 == 0) & _on_segment(a0, a1, b0)) | ((o2 == 0) & _on_segment(a0, a1, b1))
                | ((o3 == 0) & _on_segment(b0, b1, a0)) | ((o4 == 0) & _on_segment(b0, b1, a1)))
    return np.asarray(proper | touching)


def polygon_problem(polygon_px: ArrayLike) -> str | None:
    """Why an (M, 2) polygon cannot be a mask (degenerate or self-intersecting), or None if it can."""
    points = as_points(polygon_px, 2, "polygon_px")
    count = len(points)
    if count < 3:
        return f"a polygon needs at least 3 corners, got {count}"
    if count > MAX_MASK_CORNERS:
        return f"a polygon may have at most {MAX_MASK_CORNERS} corners, got {count}"
    if not np.isfinite(points).all():
        return "corners must be finite numbers"
    if np.abs(points).max() > MAX_CORNER_PX:
        # Before any products of coordinates: a corner this far out lies in no frame anyway.
        return f"corners must lie within ±{MAX_CORNER_PX:g} px"
    following = np.roll(points, -1, axis=0)
    repeated = np.flatnonzero((points == following).all(axis=1))
    if repeated.size:
        return f"corner {int(repeated[0]) + 1} repeats the corner after it (a zero-length edge)"
    if np.linalg.matrix_rank(points - points.mean(axis=0)) < 2:
        return "the polygon has no area (its corners lie on one line)"
    first, second = np.triu_indices(count, k=1)
    adjacent = (second == first + 1) | ((first == 0) & (second == count - 1))
    # Adjacent edges share a corner; they only meet elsewhere when the outline doubles back on itself.
    shared = np.where(second == first + 1, second, first)
    other_a = np.where(second == first + 1, first, second)
    other_b = np.where(second == first + 1, (second + 1) % count, 1)
    backtrack = adjacent & _doubles_back(points[other_a], points[shared], points[other_b])
    crossing = ~adjacent & segments_meet(points[first], following[first], points[second], following[second])
    bad = np.flatnonzero(crossing | backtrack)
    if bad.size:
        i, j = int(first[bad[0]]), int(second[bad[0]])
        return f"the polygon intersects itself (edge {i + 1} meets edge {j + 1})"
    if abs(polygon_area_px2(points)) < _MIN_AREA_PX2:
        return f"the polygon's area is under {_MIN_AREA_PX2:g} px²"
    return None


def _doubles_back(before: FloatArray, corner: FloatArray, after: FloatArray) -> NDArray[np.bool_]:
    """(K,) whether the outline before → corner → after turns back along itself (a 180° spike)."""
    incoming, outgoing = corner - before, after - corner
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    dot = np.sum(incoming * outgoing, axis=1)
    return np.asarray((cross == 0) & (dot < 0))


def points_in_polygon(uv_px: ArrayLike, polygon_px: ArrayLike) -> NDArray[np.bool_]:
    """(N, 2) px -> (N,) whether each point lies inside the (M, 2) polygon (even-odd rule); NaN
    points are outside."""
    points = as_points(uv_px, 2, "uv_px")
    corners = as_points(polygon_px, 2, "polygon_px")
    if len(points) == 0 or len(corners) < 3:
        return np.zeros(len(points), dtype=bool)
    u, v = points[:, 0:1], points[:, 1:2]  # (N, 1)
    u0, v0 = corners[:, 0], corners[:, 1]  # (M,)
    u1, v1 = np.roll(u0, -1), np.roll(v0, -1)
    straddles = (v0 > v) != (v1 > v)  # (N, M): the edge spans the point's row
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing_u = u0 + (v - v0) * (u1 - u0) / (v1 - v0)
    crossings = straddles & (u < crossing_u)
    return np.asarray(crossings.sum(axis=1) % 2 == 1)


def points_in_masks(uv_px: ArrayLike, masks_px: Sequence[ArrayLike]) -> NDArray[np.bool_]:
    """(N, 2) px -> (N,) whether each point lies inside any of the mask polygons."""
    points = as_points(uv_px, 2, "uv_px")
    inside = np.zeros(len(points), dtype=bool)
    for polygon in masks_px:
        inside |= points_in_polygon(points, polygon)
    return inside
