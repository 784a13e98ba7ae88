"""Latency statistics: percentiles by linear interpolation, and the summary every section reports."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass


def percentile(samples: Sequence[float], q: float) -> float:
    """The `q`-th percentile (0-100) of `samples`, linearly interpolated between the order statistics
    at rank q/100·(n-1) (numpy's default "linear" method). ValueError on no samples or q outside [0, 100]."""
    if not samples:
        raise ValueError("percentile of no samples")
    if not 0.0 <= q <= 100.0 or math.isnan(q):
        raise ValueError(f"percentile q must be within [0, 100], got {q}")
    ordered = sorted(samples)
    rank = q / 100.0 * (len(ordered) - 1)
    low = math.floor(rank)
    high = min(low + 1, len(ordered) - 1)
    return ordered[low] + (ordered[high] - ordered[low]) * (rank - low)


@dataclass(frozen=True)
class Summary:
    """n samples (ms or any unit): mean, p50, p95, p99, min, max."""

    n: int
    mean: float
    p50: float
    p95: float
    p99: float
    min: float
    max: float

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def summarize(samples: Sequence[float]) -> Summary:
    """Summary of at least one sample."""
    if not samples:
        raise ValueError("summary of no samples")
    values = [float(s) for s in samples]
    return Summary(
        n=len(values), mean=math.fsum(values) / len(values),
        p50=percentile(values, 50), p95=percentile(values, 95), p99=percentile(values, 99),
        min=min(values), max=max(values),
    )


def ratio(numerator: float, denominator: float) -> float | None:
    """numerator / denominator, or None when the denominator is not positive."""
    return numerator / denominator if denominator > 0 else None


def overhead_pct(measured: float, floor: float) -> float | None:
    """How much more `measured` takes than `floor`, in percent of `floor` (None when floor ≤ 0)."""
    return (measured - floor) / floor * 100.0 if floor > 0 else None
