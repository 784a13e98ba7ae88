"""The detector comparison of the README and the model card: one table from one script.

    python -m benchmarks.compare --model "0.1.0=v010.onnx" \\
        --model "zero-shot polar=models/fishloc-default.onnx" \\
        --baseline "12 rotations=rotations:models/pretrained/yolox_nano.onnx" \\
        --data real=../shared/real-frames/cepdof_lunch3.json --data r384=data/unseen384/annotations.json \\
        --data r1024=data/unseen1024/annotations.json --frames data/unseen2952 --json compare.json

Each model (a FishLoc ONNX file or training checkpoint) or zero-shot baseline (`rotations:ONNX`,
`letterbox:ONNX`, `tiled:ONNX`: any COCO file of `../shared/pretrained/`, `detector.baselines`)
is evaluated on every data set exactly as `fishloc eval` does (with two rows or more, each row's
`mPE_common` too: its feet over the people every row matches, `detector.metrics.common_errors`),
then timed on the frames of
`--frames` (encoded JPEGs of one size, as a camera sends them), or on those of an evaluation set,
each with its own camera (`--time-on ANNOTATIONS`: real frames of several scenes and lenses, as the
service would be sent them): *inference* is the model alone on
its own input (p50), *end to end* the whole path from the JPEG bytes to floor positions
(`service.pipeline.Pipeline.detect` for ONNX models, decode + predictor for the baselines, decode +
view + windows + selection for `tiled:`; p50 and p95), interleaved model by model so that the
machine's load hits them alike. Times are this machine's: compare rows of one run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from benchmarks.frames import FrameSet, load_frames
from benchmarks.machine import machine_info
from benchmarks.stats import summarize
from contract import (
    InputMapping,
    ModelRunner,
    OnnxModel,
    SessionThreads,
    min_decoded_side,
    run_view,
    view_inputs,
)
from contract.detect import ContractModel, FrameOutputs
from contract.metadata import OperatingPoint
from contract.model import SpinningPolicy
from contract.views import DEFAULT_VIEW
from detector.baselines import LetterboxPredictor, RotatedCropsPredictor, TiledCocoModel
from detector.data.readers import read_dataset
from detector.evaluate import Predictor, RunnerPredictor, evaluate, frame_camera, json_safe, load_predictor
from detector.metrics import common_errors, person_errors
from fisheye import FisheyeCamera, load_camera
from fisheye.view_plan import ViewPlanConfig
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH
from service.frame_decode import decode_frame, read_header
from service.pipeline import Pipeline, PipelineConfig

BASELINES: dict[str, Callable[[str, int], Predictor]] = {
    "rotations": lambda path, threads: RotatedCropsPredictor(path, threads=threads),
    "letterbox": lambda path, threads: LetterboxPredictor(path, threads=threads),
}
REAL_COLUMNS = ("AP50", "precision", "recall", "AP50_radius_aligned")
RENDER_COLUMNS = ("AP50", "mAP", "AP_near", "AP_mid", "AP_far", "mPE", "mPE_common")


@dataclass
class Entry:
    """One row: a name, how to predict for evaluation, and how to time a frame end to end."""

    name: str
    predictor: Predictor
    frame_ms: Callable[[bytes, FisheyeCamera], float]
    inference_ms: Callable[[bytes, FisheyeCamera], float] | None


def _timed(call: Callable[[], object]) -> float:
    start = time.perf_counter()
    call()
    return (time.perf_counter() - start) * 1e3


def _frame_inputs(model: ContractModel, view: ViewPlanConfig, data: bytes, camera: FisheyeCamera
                  ) -> tuple[list[np.ndarray], InputMapping, FisheyeCamera]:
    """The JPEG `data` of `camera` decoded as the service decodes it (reduced where the view
    allows), the model's inputs, their mapping and the camera at the frame's size."""
    frame_camera = camera.scaled_to(read_header(data).size_wh)
    frame = decode_frame(data, min_decoded_side(model.info, frame_camera, view), 40_000_000)
    return *view_inputs(model.info, frame.rgb, frame_camera, view), frame_camera


def _inference_timer(model: ContractModel, view: ViewPlanConfig) -> Callable[[bytes, FisheyeCamera], float]:
    """Times the model alone on a frame's inputs, made once per frame outside the timed call."""
    inputs: dict[bytes, tuple[list[np.ndarray], InputMapping]] = {}

    def inference_ms(data: bytes, camera: FisheyeCamera) -> float:
        if data not in inputs:
            inputs[data] = _frame_inputs(model, view, data, camera)[:2]
        images, mapping = inputs[data]
        return _timed(lambda: run_view(model, images, mapping))

    return inference_ms


def _onnx_entry(name: str, path: str, threads: int, view: ViewPlanConfig = DEFAULT_VIEW,
                spinning: SpinningPolicy = "off") -> Entry:
    model = OnnxModel(path, SessionThreads(intra_op=threads, spinning=spinning))
    pipeline = Pipeline(model, PipelineConfig(view=view))
    pipeline.warm_up()
    return Entry(name, RunnerPredictor(ModelRunner(model, view=view)),
                 lambda data, camera: _timed(lambda: pipeline.detect(data, camera)),
                 _inference_timer(model, view))


def _tiled_entry(name: str, spec: str, threads: int) -> Entry:
    """A COCO file read in windows on the default model's planned views (`TiledCocoModel`):
    `FILE[@PIXELS][,min_score=S][,nms_iou=I][,FIELD=VALUE...]`. End to end is the frame's decode
    (reduced as the service decodes), its view, the windows and the selection: the service's path
    without the floor positions the model has no foot output for."""
    file, _, view_text = spec.partition("@")
    fields = view_text.split(",") if view_text else []
    point = {k: float(v) for k, _, v in (f.partition("=") for f in fields) if k in ("min_score", "nms_iou")}
    rest = [f for f in fields if f.partition("=")[0] not in point]
    view = view_from_spec(",".join(rest)) if rest else DEFAULT_VIEW
    model = TiledCocoModel.like(file, DEFAULT_MODEL_PATH, threads,
                                OperatingPoint(point.get("min_score", 0.3), point.get("nms_iou", 0.5)))
    runner = ModelRunner(model, view=view)

    def frame_ms(data: bytes, camera: FisheyeCamera) -> float:
        def run() -> None:
            images, mapping, frame_camera = _frame_inputs(model, view, data, camera)
            runner.select([FrameOutputs(run_view(model, images, mapping), mapping,
                                        frame_camera.principal_point)], model.info.default_min_score)
        return _timed(run)

    return Entry(name, RunnerPredictor(runner), frame_ms, _inference_timer(model, view))


def _predictor_entry(name: str, predictor: Predictor) -> Entry:
    def frame_ms(data: bytes, camera: FisheyeCamera) -> float:
        def run() -> None:
            bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
            if bgr is None:
                raise ValueError("OpenCV cannot decode a timing frame")
            rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
            frame_camera = camera.scaled_to((rgb.shape[1], rgb.shape[0]))
            predictor.detect([rgb], [frame_camera], predictor.default_min_score)
        return _timed(run)

    return Entry(name, predictor, frame_ms, None)


def view_from_spec(text: str) -> ViewPlanConfig:
    """`PIXELS[,FIELD=VALUE...]` -> the default view plan with that budget and those numeric
    `ViewPlanConfig` fields (e.g. `1000000,nadir_scale=1.25`, `900000,second_look_patches=0`);
    ValueError naming a bad one."""
    pixels, *fields = text.split(",")
    changes: dict[str, float] = {}
    kinds = {f.name: float if f.type in ("float", "float | None") else int
             for f in dataclasses.fields(ViewPlanConfig) if f.type in ("float", "float | None", "int")}
    for field_text in fields:
        key, _, value = field_text.partition("=")
        if key not in kinds or key == "max_pixels":
            raise ValueError(f"{field_text!r}: not a numeric field of the view plan")
        changes[key] = kinds[key](value)
    return dataclasses.replace(DEFAULT_VIEW, max_pixels=int(pixels), **changes)  # type: ignore[arg-type]


# A model spec's field: its sessions' spinning policy, as `fishloc serve --onnx-spinning` sets it.
SPINNING = "onnx_spinning="


def build_entry(name: str, spec: str, threads: int) -> Entry:
    """`spec` is an ONNX file (`FILE@PIXELS`: a planned model's views within PIXELS, as `fishloc
    serve --max-view-pixels`; `FILE@PIXELS,nadir_scale=1.25`: other fields of the plan too;
    `FILE@PIXELS,onnx_spinning=on`: its sessions' spinning policy, as `fishloc serve
    --onnx-spinning` sets it; "off" otherwise), a checkpoint, or `KIND:ONNX` for a zero-shot
    baseline. Timing runs one frame at a time, so "alone" times as "on" does."""
    kind, _, path = spec.partition(":")
    if kind == "tiled" and path:
        return _tiled_entry(name, path, threads)
    if kind in BASELINES and path:
        return _predictor_entry(name, BASELINES[kind](path, threads))
    file, _, view_text = spec.partition("@")
    fields = view_text.split(",") if view_text else []
    plan = [field for field in fields if not field.startswith(SPINNING)]
    # an unknown policy is a ValueError of SessionThreads, naming the policies
    spinning = cast(SpinningPolicy, next(
        (field.removeprefix(SPINNING) for field in fields if field.startswith(SPINNING)), "off"))
    if Path(file).suffix.lower() == ".onnx":
        return _onnx_entry(name, file, threads, view_from_spec(",".join(plan)) if plan else DEFAULT_VIEW,
                           spinning=spinning)
    return _predictor_entry(name, load_predictor(spec, threads=threads))


def timing_frames(frames: FrameSet, camera: FisheyeCamera) -> list[tuple[bytes, FisheyeCamera]]:
    """`--frames`: each encoded frame with the one camera they were all taken with."""
    return [(data, camera) for data in frames.data]


def set_frames(path: str) -> list[tuple[bytes, FisheyeCamera]]:
    """`--time-on`: the frames of an evaluation set, each with its own camera (the set's, or the
    one `fishloc eval` assumes for a frame without), as the service would be sent them."""
    return [(frame.path.read_bytes(), frame_camera(frame)) for frame in read_dataset(path)]


def measure_times(entries: list[Entry], frames: list[tuple[bytes, FisheyeCamera]], runs: int,
                  warmup: int) -> dict[str, dict[str, Any]]:
    """Each entry's inference p50 and end-to-end p50/p95 (ms) over `runs` frames (each with its
    camera, in turn), the entries interleaved frame by frame."""
    frame_times: dict[str, list[float]] = {e.name: [] for e in entries}
    inference_times: dict[str, list[float]] = {e.name: [] for e in entries}
    for index in range(warmup + runs):
        data, camera = frames[index % len(frames)]
        for entry in entries:
            elapsed = entry.frame_ms(data, camera)
            alone = entry.inference_ms(data, camera) if entry.inference_ms is not None else None
            if index >= warmup:
                frame_times[entry.name].append(elapsed)
                if alone is not None:
                    inference_times[entry.name].append(alone)
    report = {}
    for entry in entries:
        whole = summarize(frame_times[entry.name])
        model_alone = inference_times[entry.name]
        report[entry.name] = {"e2e_p50_ms": whole.p50, "e2e_p95_ms": whole.p95,
                              "inference_p50_ms": summarize(model_alone).p50 if model_alone else None}
    return report


def _cell(value: Any, metre: bool = False) -> str:
    if not isinstance(value, int | float) or value != value:
        return "–"
    return f"{value:.2f}" if metre else f"{value:.3f}"


def markdown(rows: dict[str, dict[str, Any]], datasets: list[str]) -> str:
    header = ["model"]
    for data in datasets:
        columns = REAL_COLUMNS if data.startswith("real") else RENDER_COLUMNS
        header += [f"{data} {c}" + (" (m)" if c.startswith("mPE") else "") for c in columns]
    header += ["inference p50 (ms)", "end to end p50 (ms)", "end to end p95 (ms)"]
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for name, row in rows.items():
        cells = [name]
        for data in datasets:
            metrics = row["metrics"].get(data, {})
            columns = REAL_COLUMNS if data.startswith("real") else RENDER_COLUMNS
            cells += [_cell(metrics.get(c), c.startswith("mPE")) for c in columns]
        times = row.get("times", {})
        cells += [_cell(times.get(k), True) if times.get(k) is not None else "–"
                  for k in ("inference_p50_ms", "e2e_p50_ms", "e2e_p95_ms")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", action="append", default=[], metavar="NAME=PATH",
                        help="a FishLoc ONNX model or checkpoint (repeat); PATH@PIXELS[,FIELD=VALUE...] "
                             "runs a planned model in the views of that budget and plan, e.g. "
                             "model.onnx@1000000,nadir_scale=1.25; a field onnx_spinning=off|alone|on "
                             "sets its sessions' spinning policy (fishloc serve --onnx-spinning; default "
                             "off)")
    parser.add_argument("--baseline", action="append", default=[], metavar="NAME=KIND:ONNX",
                        help="a zero-shot baseline (repeat): rotations:ONNX or letterbox:ONNX, or "
                             "tiled:ONNX[@PIXELS][,min_score=S,nms_iou=I]: a COCO file read in windows "
                             "on the default model's planned views")
    parser.add_argument("--data", action="append", default=[], metavar="NAME=ANNOTATIONS",
                        help="an evaluation set; names starting with 'real' get the real-frame columns")
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--frames", default=None, help="folder of encoded frames of one size to time")
    timing.add_argument("--time-on", default=None, metavar="ANNOTATIONS",
                        help="time on the frames of this evaluation set instead, each with its own "
                             "camera (e.g. real frames of several scenes and lenses)")
    parser.add_argument("--camera", default=str(DEMO_CAMERA_PATH), help="camera of --frames (scaled)")
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", default=None, help="write every figure here")
    args = parser.parse_args(argv)
    entries = []
    for item in args.model + args.baseline:
        name, _, spec = item.partition("=")
        entries.append(build_entry(name, spec, args.threads))
    datasets = [item.split("=", 1) for item in args.data]
    rows: dict[str, dict[str, Any]] = {e.name: {"metrics": {}} for e in entries}
    for data_name, path in datasets:
        frames = read_dataset(path)
        people = {}
        for entry in entries:
            print(f"[compare] {entry.name} on {data_name}", file=sys.stderr)
            evaluation = evaluate(entry.predictor, frames)
            rows[entry.name]["metrics"][data_name] = evaluation.metrics
            people[entry.name] = person_errors(evaluation.frames)
        if len(entries) > 1:  # every row's feet over the people all of them match
            for name, figures in common_errors(people).items():
                rows[name]["metrics"][data_name].update(figures)
    if args.frames or args.time_on:
        print(f"[compare] timing on {args.frames or args.time_on}", file=sys.stderr)
        timed = (timing_frames(load_frames(args.frames), load_camera(args.camera)) if args.frames
                 else set_frames(args.time_on))
        times = measure_times(entries, timed, args.runs, args.warmup)
        for name, figures in times.items():
            rows[name]["times"] = figures
    table = markdown(rows, [name for name, _ in datasets])
    print(table)
    if args.json:
        record = {"machine": machine_info(args.threads).line(), "rows": rows, "table": table}
        Path(args.json).write_text(json.dumps(json_safe(record), indent=2, default=str) + "\n",
                                   encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
