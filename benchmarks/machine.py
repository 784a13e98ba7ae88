"""What a figure was measured on: CPU, cores and quota, load, library versions, the model."""

from __future__ import annotations

import os
import platform
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort

from contract import ModelInfo
from service.core.cpu import affinity_cpus, cgroup_cpu_quota, cpu_budget


def cpu_model_name(cpuinfo: str | None = None) -> str:
    """The CPU's model name from /proc/cpuinfo (`model name`, else `Hardware`/`Processor`), or the
    platform's processor string."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
        except OSError:
            cpuinfo = ""
    for key in ("model name", "Hardware", "Processor", "cpu model"):
        match = re.search(rf"^{re.escape(key)}\s*:\s*(.+)$", cpuinfo, flags=re.MULTILINE)
        if match:
            return match.group(1).strip()
    return platform.processor() or platform.machine() or "unknown"


def _opencv_jpeg_library() -> str:
    for line in cv2.getBuildInformation().splitlines():
        if line.strip().startswith("JPEG:"):
            return line.split(":", 1)[1].strip()
    return "unknown"


@dataclass(frozen=True)
class MachineInfo:
    cpu_model: str
    logical_cpus: int
    affinity_cpus: int
    cgroup_cpu_quota: float | None
    service_threads: int
    load_average: tuple[float, float, float] | None
    python: str
    platform: str
    onnxruntime: str
    opencv: str
    opencv_jpeg: str
    numpy: str

    def as_dict(self) -> dict[str, object]:
        return asdict(self)

    def line(self) -> str:
        quota = "none" if self.cgroup_cpu_quota is None else f"{self.cgroup_cpu_quota:g}"
        load = "?" if self.load_average is None else " ".join(f"{v:.2f}" for v in self.load_average)
        return (f"{self.cpu_model}, {self.logical_cpus} logical CPUs (affinity {self.affinity_cpus}, "
                f"cgroup quota {quota}), load {load}; onnxruntime {self.onnxruntime}, OpenCV {self.opencv} "
                f"({self.opencv_jpeg}), Python {self.python}")


def load_average() -> tuple[float, float, float] | None:
    try:
        one, five, fifteen = os.getloadavg()
    except OSError:
        return None
    return one, five, fifteen


def machine_info(service_threads: int | None = None) -> MachineInfo:
    return MachineInfo(
        cpu_model=cpu_model_name(),
        logical_cpus=os.cpu_count() or 1,
        affinity_cpus=affinity_cpus(),
        cgroup_cpu_quota=cgroup_cpu_quota(),
        service_threads=cpu_budget() if service_threads is None else service_threads,
        load_average=load_average(),
        python=platform.python_version(),
        platform=platform.platform(),
        onnxruntime=ort.__version__,
        opencv=cv2.__version__,
        opencv_jpeg=_opencv_jpeg_library(),
        numpy=np.__version__,
    )


def model_description(info: ModelInfo, path: str | Path) -> dict[str, object]:
    """The model fields of a report: file, name, version, input size, trained_on, sha256."""
    return {"path": str(path), "name": info.name, "version": info.version, "input_size": info.input_size,
            "trained_on": info.trained_on, "sha256": info.sha256}
