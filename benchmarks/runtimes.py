"""`python -m benchmarks.runtimes`: the model's network in onnxruntime against OpenVINO's CPU runtime.

The service runs its graph in onnxruntime. OpenVINO (`pip install openvino`; not a dependency of
FishLoc) is the other mature CPU runtime for such graphs, with bf16 kernels on CPUs that have them.
This times both on the same inputs, interleaved run by run with a pause before each run (so that
neither runtime's idle threads take the cores from the other's run), and reports p50 / p95 / p99,
each runtime's ratio to onnxruntime's p50 and how far its candidate scores are from onnxruntime's:

    pip install openvino
    python -m benchmarks.runtimes --model models/fishloc-default.onnx --runs 40 --json runtimes.json

Both run the network up to its candidates (`network_graph`: every cell's box, foot and score, before
the graph's top-K): OpenVINO 2026.4 refuses the graph's GatherElements, whose indices are narrower
than their data on an axis other than the gathered one (ONNX allows it). The cost of what is cut is
the same small share in either runtime. The default inputs are the shipped view's: the default
strip (416 x 1792), the two-band canvas (960 x 1888) and the nadir view (384 x 384).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from benchmarks.machine import machine_info
from benchmarks.stats import summarize
from contract import SessionThreads
from contract.model import session_options

DEFAULT_INPUTS = ("416x1792", "960x1888", "384x384")
WARM_UP_RUNS = 3
# A pause before each timed run: a runtime's pool threads may spin on after its run returns
# (OpenVINO's do), and run back to back they take the cores from the next runtime's run.
PAUSE_S = 0.05
Runner = Callable[[NDArray[np.uint8]], list[NDArray[Any]]]  # an input (1, H, W, 3) -> the graph's outputs


def network_graph(model_path: str | Path) -> bytes:
    """The model's graph cut to its candidates: the data its GatherElements gather from and the scores
    its TopK ranks (`onnx.utils.Extractor`). ValueError for a graph without them."""
    import onnx
    from onnx.utils import Extractor

    model = onnx.load(str(model_path))
    gathered = [node.input[0] for node in model.graph.node if node.op_type == "GatherElements"]
    ranked = [node.input[0] for node in model.graph.node if node.op_type == "TopK"]
    if not gathered or len(ranked) != 1:
        raise ValueError(f"{model_path}: no candidates to cut at (GatherElements and one TopK)")
    cut = Extractor(model).extract_model([model.graph.input[0].name], [*gathered, *ranked])
    return bytes(cut.SerializeToString())


def openvino_runners(graph: bytes, threads: int) -> dict[str, Runner]:
    """OpenVINO's CPU runtime on `graph` at each precision this CPU offers (f32, and bf16 where it has
    bf16 kernels), latency-tuned on `threads` threads. ImportError when OpenVINO is not installed."""
    import openvino as ov

    core = ov.Core()
    model = core.read_model(graph, b"")
    capabilities = core.get_property("CPU", "OPTIMIZATION_CAPABILITIES")
    runners: dict[str, Runner] = {}
    for precision in ["f32"] + (["bf16"] if "BF16" in capabilities else []):
        settings = {"PERFORMANCE_HINT": "LATENCY", "INFERENCE_NUM_THREADS": threads,
                    "INFERENCE_PRECISION_HINT": precision}
        request = core.compile_model(model, "CPU", settings).create_infer_request()

        def run(image: NDArray[np.uint8], request: Any = request) -> list[NDArray[Any]]:
            return [np.asarray(out) for out in request.infer({0: image}).values()]

        runners[f"openvino {precision}"] = run
    return runners


def onnxruntime_runner(graph: bytes, threads: int) -> Runner:
    """onnxruntime's CPU session on `graph` as the service makes one for a frame alone on the model:
    `threads` threads whose pools spin (`contract.model.session_options`)."""
    options = session_options(SessionThreads(intra_op=threads), spinning=True, intra_op=threads)
    session = ort.InferenceSession(graph, options, providers=["CPUExecutionProvider"])
    return lambda image: [np.asarray(out) for out in session.run(None, {session.get_inputs()[0].name: image})]


def block_image(height: int, width: int, seed: int = 0) -> NDArray[np.uint8]:
    """(1, height, width, 3) uint8: blocks of 16 px of random colour, an input with edges to find."""
    shape = (1, -(-height // 16), -(-width // 16), 3)
    blocks = np.random.default_rng(seed).integers(0, 256, shape, dtype=np.uint8)
    return np.ascontiguousarray(np.repeat(np.repeat(blocks, 16, axis=1), 16, axis=2)[:, :height, :width])


def compare(runners: dict[str, Runner], image: NDArray[np.uint8], runs: int) -> dict[str, dict[str, Any]]:
    """Each runner timed on `image` `runs` times, interleaved, after warm-up: its summary in ms, its
    p50 over the first runner's, and its largest score difference from the first runner's."""
    scores = {name: runner(image)[-1] for name, runner in runners.items()}  # the first warm-up run
    reference = next(iter(scores.values()))
    times: dict[str, list[float]] = {name: [] for name in runners}
    for run in range(1, WARM_UP_RUNS + runs):
        for name, runner in runners.items():
            time.sleep(PAUSE_S)
            start = time.perf_counter()
            runner(image)
            if run >= WARM_UP_RUNS:
                times[name].append((time.perf_counter() - start) * 1000)
    summaries = {name: summarize(ms) for name, ms in times.items()}
    base = next(iter(summaries.values())).p50
    return {name: {**summary.as_dict(), "ratio_p50": summary.p50 / base,
                   "max_score_difference": float(np.abs(scores[name] - reference).max())}
            for name, summary in summaries.items()}


def parse_size(text: str) -> tuple[int, int]:
    """'HxW' -> (H, W), each a positive multiple of 32."""
    try:
        height, width = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"an input size is HxW, got {text!r}") from None
    if height <= 0 or width <= 0 or height % 32 or width % 32:
        raise argparse.ArgumentTypeError(f"an input's sides must be positive multiples of 32, got {text!r}")
    return height, width


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.runtimes", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True, help="a planned FishLoc ONNX model")
    parser.add_argument("--input", type=parse_size, action="append", default=None,
                        help=f"an input size HxW (repeat; default {', '.join(DEFAULT_INPUTS)})")
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.runs < 1 or args.threads < 1:
        parser.error("--runs and --threads must be at least 1")
    try:
        graph = network_graph(args.model)
        runners = {"onnxruntime": onnxruntime_runner(graph, args.threads)}
    except (OSError, ValueError, RuntimeError) as error:  # onnx and onnxruntime raise these for bad files
        print(f"benchmarks.runtimes: {error}", file=sys.stderr)
        return 2
    try:
        runners |= openvino_runners(graph, args.threads)
        from openvino import __version__ as openvino_version
    except ImportError:
        print("benchmarks.runtimes: OpenVINO is not installed (pip install openvino)", file=sys.stderr)
        return 2
    results: dict[str, Any] = {"machine": machine_info().as_dict(), "openvino": openvino_version,
                               "model": args.model, "inputs": {}}
    for height, width in args.input or [parse_size(size) for size in DEFAULT_INPUTS]:
        found = compare(runners, block_image(height, width), args.runs)
        results["inputs"][f"{height}x{width}"] = found
        for name, row in found.items():
            print(f"{height}x{width} {name}: p50 {row['p50']:.1f} p95 {row['p95']:.1f} "
                  f"p99 {row['p99']:.1f} ms ({row['ratio_p50']:.2f}x), "
                  f"scores within {row['max_score_difference']:.1e}", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
