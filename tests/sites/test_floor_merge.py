"""Floor-plane merge of one camera frame's detections: the same person twice is one, two people are two."""

from __future__ import annotations

import numpy as np
import pytest

from sites.floor_merge import merge_on_floor


@pytest.mark.parametrize(("positions_m", "distance_m", "scores", "expected"), [
    (np.zeros((0, 2)), np.zeros(0), np.zeros(0), []),
    # One person twice, 0.4 m apart, 3 m from the nadir (radius 0.3 + 0.1 · 3 = 0.6 m): one.
    ([[3.0, 0.0], [3.4, 0.0]], [3.0, 3.4], [0.6, 0.9], [1, 1]),
    # The same 0.4 m at the nadir (radius 0.3 m): two people.
    ([[0.0, 0.0], [0.4, 0.0]], [0.0, 0.4], [0.6, 0.9], [0, 1]),
    # Two confident detections 0.5 m apart 4 m out: two people walking side by side.
    ([[4.0, 0.0], [4.0, 0.5]], [4.0, 4.03], [0.85, 0.9], [0, 1]),
    # ...but 0.25 m apart, within the base radius: one.
    ([[4.0, 0.0], [4.0, 0.25]], [4.0, 4.01], [0.85, 0.9], [1, 1]),
    # A chain: the middle one is dropped by the best, the far end is kept (1.0 m from the best).
    ([[2.0, 0.0], [2.5, 0.0], [3.0, 0.0]], [2.0, 2.5, 3.0], [0.9, 0.5, 0.7], [0, 0, 2]),
])
def test_merge_on_floor(positions_m: object, distance_m: object, scores: object, expected: list[int]) -> None:
    kept_for = merge_on_floor(np.asarray(positions_m, dtype=np.float64).reshape(-1, 2),
                              np.asarray(distance_m, dtype=np.float64), np.asarray(scores, dtype=np.float64),
                              radius_base_m=0.3, radius_per_m=0.1, sure_score=0.8)
    assert kept_for.tolist() == expected


def test_merge_on_floor_leaves_its_inputs_alone() -> None:
    positions = np.array([[3.0, 0.0], [3.3, 0.0]])
    scores = np.array([0.5, 0.9])
    merge_on_floor(positions, np.array([3.0, 3.3]), scores, 0.3, 0.1)
    np.testing.assert_array_equal(positions, [[3.0, 0.0], [3.3, 0.0]])
    np.testing.assert_array_equal(scores, [0.5, 0.9])
