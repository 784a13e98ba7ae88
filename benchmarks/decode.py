"""JPEG decoding, TurboJPEG against OpenCV, at the scale the service decodes a camera's frames.

    python -m benchmarks.decode --frames data/bench2952 --frames data/bench2048 --frames data/bench1080 \\
        --budget 900000 --budget 4000000 --runs 200 --json decode.json

For each folder of frames (one camera's size) and each view budget (`fishloc serve
--max-view-pixels`), the shipped model's plan gives the reduced size the frames are decoded at
(`contract.min_decoded_side`); both decoders then decode every frame at that size, interleaved
frame by frame so that the machine's load hits them alike, and the pixels are checked equal.
Times are this machine's (named in the output): compare rows of one run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import simplejpeg

from benchmarks.frames import load_frames
from benchmarks.machine import machine_info
from benchmarks.stats import summarize
from contract import OnnxModel, SessionThreads, min_decoded_side
from fisheye import load_camera
from fisheye.view_plan import ViewPlanConfig
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH
from service.frame_decode import DecodedFrame, decode_frame, decode_with_opencv, pick_reduction, read_header


def _time_ms(call: Callable[..., object], *args: object) -> tuple[float, object]:
    start = time.perf_counter()
    result = call(*args)
    return (time.perf_counter() - start) * 1e3, result


def measure(folder: str, budget: int, runs: int, model: OnnxModel) -> dict[str, object]:
    """Both decoders on the frames of `folder` at the size a view of `budget` px decodes them."""
    frames = load_frames(folder)
    camera = load_camera(DEMO_CAMERA_PATH).scaled_to((frames.width, frames.height))
    side = min_decoded_side(model.info, camera, ViewPlanConfig(max_pixels=budget))
    headers = [read_header(data) for data in frames.data]
    reduction = pick_reduction(headers[0].size_wh, side)
    samples: dict[str, list[float]] = {"opencv": [], "turbojpeg": []}
    for run in range(runs):
        data, header = frames.data[run % len(frames.data)], headers[run % len(frames.data)]
        turbo_ms, turbo = _time_ms(decode_frame, data, side, 10**9, header)
        opencv_ms, opencv = _time_ms(decode_with_opencv, data, header, reduction)
        assert isinstance(turbo, DecodedFrame) and isinstance(opencv, np.ndarray)
        if not np.array_equal(turbo.rgb, opencv):
            raise SystemExit(f"{folder}: the decoders disagree on frame {run % len(frames.data)}")
        samples["turbojpeg"].append(turbo_ms)
        samples["opencv"].append(opencv_ms)
    summaries = {name: summarize(values[min(10, runs // 10):]).as_dict() for name, values in samples.items()}
    return {"frames": folder, "frame_wh": [frames.width, frames.height], "budget": budget,
            "reduction": reduction, "decoded_wh": [frames.width // reduction, frames.height // reduction],
            "ms": summaries, "p50_ratio": summaries["turbojpeg"]["p50"] / summaries["opencv"]["p50"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.decode", description=__doc__.split("\n")[0])
    parser.add_argument("--frames", action="append", required=True, help="folder of frames of one size")
    parser.add_argument("--budget", action="append", type=int, metavar="PIXELS",
                        help="view budget in px (default: the service's)")
    parser.add_argument("--runs", type=int, default=200, help="decodes per decoder and row (default 200)")
    parser.add_argument("--model", default=str(DEFAULT_MODEL_PATH), help="model whose plan sets the size")
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args(argv)
    if args.runs < 20:
        parser.error("--runs must be at least 20")
    model = OnnxModel(args.model, SessionThreads(intra_op=1))
    machine = machine_info()
    print(f"machine: {machine.line()}; simplejpeg {simplejpeg.__version__}")
    print("| frames | budget | decoded at | OpenCV p50 / p95 / p99 | TurboJPEG p50 / p95 / p99 | p50 ratio |")
    print("|---|---|---|---|---|---|")
    rows = []
    for folder in args.frames:
        for budget in args.budget or [ViewPlanConfig().max_pixels]:
            row = measure(folder, budget, args.runs, model)
            rows.append(row)
            ms = row["ms"]
            assert isinstance(ms, dict)
            cells = [" / ".join(f"{ms[name][key]:.1f}" for key in ("p50", "p95", "p99"))
                     for name in ("opencv", "turbojpeg")]
            frame_wh = row["frame_wh"]
            assert isinstance(frame_wh, list)
            print(f"| {frame_wh[0]}x{frame_wh[1]} | {budget} | 1/{row['reduction']} | {cells[0]} | "
                  f"{cells[1]} | {row['p50_ratio']:.2f} |")
            sys.stdout.flush()
    if args.json:
        args.json.write_text(json.dumps({"machine": machine.line(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
