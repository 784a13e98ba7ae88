"""The CPU budget comes from the container's quota, not the host's core count."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.core.cpu import affinity_cpus, cgroup_cpu_quota, cpu_budget, quota_from_cfs, quota_from_cpu_max


@pytest.mark.parametrize(("text", "expected"), [
    ("", None), ("max 100000", None), ("200000 100000", 2.0), ("150000 100000", 1.5), ("garbage", None),
])
def test_cpu_max(text: str, expected: float | None) -> None:
    assert quota_from_cpu_max(text) == expected


@pytest.mark.parametrize(("quota", "period", "expected"), [
    ("-1", "100000", None), ("50000", "100000", 0.5), ("400000", "100000", 4.0), ("x", "1", None),
])
def test_cfs(quota: str, period: str, expected: float | None) -> None:
    assert quota_from_cfs(quota, period) == expected


def test_v2_quota_limits_the_budget(tmp_path: Path) -> None:
    (tmp_path / "cpu.max").write_text("50000 100000\n")
    assert cgroup_cpu_quota(tmp_path) == 0.5
    assert cpu_budget(tmp_path) == 1


def test_v1_quota_is_read(tmp_path: Path) -> None:
    (tmp_path / "cpu").mkdir()
    (tmp_path / "cpu" / "cpu.cfs_quota_us").write_text("100000\n")
    (tmp_path / "cpu" / "cpu.cfs_period_us").write_text("100000\n")
    assert cgroup_cpu_quota(tmp_path) == 1.0
    assert cpu_budget(tmp_path) == 1


def test_no_quota_means_the_affinity_mask(tmp_path: Path) -> None:
    assert cgroup_cpu_quota(tmp_path) is None
    assert cpu_budget(tmp_path) == affinity_cpus() >= 1
