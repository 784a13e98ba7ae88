"""The numpy assignment solver against scipy's (an independent implementation): the same least total
cost on every matrix, the same matching wherever the optimum is unique, for every shape from empty."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment as scipy_assignment
from scipy.spatial.distance import cdist

from sites.assignment import linear_sum_assignment, pairwise_distance_m

SHAPES = [(0, 0), (0, 3), (3, 0), (1, 1), (1, 5), (5, 1), (4, 4), (3, 9), (9, 3), (12, 12), (20, 7)]


@pytest.mark.parametrize("shape", SHAPES)
def test_the_matching_is_scipys_on_continuous_costs(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(sum(shape))
    for _ in range(40):
        cost = rng.random(shape) * 10
        cost[rng.random(shape) < 0.3] = 1e9  # gated pairs, as fusion marks them
        rows, cols = linear_sum_assignment(cost)
        expected_rows, expected_cols = scipy_assignment(cost)
        np.testing.assert_array_equal(rows, expected_rows)
        np.testing.assert_array_equal(cols, expected_cols)
        assert rows.dtype == np.int64 and cols.dtype == np.int64


@pytest.mark.parametrize("shape", SHAPES)
def test_the_total_cost_is_scipys_with_ties(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(100 + sum(shape))
    for _ in range(40):
        cost = rng.integers(0, 3, shape).astype(np.float64)
        rows, cols = linear_sum_assignment(cost)
        expected_rows, expected_cols = scipy_assignment(cost)
        assert len(rows) == min(shape) and len(set(cols.tolist())) == len(cols)
        assert np.all(np.diff(rows) > 0)
        assert cost[rows, cols].sum() == cost[expected_rows, expected_cols].sum()


def test_bad_matrices_are_refused() -> None:
    with pytest.raises(ValueError, match="2-D"):
        linear_sum_assignment(np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        linear_sum_assignment(np.array([[1.0, np.inf]]))


@pytest.mark.parametrize(("n", "m"), [(0, 0), (0, 4), (3, 0), (5, 4)])
def test_pairwise_distances_are_cdists(n: int, m: int) -> None:
    rng = np.random.default_rng(n * 10 + m)
    a, b = rng.normal(size=(n, 2)) * 5, rng.normal(size=(m, 2)) * 5
    np.testing.assert_array_equal(pairwise_distance_m(a, b), cdist(a, b).reshape(n, m))
