"""`fishloc bench sweep`: latency against accuracy over input sizes and precisions.

Each model (an ONNX export at some input size, FP32 or INT8) is timed in process on the same frames,
interleaved frame by frame with the others: `Pipeline.detect` whole (the service's code path) and
inference alone, in wall-clock and in process CPU time (which other processes' load inflates less).
With `--eval-data ANN.json` (unseen synthetic scenes) each model is also scored by `fishloc eval`
(AP50), when this checkout has that command; otherwise the AP50 column says why not.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks.checkout import checkout_env, source_root
from benchmarks.frames import bench_frames
from benchmarks.stats import Summary, summarize

QUANTIZED_OPS = frozenset({"QuantizeLinear", "DequantizeLinear", "QLinearConv", "ConvInteger"})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--models", type=Path, nargs="+", required=True,
                        help="ONNX models to compare (e.g. exports at 512/768/1024, FP32 and INT8)")
    parser.add_argument("--eval-data", type=Path, default=None,
                        help="annotations.json of unseen scenes for `fishloc eval` (AP50)")
    parser.add_argument("--sweep-json", type=Path, default=Path("bench-sweep.json"),
                        help="where to write the sweep's JSON (default bench-sweep.json)")


def precision_of(model_path: Path) -> str:
    """"int8" when the graph holds quantisation operators, else "fp32" (reads the graph with `onnx`)."""
    try:
        import onnx
    except ImportError:
        return "int8" if "int8" in model_path.name.lower() else "fp32"
    graph = onnx.load(str(model_path), load_external_data=False).graph
    return "int8" if any(node.op_type in QUANTIZED_OPS for node in graph.node) else "fp32"


@dataclass(frozen=True)
class SweepRow:
    model: str
    name: str
    version: str
    input_size: int
    precision: str
    pipeline_ms: Summary
    inference_ms: Summary
    pipeline_cpu_ms: Summary
    inference_cpu_ms: Summary
    ap50: float | None
    ap50_note: str

    def as_dict(self) -> dict[str, Any]:
        return {"model": self.model, "name": self.name, "version": self.version,
                "input_size": self.input_size, "precision": self.precision,
                "pipeline_ms": self.pipeline_ms.as_dict(), "inference_ms": self.inference_ms.as_dict(),
                "pipeline_cpu_ms": self.pipeline_cpu_ms.as_dict(),
                "inference_cpu_ms": self.inference_cpu_ms.as_dict(),
                "ap50": self.ap50, "ap50_note": self.ap50_note}


def evaluate_ap50(model: Path, eval_data: Path | None) -> tuple[float | None, str]:
    """AP50 of `model` on `eval_data` by `fishloc eval`, or None and the reason it is not measured."""
    from service.cli import COMMANDS

    if eval_data is None:
        return None, "no --eval-data given"
    if "eval" not in COMMANDS:
        return None, "`fishloc eval` is not in this checkout (detector branch not merged)"
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "eval.json"
        command = [sys.executable, "-m", "service.cli", "eval", "--model", str(model.resolve()),
                   "--data", str(eval_data.resolve()), "--json", str(out)]
        done = subprocess.run(command, capture_output=True, text=True, check=False, cwd=source_root(),
                              env=checkout_env())
        if done.returncode != 0 or not out.exists():
            return None, f"fishloc eval failed ({done.returncode}): {done.stderr.strip()[-300:]}"
        metrics = json.loads(out.read_text(encoding="utf-8"))
    return float(metrics["AP50"]), f"fishloc eval on {eval_data}"


def run(args: argparse.Namespace) -> int:
    from benchmarks.inprocess import service_pipeline
    from benchmarks.machine import machine_info
    from contract import run_view
    from fisheye import load_camera
    from service.core.cpu import cpu_budget

    threads = args.threads or cpu_budget()
    camera = load_camera(args.camera)
    frames = bench_frames(args, lambda message: print(f"[bench] {message}", file=sys.stderr))
    pipelines = [service_pipeline(path, threads) for path in args.models]
    inputs = []
    for pipeline in pipelines:
        from benchmarks.inprocess import NaivePipeline

        inputs.append(NaivePipeline.full_decode_input(frames.data[0], pipeline, camera)[:2])
    whole: list[list[float]] = [[] for _ in pipelines]
    alone: list[list[float]] = [[] for _ in pipelines]
    whole_cpu: list[list[float]] = [[] for _ in pipelines]
    alone_cpu: list[list[float]] = [[] for _ in pipelines]
    print(f"[bench] sweep: {len(pipelines)} models × ({args.warmup} warm-up + {args.runs}) frames, "
          "interleaved", file=sys.stderr)
    for index in range(args.warmup + args.runs):
        data = frames.data[index % len(frames)]
        for slot, pipeline in enumerate(pipelines):
            start, start_cpu = time.perf_counter(), time.process_time()
            pipeline.detect(data, camera)
            middle, middle_cpu = time.perf_counter(), time.process_time()
            run_view(pipeline.model, *inputs[slot])
            end, end_cpu = time.perf_counter(), time.process_time()
            if index >= args.warmup:
                whole[slot].append((middle - start) * 1e3)
                alone[slot].append((end - middle) * 1e3)
                whole_cpu[slot].append((middle_cpu - start_cpu) * 1e3)
                alone_cpu[slot].append((end_cpu - middle_cpu) * 1e3)
    rows = []
    for slot, (path, pipeline) in enumerate(zip(args.models, pipelines, strict=True)):
        ap50, note = evaluate_ap50(path, args.eval_data)
        info = pipeline.info
        rows.append(SweepRow(str(path), info.name, info.version, info.input_size, precision_of(path),
                             summarize(whole[slot]), summarize(alone[slot]), summarize(whole_cpu[slot]),
                             summarize(alone_cpu[slot]), ap50, note))
    machine = machine_info(threads)
    report = {"schema": "fishloc-bench-sweep/1", "machine": dict(machine.as_dict(), summary=machine.line()),
              "frames": {"folder": frames.folder, "count": len(frames), "width": frames.width,
                         "height": frames.height, "bytes": frames.byte_sizes},
              "runs": args.runs, "warmup": args.warmup, "threads": threads,
              "rows": [row.as_dict() for row in rows]}
    args.sweep_json.parent.mkdir(parents=True, exist_ok=True)
    args.sweep_json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"Machine: {machine.line()}")
    print(f"Frames: {len(frames)} × {frames.width}×{frames.height} from {frames.folder}\n")
    print("| model | input | precision | detect p50 | detect p95 | inference p50 | detect CPU p50 | "
          "inference CPU p50 | AP50 |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        ap = "—" if row.ap50 is None else f"{row.ap50:.3f}"
        print(f"| {Path(row.model).name} | {row.input_size} | {row.precision} | {row.pipeline_ms.p50:.1f} | "
              f"{row.pipeline_ms.p95:.1f} | {row.inference_ms.p50:.1f} | {row.pipeline_cpu_ms.p50:.1f} | "
              f"{row.inference_cpu_ms.p50:.1f} | {ap} |")
    notes = sorted({row.ap50_note for row in rows if row.ap50 is None})
    for note in notes:
        print(f"AP50 not measured: {note}")
    print(f"\nJSON: {args.sweep_json}")
    return 0
