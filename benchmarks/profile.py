"""`fishloc bench profile`: where the time of one frame goes, by a sampling profiler (pyinstrument).

Runs `Pipeline.detect` (built as `fishloc serve` builds it) over the benchmark frames under
pyinstrument and prints the call tree; `--html` also writes the interactive view. pyinstrument is a
development tool (`pip install 'fishloc[dev]'`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames-to-profile", type=int, default=60, help="frames to run (default 60)")
    parser.add_argument("--html", type=Path, default=None, help="also write pyinstrument's HTML view here")
    parser.add_argument("--interval-ms", type=float, default=1.0, help="sampling interval (default 1 ms)")


def run(args: argparse.Namespace) -> int:
    try:
        from pyinstrument import Profiler
    except ImportError:
        print("fishloc bench profile needs pyinstrument: pip install 'fishloc[dev]'", file=sys.stderr)
        return 2
    from benchmarks.cli import bench_frames
    from benchmarks.inprocess import service_pipeline
    from fisheye import load_camera
    from service.core.cpu import cpu_budget

    camera = load_camera(args.camera)
    frames = bench_frames(args, lambda message: print(f"[bench] {message}", file=sys.stderr))
    pipeline = service_pipeline(args.model, args.threads or cpu_budget())
    for index in range(args.warmup):
        pipeline.detect(frames.data[index % len(frames)], camera)
    profiler = Profiler(interval=args.interval_ms / 1e3)
    with profiler:
        for index in range(args.frames_to_profile):
            pipeline.detect(frames.data[index % len(frames)], camera)
    print(profiler.output_text(unicode=True, color=False, show_all=False))
    if args.html is not None:
        args.html.write_text(profiler.output_html(), encoding="utf-8")
        print(f"HTML view: {args.html}")
    return 0
