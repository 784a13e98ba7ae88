"""Zones and counting lines: validation, containment and crossings."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from sites import CountingLine, LayoutError, Zone, line_from_body, zone_from_body

SQUARE = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]


@pytest.mark.parametrize(("body", "message"), [
    ({"polygon_m": [[0, 0], [1, 1], [1, 0], [0, 1]]}, "intersects itself"),
    ({"polygon_m": [[0, 0], [1, 0], [2, 0]]}, "degenerate"),
    ({"polygon_m": [[0, 0], [1, 0]]}, "at least 3 corners"),
    ({"polygon_m": [[0, 0], [1, 0], [1, 1], [1, 0], [0, 1]]}, "repeats a corner"),
    ({"polygon_m": [[0, 0], [1, "a"], [1, 1]]}, "pairs of numbers"),
    ({"polygon_m": [[0, 0, 0], [1, 0, 0], [1, 1, 0]]}, "pairs of numbers"),
    ({"polygon_m": [[0, 0], [1, 0], [1, float("inf")]]}, "finite"),
    ({"polygon_m": "square"}, "pairs of numbers"),
    ({}, "needs polygon_m"),
    ({"polygon_m": SQUARE, "colour": "red"}, "unknown field"),
])
def test_invalid_zones_are_refused_with_the_reason(body: dict[str, Any], message: str) -> None:
    with pytest.raises(LayoutError, match=message):
        zone_from_body("entrance", body)


@pytest.mark.parametrize(("body", "message"), [
    ({"from_m": [1, 1], "to_m": [1, 1]}, "apart"),
    ({"from_m": [1, 1]}, "needs from_m"),
    ({"from_m": [1, 1], "to_m": [1]}, "pairs of numbers"),
    ({"from_m": [1, 1], "to_m": [2, 2], "width": 1}, "unknown field"),
])
def test_invalid_lines_are_refused_with_the_reason(body: dict[str, Any], message: str) -> None:
    with pytest.raises(LayoutError, match=message):
        line_from_body("door", body)


@pytest.mark.parametrize("name", ["", "-x", "a b", "x" * 65, "zone\n"])
def test_names_must_be_ids(name: str) -> None:
    with pytest.raises(LayoutError, match="id must be"):
        Zone(name, np.array(SQUARE))


def test_a_closed_ring_loses_its_repeated_corner() -> None:
    zone = zone_from_body("entrance", {"polygon_m": [*SQUARE, SQUARE[0]]})
    assert zone.to_dict() == {"polygon_m": SQUARE}


@pytest.mark.parametrize(("points", "inside"), [
    (np.zeros((0, 2)), []),
    (np.array([[1.0, 1.0], [3.0, 1.0], [2.0, 1.0]]), [True, False, True]),  # the boundary counts
])
def test_zone_containment(points: np.ndarray, inside: list[bool]) -> None:
    assert Zone("z", np.array(SQUARE)).contains_xy(points).tolist() == inside


@pytest.mark.parametrize(("before", "after", "sign"), [
    ([-1.0, 0.0], [1.0, 0.0], 1),    # left -> right looking from (0, -1) to (0, 1): in
    ([1.0, 0.0], [-1.0, 0.0], -1),   # right -> left: out
    ([-1.0, 2.0], [1.0, 2.0], 0),    # past the segment's end
    ([-1.0, 0.0], [-0.5, 0.0], 0),   # stays on the left
    ([-1.0, 0.0], [0.0, 0.0], 0),    # ends on the line: not across yet
])
def test_line_crossing_signs(before: list[float], after: list[float], sign: int) -> None:
    line = CountingLine("door", np.array([0.0, -1.0]), np.array([0.0, 1.0]))
    assert line.crossings(np.array([before]), np.array([after])).tolist() == [sign]
