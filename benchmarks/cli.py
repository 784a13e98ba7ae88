"""`fishloc bench`: latency and throughput of the service on realistic frames, with a budget check.

`fishloc bench` runs the three sections (in process, HTTP, gRPC streams) and exits non-zero when the
one-client HTTP p95 passes `--budget-ms`; `fishloc bench sweep` times models of several input sizes
and precisions (and their AP50 where an eval set and `fishloc eval` are at hand); `fishloc bench
profile` shows where a frame's time goes.
"""

from __future__ import annotations

import argparse
import datetime as dt
import gc
import sys
from pathlib import Path
from typing import Any

from benchmarks.frames import (
    FrameSet,
    FrameSpec,
    load_frames,
    make_frames,
    make_synth_frames,
    synth_available,
)
from benchmarks.grpc_streams import grpc_unavailable_reason, stream_cameras
from benchmarks.http_load import concurrent_clients, single_client
from benchmarks.machine import load_average, machine_info, model_description
from benchmarks.report import (
    budget_verdict,
    check_report,
    format_table,
    targets,
    unavailable,
    write_report,
)
from benchmarks.server_process import ServerProcess
from benchmarks.stats import overhead_pct
from contract import ModelError, OnnxModel, SessionThreads
from fisheye import FisheyeCamera, load_camera
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH
from service.core.cpu import cpu_budget

SECTION_CHOICES = ("in-process", "http", "grpc")


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", type=Path, default=DEFAULT_MODEL_PATH,
                        help="ONNX model (default: the shipped default model)")
    parser.add_argument("--frames", type=Path, metavar="DIR",
                        help="folder of JPEG/PNG frames of one size (default: 2952×2952 frames rendered once "
                             "and cached under ~/.cache/fishloc/bench-frames, see --renderer)")
    parser.add_argument("--renderer", choices=("synth", "procedural"), default=None,
                        help="what makes the frames when no --frames is given: `fishloc synth` (the "
                             "default where this checkout has it) or the procedural generator "
                             "(benchmarks/frames.py)")
    parser.add_argument("--frame-size", type=int, default=2952, help="side of the rendered frames (px)")
    parser.add_argument("--frame-count", type=int, default=6, help="number of rendered frames")
    parser.add_argument("--camera", type=Path, default=DEMO_CAMERA_PATH,
                        help="camera file of the frames (default: the demo camera, scaled to the frames)")
    parser.add_argument("--runs", type=int, default=100, help="timed frames per measurement (default 100)")
    parser.add_argument("--warmup", type=int, default=10, help="untimed frames first (default 10)")
    parser.add_argument("--threads", type=int, default=None,
                        help="service threads (default: the CPU quota, as `fishloc serve`)")
    parser.add_argument("--clients", type=int, default=4, help="concurrent HTTP clients (default 4)")
    parser.add_argument("--streams", type=int, default=8, help="gRPC camera streams (default 8)")
    parser.add_argument("--fps", type=float, default=3.0, help="frames per second per stream (default 3)")
    parser.add_argument("--duration", type=float, default=15.0, help="gRPC streaming seconds (default 15)")
    parser.add_argument("--stream-warmup", type=float, default=3.0,
                        help="first seconds of streaming left out of the figures (default 3)")
    parser.add_argument("--sections", default=",".join(SECTION_CHOICES),
                        help="comma-separated sections to run (default: in-process,http,grpc)")
    parser.add_argument("--budget-ms", type=float, default=100.0,
                        help="exit 1 when the one-client HTTP p95 is above this (default 100)")
    parser.add_argument("--json", type=Path, default=Path("bench-report.json"),
                        help="where to write the JSON report (default bench-report.json)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__.split("\n\n")[1].replace("\n", " ") if __doc__ else None
    add_run_arguments(parser)
    commands = parser.add_subparsers(dest="mode", metavar="{sweep,profile}")
    from benchmarks import profile, sweep

    sweep.add_arguments(commands.add_parser("sweep", help="latency (and AP50) per input size and precision"))
    profile.add_arguments(commands.add_parser("profile", help="where a frame's time goes (pyinstrument)"))


def bench_frames(args: argparse.Namespace, progress: Any = print) -> FrameSet:
    if args.frames is not None:
        return load_frames(args.frames)
    spec = FrameSpec(size=args.frame_size, count=args.frame_count)
    renderer = args.renderer or ("synth" if synth_available() else "procedural")
    if renderer == "synth":
        progress(f"frames: {spec.count} unseen {spec.size}×{spec.size} scenes by `fishloc synth` "
                 "(rendered once, then cached; minutes on 2 cores)")
        return load_frames(make_synth_frames(spec, camera_path=args.camera))
    progress(f"frames: rendering/caching {spec.count} procedural {spec.size}×{spec.size} JPEGs ({spec.key})")
    return load_frames(make_frames(spec))


def frames_description(frames: FrameSet) -> dict[str, object]:
    sizes = frames.byte_sizes
    return {"folder": frames.folder, "count": len(frames), "width": frames.width, "height": frames.height,
            "names": list(frames.names), "bytes": sizes, "bytes_min": min(sizes), "bytes_max": max(sizes),
            "bytes_mean": sum(sizes) / len(sizes)}


def _sections(text: str) -> set[str]:
    chosen = {s.strip() for s in text.split(",") if s.strip()}
    unknown = chosen - set(SECTION_CHOICES)
    if unknown:
        raise ValueError(f"unknown sections {sorted(unknown)}; choose from {', '.join(SECTION_CHOICES)}")
    return chosen


def run_benchmark(args: argparse.Namespace, progress: Any = print) -> dict[str, Any]:
    """Run the chosen sections and return the report (see benchmarks.report)."""
    sections = _sections(args.sections)
    threads = args.threads or cpu_budget()
    camera: FisheyeCamera = load_camera(args.camera)
    frames = bench_frames(args, progress)
    sizes = ", ".join(f"{s / 1e6:.2f}" for s in frames.byte_sizes)
    progress(f"frames: {len(frames)} × {frames.width}×{frames.height} from {frames.folder}: {sizes} MB")
    info = OnnxModel(args.model, SessionThreads(1)).info
    machine = machine_info(threads)
    report: dict[str, Any] = {
        "schema": "fishloc-bench/1",
        "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "command": ["fishloc", "bench", *sys.argv[2:]] if sys.argv[1:2] == ["bench"] else sys.argv,
        "machine": dict(machine.as_dict(), summary=machine.line()),
        "model": model_description(info, args.model),
        "frames": frames_description(frames),
        "settings": {"runs": args.runs, "warmup": args.warmup, "threads": threads, "clients": args.clients,
                     "streams": args.streams, "fps": args.fps, "duration_s": args.duration,
                     "stream_warmup_s": args.stream_warmup, "camera": str(args.camera)},
        "sections": {},
    }
    progress(f"machine: {machine.line()}")
    if "in-process" in sections:
        from benchmarks.inprocess import run_in_process

        result = run_in_process(args.model, frames, camera, threads, args.runs, args.warmup, progress)
        report["sections"]["in_process"] = result.as_dict()
        gc.collect()
    else:
        report["sections"]["in_process"] = unavailable("not requested (--sections)")
    report["sections"].update(_server_sections(args, sections, camera, frames, threads, progress))
    floor = report["sections"]["in_process"].get("floor_decode_plus_inference_p50_ms")
    http = report["sections"]["http"]
    if http.get("available"):
        p50 = http["single"]["latency_ms"]["p50"] if http["single"]["latency_ms"] else None
        http["overhead_pct_over_decode_plus_inference"] = (
            overhead_pct(p50, floor) if p50 is not None and floor is not None else None)
    report["machine"]["load_average_end"] = load_average()
    verdict = budget_verdict(report, args.budget_ms)
    report["budget"] = verdict.as_dict()
    report["targets"] = targets(report)
    return report


def _server_sections(args: argparse.Namespace, sections: set[str], camera: FisheyeCamera, frames: FrameSet,
                     threads: int, progress: Any) -> dict[str, dict[str, object]]:
    out: dict[str, dict[str, object]] = {}
    grpc_reason = grpc_unavailable_reason() if "grpc" in sections else "not requested (--sections)"
    if "http" not in sections and grpc_reason is not None:
        return {"http": unavailable("not requested (--sections)"), "grpc": unavailable(grpc_reason)}
    stream_ids = [f"bench-{index:02d}" for index in range(args.streams)]
    server = ServerProcess(args.model, camera, ["bench", *stream_ids], args.threads, grpc=grpc_reason is None)
    progress(f"server: {' '.join(server.command)}")
    try:
        server.start()
    except (RuntimeError, TimeoutError) as error:
        reason = f"fishloc serve did not start: {error}"
        return {"http": unavailable(reason), "grpc": unavailable(grpc_reason or reason)}
    try:
        if "http" in sections:
            progress(f"HTTP: 1 client, {args.warmup} warm-up + {args.runs} frames")
            single = single_client(server.url, "bench", frames, args.runs, args.warmup)
            concurrent = None
            if args.clients > 1:
                progress(f"HTTP: {args.clients} concurrent clients, {args.runs} frames in all")
                concurrent = concurrent_clients(server.url, "bench", frames, args.clients, args.runs)
            out["http"] = {"available": True, "url": server.url, "single": single.as_dict(),
                           "concurrent": None if concurrent is None else concurrent.as_dict()}
        else:
            out["http"] = unavailable("not requested (--sections)")
        if grpc_reason is None:
            progress(f"gRPC: {args.streams} streams × {args.fps:g} fps for {args.duration:g} s")
            load = stream_cameras(f"127.0.0.1:{server.grpc_port}", stream_ids, frames, args.fps,
                                  args.duration, args.stream_warmup)
            out["grpc"] = load.as_dict()
        else:
            out["grpc"] = unavailable(grpc_reason)
    finally:
        server.stop()
    return out


def run(args: argparse.Namespace) -> int:
    if args.mode == "sweep":
        from benchmarks import sweep

        return sweep.run(args)
    if args.mode == "profile":
        from benchmarks import profile

        return profile.run(args)

    def progress(message: str) -> None:
        print(f"[bench] {message}", file=sys.stderr, flush=True)

    try:
        report = run_benchmark(args, progress)
    except (ModelError, ValueError, OSError) as error:
        hint = ""
        if args.model == DEFAULT_MODEL_PATH and not args.model.exists():
            hint = " (the shipped default model is missing: make it with `fishloc export`, or pass --model)"
        print(f"fishloc bench: {error}{hint}", file=sys.stderr)
        return 2
    problems = check_report(report)
    if problems:
        print(f"fishloc bench: the report is malformed: {problems}", file=sys.stderr)
        return 2
    write_report(report, args.json)
    print(format_table(report))
    print(f"\nJSON report: {args.json}")
    return budget_verdict(report, args.budget_ms).exit_code
