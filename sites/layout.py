"""A site's zones (polygons) and counting lines, in the site frame (metres, x right, y up).

Validation lives here so that the registry, the REST routes and the tracker agree on what a zone or
a line may be: a zone is a simple polygon of at least three corners with a positive area (no
self-intersection, no repeated corner); a line is a segment of positive length. Geometry is
vectorised over points: `Zone.contains_xy` and `CountingLine.crossings` take (N, 2) arrays.

Sign convention of a line (DESIGN.md): looking from `from_m` towards `to_m`, a track that crosses
from the left side to the right side counts `in`, the other way `out`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray

from fisheye.camera import CAMERA_ID_PATTERN

FloatArray = NDArray[np.float64]

NAME_PATTERN = CAMERA_ID_PATTERN  # site, zone and line ids follow the rule of camera ids
_NAME_RE = re.compile(NAME_PATTERN)
MAX_CORNERS = 256
MAX_COORDINATE_M = 100_000.0
MIN_LINE_LENGTH_M = 0.01
MIN_ZONE_AREA_M2 = 1e-4


class LayoutError(ValueError):
    """A zone, line or site name that cannot be used; the message says why."""


def check_name(name: str, what: str) -> str:
    """`name` when it is a valid site, zone or line id, else LayoutError."""
    if not isinstance(name, str) or _NAME_RE.fullmatch(name) is None:
        raise LayoutError(f"{what} id must be 1-64 characters of letters, digits, '.', '_' or '-', "
                          "starting with a letter or digit")
    return name


def _points(value: Any, what: str) -> FloatArray:
    try:
        points = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise LayoutError(f"{what} must be a list of [x, y] pairs of numbers") from None
    if points.ndim != 2 or points.shape[1] != 2:
        raise LayoutError(f"{what} must be a list of [x, y] pairs of numbers")
    if not np.isfinite(points).all() or np.abs(points).max(initial=0.0) > MAX_COORDINATE_M:
        raise LayoutError(f"{what} must hold finite numbers within ±{MAX_COORDINATE_M:g} m")
    return points


@dataclass(frozen=True)
class Zone:
    """A simple polygon in the site frame: `polygon_m` (K, 2) m, K ≥ 3, without the closing corner."""

    id: str
    polygon_m: FloatArray
    shape: shapely.Polygon = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_name(self.id, "zone")
        corners = _points(self.polygon_m, "polygon_m")
        if len(corners) > 1 and np.array_equal(corners[0], corners[-1]):
            corners = corners[:-1]  # a closed ring given with its first corner repeated
        if len(corners) < 3:
            raise LayoutError(f"zone {self.id!r}: polygon_m needs at least 3 corners, got {len(corners)}")
        if len(corners) > MAX_CORNERS:
            raise LayoutError(f"zone {self.id!r}: polygon_m has {len(corners)} corners; at most "
                              f"{MAX_CORNERS}")
        if len(np.unique(corners, axis=0)) < len(corners):
            raise LayoutError(f"zone {self.id!r}: polygon_m repeats a corner")
        polygon = shapely.Polygon(corners)
        reason = str(shapely.is_valid_reason(polygon))
        if polygon.convex_hull.area < MIN_ZONE_AREA_M2:  # all corners on one line
            raise LayoutError(f"zone {self.id!r}: polygon_m is degenerate (its corners lie on a line)")
        if "Self-intersection" in reason:
            raise LayoutError(f"zone {self.id!r}: polygon_m intersects itself ({reason})")
        if polygon.area < MIN_ZONE_AREA_M2:
            raise LayoutError(f"zone {self.id!r}: polygon_m is degenerate (area {polygon.area:.2g} m²)")
        if not polygon.is_valid:
            raise LayoutError(f"zone {self.id!r}: polygon_m is not a simple polygon ({reason})")
        shapely.prepare(polygon)
        object.__setattr__(self, "polygon_m", corners)
        object.__setattr__(self, "shape", polygon)

    def contains_xy(self, xy_m: FloatArray) -> NDArray[np.bool_]:
        """(N, 2) m -> (N,) whether each point lies inside the zone (boundary included)."""
        if len(xy_m) == 0:
            return np.zeros(0, dtype=bool)
        inside: NDArray[np.bool_] = shapely.intersects_xy(self.shape, xy_m[:, 0], xy_m[:, 1])
        return inside

    def to_dict(self) -> dict[str, Any]:
        return {"polygon_m": self.polygon_m.round(4).tolist()}


def side_of(from_m: FloatArray, to_m: FloatArray, xy_m: FloatArray) -> FloatArray:
    """(N, 2) m -> (N,) cross product of the line direction with each point: > 0 on the left
    (looking from `from_m` towards `to_m`), < 0 on the right, 0 on the line's carrier."""
    direction = to_m - from_m
    offset = xy_m - from_m
    return direction[0] * offset[:, 1] - direction[1] * offset[:, 0]


@dataclass(frozen=True)
class CountingLine:
    """A counting segment from `from_m` (2,) to `to_m` (2,) m in the site frame."""

    id: str
    from_m: FloatArray
    to_m: FloatArray

    def __post_init__(self) -> None:
        check_name(self.id, "line")
        ends = _points([self.from_m, self.to_m], "from_m and to_m")
        length = float(np.hypot(*(ends[1] - ends[0])))
        if length < MIN_LINE_LENGTH_M:
            raise LayoutError(f"line {self.id!r}: from_m and to_m are {length:.3g} m apart; a counting "
                              f"line needs at least {MIN_LINE_LENGTH_M} m")
        object.__setattr__(self, "from_m", ends[0])
        object.__setattr__(self, "to_m", ends[1])

    def crossings(self, before_m: FloatArray, after_m: FloatArray) -> NDArray[np.int8]:
        """Moves (N, 2) -> (N, 2) m to (N,): +1 for a move that crosses the segment from its left to
        its right (`in`), -1 the other way (`out`), 0 when it does not cross. A move that only
        touches the line (ends on it) does not cross; the move that leaves it on the other side does."""
        side_before = side_of(self.from_m, self.to_m, before_m)
        side_after = side_of(self.from_m, self.to_m, after_m)
        # The move's own carrier must separate the segment's ends, too, for the segments to meet.
        move = after_m - before_m
        to_from = self.from_m - before_m
        to_to = self.to_m - before_m
        end_a = move[:, 0] * to_from[:, 1] - move[:, 1] * to_from[:, 0]
        end_b = move[:, 0] * to_to[:, 1] - move[:, 1] * to_to[:, 0]
        meets = (end_a * end_b) <= 0
        crossing_in = (side_before > 0) & (side_after < 0) & meets
        crossing_out = (side_before < 0) & (side_after > 0) & meets
        return crossing_in.astype(np.int8) - crossing_out.astype(np.int8)

    def to_dict(self) -> dict[str, Any]:
        return {"from_m": self.from_m.round(4).tolist(), "to_m": self.to_m.round(4).tolist()}


def zone_from_body(zone_id: str, body: Mapping[str, Any]) -> Zone:
    """A zone from a JSON body `{"polygon_m": [[x, y], ...]}`; LayoutError when invalid."""
    unknown = set(body) - {"polygon_m"}
    if unknown:
        raise LayoutError(f"unknown field(s) {sorted(unknown)}; a zone body has only polygon_m")
    if "polygon_m" not in body:
        raise LayoutError("a zone body needs polygon_m: [[x, y], ...] in the site frame (m)")
    return Zone(zone_id, body["polygon_m"])


def line_from_body(line_id: str, body: Mapping[str, Any]) -> CountingLine:
    """A counting line from a JSON body `{"from_m": [x, y], "to_m": [x, y]}`; LayoutError when invalid."""
    unknown = set(body) - {"from_m", "to_m"}
    if unknown:
        raise LayoutError(f"unknown field(s) {sorted(unknown)}; a line body has from_m and to_m")
    if "from_m" not in body or "to_m" not in body:
        raise LayoutError("a line body needs from_m: [x, y] and to_m: [x, y] in the site frame (m)")
    return CountingLine(line_id, body["from_m"], body["to_m"])


@dataclass(frozen=True)
class SiteLayout:
    """The zones and lines of one site, by id."""

    zones: Mapping[str, Zone] = field(default_factory=dict)
    lines: Mapping[str, CountingLine] = field(default_factory=dict)

    @classmethod
    def of(cls, zones: Sequence[Zone] = (), lines: Sequence[CountingLine] = ()) -> SiteLayout:
        return cls({zone.id: zone for zone in zones}, {line.id: line for line in lines})
