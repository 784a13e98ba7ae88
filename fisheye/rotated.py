"""Intersection over union of rotated boxes, and rotated non-maximum suppression.

Convex quadrilaterals are intersected by Sutherland–Hodgman clipping, vectorised over all box pairs
whose circumscribed circles overlap (the others have IoU 0 without clipping).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.arrays import as_points
from fisheye.boxes import cxcywh_to_corners

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_MAX_VERTICES = 8  # a quadrilateral clipped by four half-planes has at most 8 vertices


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _signed_areas(polygons: FloatArray, counts: IntArray) -> FloatArray:
    """Shoelace area of (P, V, 2) polygons with `counts` (P,) vertices each -> (P,)."""
    V = polygons.shape[1]  # polygons: (P, V, 2)
    index = np.arange(V)[None, :]
    following = np.where(index + 1 < counts[:, None], index + 1, 0)
    nxt = np.take_along_axis(polygons, following[:, :, None], axis=1)
    terms = np.where(index < counts[:, None], _cross(polygons, nxt), 0.0)
    return 0.5 * terms.sum(axis=1)


def _counter_clockwise(quads: FloatArray) -> FloatArray:
    """(P, 4, 2) quadrilaterals with positive signed area (vertex order reversed where needed)."""
    area = _signed_areas(quads, np.full(len(quads), 4))
    return np.where((area < 0)[:, None, None], quads[:, ::-1], quads)


def _clip(subject: FloatArray, counts: IntArray, edge_from: FloatArray, edge_to: FloatArray
          ) -> tuple[FloatArray, IntArray]:
    """Keep the part of each (P, V, 2) polygon left of its edge (P, 2) -> (P, 2). -> (P, V, 2), (P,)."""
    P, V, _ = subject.shape  # (P, V, 2)
    direction = (edge_to - edge_from)[:, None, :]
    side = _cross(direction, subject - edge_from[:, None, :])  # (P, V), >= 0 inside
    index = np.arange(V)[None, :]
    present = index < counts[:, None]
    following = np.where(index + 1 < counts[:, None], index + 1, 0)
    nxt = np.take_along_axis(subject, following[:, :, None], axis=1)
    side_next = np.take_along_axis(side, following, axis=1)
    inside = side >= 0
    # Only a strict change of sign is a crossing: a vertex on the edge is kept once, as a vertex,
    # so touching polygons never gain duplicate vertices (at most one new vertex per clip).
    crosses = ((side > 0) & (side_next < 0)) | ((side < 0) & (side_next > 0))
    denominator = side - side_next
    t = side / np.where(denominator == 0, 1.0, denominator)
    crossing = subject + t[:, :, None] * (nxt - subject)
    candidates = np.stack([subject, crossing], axis=2).reshape(P, 2 * V, 2)
    keep = np.stack([inside & present, crosses & present], axis=2).reshape(P, 2 * V)
    order = np.argsort(~keep, axis=1, kind="stable")[:, :V]
    clipped = np.take_along_axis(candidates, order[:, :, None], axis=1)
    return clipped, np.minimum(keep.sum(axis=1), V)


def quad_intersection_areas(quads_a: FloatArray, quads_b: FloatArray) -> FloatArray:
    """Pairwise rows: (P, 4, 2) and (P, 4, 2) convex quadrilaterals -> (P,) intersection areas."""
    P = len(quads_a)
    if P == 0:
        return np.zeros(0)
    subject = np.zeros((P, _MAX_VERTICES, 2))
    subject[:, :4] = _counter_clockwise(quads_a)
    counts = np.full(P, 4)
    clip = _counter_clockwise(quads_b)
    for k in range(4):
        subject, counts = _clip(subject, counts, clip[:, k], clip[:, (k + 1) % 4])
    areas = _signed_areas(subject, counts)
    return np.where(counts >= 3, np.abs(areas), 0.0)


def polygon_iou(corners_a: ArrayLike, corners_b: ArrayLike) -> FloatArray:
    """(N, 4, 2) and (M, 4, 2) convex quadrilaterals (corners px) -> (N, M) IoU."""
    a = np.array(corners_a, dtype=np.float64).reshape(-1, 4, 2)
    b = np.array(corners_b, dtype=np.float64).reshape(-1, 4, 2)
    iou = np.zeros((len(a), len(b)))
    if len(a) == 0 or len(b) == 0:
        return iou
    center_a, center_b = a.mean(axis=1), b.mean(axis=1)
    radius_a = np.linalg.norm(a - center_a[:, None], axis=2).max(axis=1)
    radius_b = np.linalg.norm(b - center_b[:, None], axis=2).max(axis=1)
    gap = np.linalg.norm(center_a[:, None] - center_b[None], axis=2)
    rows, cols = np.nonzero(gap < radius_a[:, None] + radius_b[None, :])
    if len(rows) == 0:
        return iou
    area_a = np.abs(_signed_areas(a, np.full(len(a), 4)))
    area_b = np.abs(_signed_areas(b, np.full(len(b), 4)))
    inter = quad_intersection_areas(a[rows], b[cols])
    union = area_a[rows] + area_b[cols] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        iou[rows, cols] = np.where(union > 0, inter / union, 0.0)
    return np.clip(iou, 0.0, 1.0)


def rotated_iou(cxcywh_a: ArrayLike, cxcywh_b: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4) and (M, 4) radius-aligned boxes around one principal point -> (N, M) IoU."""
    return polygon_iou(
        cxcywh_to_corners(cxcywh_a, principal_point), cxcywh_to_corners(cxcywh_b, principal_point)
    )


def rotated_nms(cxcywh: ArrayLike, scores: ArrayLike, principal_point: ArrayLike,
                iou_threshold: float) -> IntArray:
    """Greedy NMS of (N, 4) radius-aligned boxes with (N,) scores -> indices kept, best first.

    A box is dropped when its IoU with a better-scoring kept box exceeds `iou_threshold`.
    """
    boxes = as_points(cxcywh, 4, "cxcywh")
    score = np.asarray(scores, dtype=np.float64).reshape(-1)
    if len(score) != len(boxes):
        raise ValueError(f"{len(boxes)} boxes but {len(score)} scores")
    order = np.argsort(-score, kind="stable")
    iou = rotated_iou(boxes[order], boxes[order], principal_point)
    suppressed = np.zeros(len(order), dtype=bool)
    keep: list[int] = []
    for i in range(len(order)):
        if suppressed[i]:
            continue
        keep.append(int(order[i]))
        suppressed |= iou[i] > iou_threshold
    return np.asarray(keep, dtype=np.int64)
