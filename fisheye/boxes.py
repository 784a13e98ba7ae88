"""Radius-aligned boxes: rotated rectangles whose `h` axis lies on the ray from the principal point.

A box is `cxcywh` (N, 4) px: centre, `w` across the ray (tangential), `h` along it (radial). Its
angle follows from its position: `angle = atan2(cy - v0, cx - u0)`, the direction of the `h` axis
(clockwise on screen, since v points down). Pure functions on arrays; inputs are never mutated.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fisheye.arrays import as_points

FloatArray = NDArray[np.float64]


def radial_angles_rad(centers_xy: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 2) px box centres -> (N,) rad, the direction of the ray from the principal point."""
    centers = as_points(centers_xy, 2, "centers_xy")
    offset = centers - np.asarray(principal_point, dtype=np.float64)
    return np.arctan2(offset[:, 1], offset[:, 0])


def _axes(cxcywh: FloatArray, principal_point: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Unit radial (N, 2) and tangential (N, 2) axes of the boxes."""
    angle = radial_angles_rad(cxcywh[:, :2], principal_point)
    radial = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    tangential = np.stack([-radial[:, 1], radial[:, 0]], axis=1)
    return radial, tangential


def cxcywh_to_corners(cxcywh: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4) radius-aligned boxes -> (N, 4, 2) corners px.

    Order: the two corners of the side nearest the principal point first, then the two of the far
    side, so that consecutive corners go round the rectangle.
    """
    boxes = as_points(cxcywh, 4, "cxcywh")
    radial, tangential = _axes(boxes, principal_point)
    center = boxes[:, None, :2]
    half_h = (boxes[:, 3:4] / 2) * radial
    half_w = (boxes[:, 2:3] / 2) * tangential
    signs = np.array([[-1.0, -1.0], [-1.0, 1.0], [1.0, 1.0], [1.0, -1.0]])  # (radial, tangential)
    return center + signs[None, :, :1] * half_h[:, None, :] + signs[None, :, 1:] * half_w[:, None, :]


def corners_to_cxcywh(corners_xy: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4, 2) corners in the order of `cxcywh_to_corners` -> (N, 4) radius-aligned boxes."""
    corners = np.array(corners_xy, dtype=np.float64)
    if corners.size == 0:
        return np.zeros((0, 4))
    if corners.ndim != 3 or corners.shape[1:] != (4, 2):
        raise ValueError(f"corners_xy must have shape (N, 4, 2), got {corners.shape}")
    center = corners.mean(axis=1)
    h = np.linalg.norm(corners[:, 3] - corners[:, 0], axis=1)
    w = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    return np.concatenate([center, w[:, None], h[:, None]], axis=1)


def foot_points(cxcywh: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4) radius-aligned boxes -> (N, 2) px, the point of each box nearest the principal point.

    That is the midpoint of the box side nearest the principal point; when the principal point lies
    within h/2 of the centre (the person stands below the lens) it is the principal point itself.
    """
    boxes = as_points(cxcywh, 4, "cxcywh")
    pp = np.asarray(principal_point, dtype=np.float64)
    offset = boxes[:, :2] - pp
    distance = np.hypot(offset[:, 0], offset[:, 1])
    half_h = boxes[:, 3] / 2
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = offset / distance[:, None]
    foot = boxes[:, :2] - unit * half_h[:, None]
    below_lens = distance <= half_h
    foot[below_lens] = pp
    return foot


def box_centers_distance_px(cxcywh: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4) boxes -> (N,) px, distance of each centre from the principal point."""
    boxes = as_points(cxcywh, 4, "cxcywh")
    offset = boxes[:, :2] - np.asarray(principal_point, dtype=np.float64)
    return np.hypot(offset[:, 0], offset[:, 1])


def cepdof_to_radius_aligned(cxcywha: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 5) CEPDOF/WEPDTOF boxes `[cx, cy, w, h, angle_deg]` -> (N, 4) radius-aligned `cxcywh`.

    CEPDOF's angle turns the `h` axis clockwise from the image's vertical, so that axis points along
    (sin a, -cos a). Annotators draw boxes roughly radial; the box keeps its centre and its two side
    lengths, and whichever side lies closer to the ray becomes `h` (area is preserved, and a box that
    was already radius-aligned comes back unchanged).
    """
    boxes = as_points(cxcywha, 5, "cxcywha")
    angle = np.radians(boxes[:, 4])
    axis_h = np.stack([np.sin(angle), -np.cos(angle)], axis=1)
    radial, _ = _axes(boxes[:, :4], principal_point)
    alignment = np.abs(np.sum(axis_h * radial, axis=1))  # |cos| of the angle between h axis and ray
    h_is_radial = alignment >= np.sqrt(0.5)
    w, h = boxes[:, 2], boxes[:, 3]
    radial_extent = np.where(h_is_radial, h, w)
    tangential_extent = np.where(h_is_radial, w, h)
    return np.stack([boxes[:, 0], boxes[:, 1], tangential_extent, radial_extent], axis=1)


def loaf_to_radius_aligned(cxcywha: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 5) LOAF boxes `[cx, cy, w, h, angle_deg]` -> (N, 4) radius-aligned `cxcywh`.

    LOAF's angle turns the box counter-clockwise on screen, the opposite sense to CEPDOF's, so the
    `h` axis points along (sin a, cos a): CEPDOF's axis for the angle −a. Source: the public
    helpers that read LOAF's `annotations/resolution_*/instances_*.json` (`vis_rotatedbox` turns a
    corner offset (dx, dy) into (dx·cos a + dy·sin a, −dx·sin a + dy·cos a); `bbox2rotatedbox` sets
    a = polar angle of the centre (counter-clockwise, y up) − 90°, or − 270° below the centre, which
    with that rotation puts `h` on the ray, as the paper's radius-aligned boxes have it). A
    radius-aligned box comes back unchanged.
    """
    boxes = as_points(cxcywha, 5, "cxcywha")
    return cepdof_to_radius_aligned(boxes * np.array([1.0, 1.0, 1.0, 1.0, -1.0]), principal_point)


def radius_aligned_to_cepdof(cxcywh: ArrayLike, principal_point: ArrayLike) -> FloatArray:
    """(N, 4) radius-aligned boxes -> (N, 5) CEPDOF boxes `[cx, cy, w, h, angle_deg]` with w ≤ h and
    the angle in [-90, 90)."""
    boxes = as_points(cxcywh, 4, "cxcywh")
    radial_angle = radial_angles_rad(boxes[:, :2], principal_point)
    # The radial direction (cos r, sin r) equals (sin a, -cos a) for a = r + 90°.
    angle_deg = np.degrees(radial_angle) + 90.0
    w, h = boxes[:, 2], boxes[:, 3]
    swap = w > h
    angle_deg = np.where(swap, angle_deg + 90.0, angle_deg)
    angle_deg = (angle_deg + 90.0) % 180.0 - 90.0
    short = np.where(swap, h, w)
    long = np.where(swap, w, h)
    return np.stack([boxes[:, 0], boxes[:, 1], short, long, angle_deg], axis=1)


def cepdof_to_corners(cxcywha: ArrayLike) -> FloatArray:
    """(N, 5) CEPDOF boxes -> (N, 4, 2) corners px."""
    boxes = as_points(cxcywha, 5, "cxcywha")
    angle = np.radians(boxes[:, 4])
    axis_h = np.stack([np.sin(angle), -np.cos(angle)], axis=1)
    axis_w = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    half_h = (boxes[:, 3:4] / 2) * axis_h
    half_w = (boxes[:, 2:3] / 2) * axis_w
    center = boxes[:, :2]
    return np.stack(
        [center - half_h - half_w, center - half_h + half_w, center + half_h + half_w,
         center + half_h - half_w],
        axis=1,
    )
