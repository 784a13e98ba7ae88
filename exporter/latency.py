"""Latency of an exported model in onnxruntime (what the FP32-vs-INT8 decision is based on).

    python -m exporter.latency models/fishloc-default.onnx other.onnx --threads 2 --runs 100

Times `session.run` alone on one letterboxed frame (batch 1), after warm-up, and prints p50/p95 in
milliseconds per model as JSON lines.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from contract import OnnxModel, SessionThreads
from exporter.parity import synthetic_parity_frames


def measure_latency_ms(model: str | Path, threads: int, runs: int, warmup: int = 10) -> dict[str, float]:
    onnx_model = OnnxModel(model, SessionThreads(intra_op=threads))
    width, height = onnx_model.info.input_wh
    frame = synthetic_parity_frames(height, count=1, seed=11, width=width)
    for _ in range(warmup):
        onnx_model.run_batch(frame)
    samples = []
    for _ in range(runs):
        started = time.perf_counter()
        onnx_model.run_batch(frame)
        samples.append((time.perf_counter() - started) * 1000.0)
    values = np.asarray(samples)
    return {"p50_ms": float(np.percentile(values, 50)), "p95_ms": float(np.percentile(values, 95)),
            "mean_ms": float(values.mean()), "runs": float(runs), "threads": float(threads),
            "input_size": float(height)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("models", nargs="+")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--runs", type=int, default=100)
    args = parser.parse_args()
    for model in args.models:
        print(json.dumps({"model": model, **measure_latency_ms(model, args.threads, args.runs)}))


if __name__ == "__main__":
    main()
