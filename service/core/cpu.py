"""How many CPUs this process may really use: the container's CPU quota, not the host's core count.

`os.cpu_count()` reports the host's cores; a container limited to 2 CPUs on a 64-core host that
starts 64 inference threads spends its quota on context switches. The budget is the smallest of the
cgroup CPU quota (v2 `cpu.max`, v1 `cpu.cfs_quota_us / cpu.cfs_period_us`) and the CPU affinity mask.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

_CGROUP_ROOT = Path("/sys/fs/cgroup")


def _read(path: Path) -> str | None:
    try:
        return path.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None


def _own_cgroup_v2_dir(root: Path) -> Path:
    """The cgroup v2 folder of this process (`0::/path` of /proc/self/cgroup), or the root."""
    text = _read(Path("/proc/self/cgroup")) or ""
    for line in text.splitlines():
        if line.startswith("0::"):
            candidate = root / line[3:].lstrip("/")
            if (candidate / "cpu.max").exists():
                return candidate
    return root


def quota_from_cpu_max(text: str) -> float | None:
    """CPUs allowed by a cgroup v2 `cpu.max` line (`"200000 100000"` -> 2.0; `"max ..."` -> None)."""
    parts = text.split()
    if len(parts) != 2 or parts[0] == "max":
        return None
    try:
        quota, period = int(parts[0]), int(parts[1])
    except ValueError:
        return None
    return quota / period if quota > 0 and period > 0 else None


def quota_from_cfs(quota_text: str, period_text: str) -> float | None:
    """CPUs allowed by cgroup v1 `cpu.cfs_quota_us` and `cpu.cfs_period_us` (-1 quota -> None)."""
    try:
        quota, period = int(quota_text), int(period_text)
    except ValueError:
        return None
    return quota / period if quota > 0 and period > 0 else None


def cgroup_cpu_quota(root: Path = _CGROUP_ROOT) -> float | None:
    """CPUs allowed by this process's cgroup (v2, then v1), or None when unlimited or unknown."""
    cpu_max = _read(_own_cgroup_v2_dir(root) / "cpu.max")
    if cpu_max is not None:
        return quota_from_cpu_max(cpu_max)
    for folder in (root / "cpu", root / "cpu,cpuacct", root / "cpuacct,cpu"):
        quota, period = _read(folder / "cpu.cfs_quota_us"), _read(folder / "cpu.cfs_period_us")
        if quota is not None and period is not None:
            return quota_from_cfs(quota, period)
    return None


def affinity_cpus() -> int:
    """CPUs this process may be scheduled on (the affinity mask; os.cpu_count() where unknown)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def cpu_budget(root: Path = _CGROUP_ROOT) -> int:
    """Whole CPUs to plan threads for: min(cgroup quota rounded up, affinity), at least 1."""
    cpus = affinity_cpus()
    quota = cgroup_cpu_quota(root)
    if quota is not None:
        cpus = min(cpus, max(1, math.ceil(quota)))
    return cpus
