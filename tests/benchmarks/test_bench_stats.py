"""Percentiles and summaries on data whose answers are known by hand (and by numpy)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from benchmarks.stats import overhead_pct, percentile, ratio, summarize


@pytest.mark.parametrize(("samples", "q", "expected"), [
    ([5.0], 99, 5.0),
    ([1.0, 2.0], 50, 1.5),
    ([3.0, 1.0, 2.0], 50, 2.0),          # unsorted input
    (list(range(1, 101)), 95, 95.05),    # rank 0.95 * 99 = 94.05 -> 95 + 0.05
    (list(range(1, 101)), 99, 99.01),
    (list(range(1, 101)), 0, 1.0),
    (list(range(1, 101)), 100, 100.0),
    ([10.0, 20.0, 30.0, 40.0], 25, 17.5),
])
def test_percentile_known_values(samples: list[float], q: float, expected: float) -> None:
    assert percentile(samples, q) == pytest.approx(expected)


@given(st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=60), st.floats(0, 100))
def test_percentile_matches_numpy_linear(samples: list[float], q: float) -> None:
    assert percentile(samples, q) == pytest.approx(float(np.percentile(samples, q)), rel=1e-9, abs=1e-6)


@pytest.mark.parametrize(("samples", "q"), [([], 50), ([1.0], -1), ([1.0], 100.5), ([1.0], float("nan"))])
def test_percentile_refuses(samples: list[float], q: float) -> None:
    with pytest.raises(ValueError):
        percentile(samples, q)


def test_summary_of_one_to_hundred() -> None:
    summary = summarize([float(v) for v in range(100, 0, -1)])
    assert summary.n == 100
    assert summary.mean == pytest.approx(50.5)
    assert (summary.min, summary.p50, summary.max) == (1.0, 50.5, 100.0)
    assert summary.p95 == pytest.approx(95.05) and summary.p99 == pytest.approx(99.01)
    assert set(summary.as_dict()) == {"n", "mean", "p50", "p95", "p99", "min", "max"}
    with pytest.raises(ValueError):
        summarize([])


def test_ratio_and_overhead() -> None:
    assert ratio(30.0, 20.0) == pytest.approx(1.5)
    assert ratio(1.0, 0.0) is None
    assert overhead_pct(46.0, 40.0) == pytest.approx(15.0)
    assert overhead_pct(36.0, 40.0) == pytest.approx(-10.0)
    assert overhead_pct(1.0, 0.0) is None
