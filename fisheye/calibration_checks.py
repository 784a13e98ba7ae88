"""Checks of ruler marks before a calibration fit: mistakes a user makes while marking (a mark off
the frame, a distance of 0 typed for a mark that is not the nadir, distances that shrink outwards,
rulers all on one line) are refused with a message that names the mark, never fitted into a lens."""

from __future__ import annotations

import itertools
import math

import numpy as np

from fisheye.camera_file import CalibrationError
from fisheye.ruler_marks import RulerMarks

MIN_DIRECTION_SPREAD = 0.05  # smallest eigenvalue of the marks' direction scatter for a fitted centre
MIN_TILT_DIRECTIONS = 3
_DIRECTION_SEPARATION_RAD = math.radians(10.0)  # rulers closer than this count as one direction
_NADIR_AGREEMENT_PX = 3.0  # nadir clicks may scatter this much whatever the lens
_ORDER_SLACK_PX = 2.0  # click noise may reverse neighbouring marks by this much


def check_marks_in_image(marks: RulerMarks, image_size: tuple[int, int]) -> None:
    """Every mark must lie on the frame the calibration is made at."""
    width, height = image_size
    u, v = marks.uv_px[:, 0], marks.uv_px[:, 1]
    outside = np.flatnonzero((u < -0.5) | (u > width - 0.5) | (v < -0.5) | (v > height - 0.5))
    if outside.size:
        i = int(outside[0])
        raise CalibrationError(
            f"image_size: mark {i + 1} ({marks.uv_px[i, 0]:g}, {marks.uv_px[i, 1]:g}) lies outside the "
            f"{width}x{height} image; were the marks taken on a frame of another size?",
            code="frame_size_mismatch")


def check_nadir_marks(marks: RulerMarks) -> None:
    """Marks of distance 0 must all be clicks of one point: a second one far from the first is a
    mark whose distance was left at 0 by mistake."""
    nadir = np.flatnonzero(marks.is_nadir)
    away = ~marks.is_nadir
    if len(nadir) < 2 or not away.any():
        return
    centre = np.median(marks.uv_px[nadir], axis=0)
    nearest_px = float(np.hypot(*(marks.uv_px[away] - centre).T).min())
    allowed = max(_NADIR_AGREEMENT_PX, 0.5 * nearest_px)
    offsets = np.hypot(*(marks.uv_px[nadir] - centre).T)
    if offsets.max() > allowed:
        i = int(nadir[int(np.argmax(offsets))])
        raise CalibrationError(
            f"distance_m: mark {i + 1} (ruler {marks.ruler[i]!r}) has distance 0 but lies "
            f"{offsets.max():.0f} px from the other nadir marks; only the point straight below the "
            "lens has distance 0", code="nadir_mismatch")


def check_ruler_order(marks: RulerMarks, centre_px: tuple[float, float]) -> None:
    """Along each labelled ruler, marks farther out on the floor must lie farther from the nadir in
    the image; otherwise the lens would have to turn back (r(θ) not increasing)."""
    labels = np.asarray(marks.ruler, dtype=object)
    radius_px = np.hypot(marks.uv_px[:, 0] - centre_px[0], marks.uv_px[:, 1] - centre_px[1])
    for label in sorted({str(name) for name in labels if name}):
        index = np.flatnonzero((labels == label) & ~marks.is_nadir)
        index = index[np.argsort(marks.distance_m[index], kind="stable")]
        for near, far in itertools.pairwise(index):
            if marks.distance_m[far] > marks.distance_m[near] and \
                    radius_px[far] < radius_px[near] - _ORDER_SLACK_PX:
                raise CalibrationError(
                    f"distance_m: on ruler {label!r}, mark {far + 1} ({marks.distance_m[far]:g} m) lies "
                    f"nearer the nadir in the image ({radius_px[far]:.0f} px) than mark {near + 1} "
                    f"({marks.distance_m[near]:g} m, {radius_px[near]:.0f} px); a lens cannot do that, so "
                    "a distance or a click is wrong", code="not_monotonic")


def mark_directions_rad(marks: RulerMarks, centre_px: tuple[float, float]) -> np.ndarray:
    """(K,) floor azimuths of the marks away from the nadir: from x, y where known, else the image
    direction from `centre_px` (v flipped, so both count counter-clockwise from x)."""
    away = ~marks.is_nadir
    offset = np.where(marks.has_xy[away, None], marks.xy_m[away] * [1.0, -1.0],
                      marks.uv_px[away] - np.asarray(centre_px))
    return np.asarray(np.arctan2(-offset[:, 1], offset[:, 0]))


def direction_spread(marks: RulerMarks, centre_px: tuple[float, float]) -> float:
    """Smallest eigenvalue of the scatter of the marks' unit directions from the centre: 0 when all
    marks lie on one line through it, 0.5 for rulers evenly spread."""
    angles = mark_directions_rad(marks, centre_px)
    unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return float(np.linalg.eigvalsh(unit.T @ unit / len(unit))[0]) if len(unit) else 0.0


def count_directions(marks: RulerMarks, centre_px: tuple[float, float]) -> int:
    """How many distinct directions (at least 10° apart) the marks lie in, seen from the nadir."""
    angles = np.sort(np.mod(mark_directions_rad(marks, centre_px), 2 * math.pi))
    count, start = 0, -math.inf
    for angle in angles:  # a direction starts where an angle passes the last start by 10°
        if angle - start > _DIRECTION_SEPARATION_RAD:
            count, start = count + 1, float(angle)
    if count > 1 and angles[0] + 2 * math.pi - start <= _DIRECTION_SEPARATION_RAD:
        count -= 1  # the last direction runs on into the first across 0°
    return count


def check_tilt_marks(marks: RulerMarks, centre_px: tuple[float, float], undirected: int) -> None:
    """A tilt fit needs every mark's floor direction (a ruler label or x, y) and rulers in three or
    more directions: rulers on one or two lines cannot tell a tilt from a shifted principal point."""
    if undirected:
        raise CalibrationError(
            f"fit_tilt: {undirected} mark(s) have neither a ruler label nor x_m, y_m; fitting the tilt "
            "needs every mark's floor direction", code="invalid_marks")
    directions = count_directions(marks, centre_px)
    if directions < MIN_TILT_DIRECTIONS or direction_spread(marks, centre_px) < MIN_DIRECTION_SPREAD:
        raise CalibrationError(
            f"fit_tilt: the marks lie in {directions} direction(s) from the nadir; fitting the tilt "
            f"needs rulers in {MIN_TILT_DIRECTIONS} or more directions around it", code="one_direction")
