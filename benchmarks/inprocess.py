"""Section 1: the pipeline in this process, stage by stage, beside a naive pipeline and the floor.

Three ways of answering the same frames, interleaved frame by frame so that load from other jobs on
a shared machine hits them alike and their ratios stay meaningful:

- *service*: `Pipeline.detect` as `fishloc serve` builds it (`build_runner`: its session options,
  thread counts and OpenCV threading), timed whole, and the same calls timed stage by stage:
  decode (header + reduced-scale JPEG decode), preprocess (letterbox or polar unwrap), inference
  (onnxruntime), postprocess (threshold, boxes to frame px, rotated NMS), localization (foot
  points, floor, site).
- *naive*: full-size `cv2.imdecode`, the model's view made from the full frame, onnxruntime with
  default session options, then the same post-processing: what a first attempt would do.
- *floor*: model inference alone on the view's inputs made beforehand (and on the second look's
  canvas, where the view has the look), and the decode alone; their
  sum is what any service must spend on a frame, and the service's overhead is measured over it
  (in wall-clock and, less sensitive to other processes, in CPU time).

Every one of them sees the view the service plans (`FISHLOC_MAX_VIEW_PIXELS` included: a budget
with room for the nadir view times it too).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from benchmarks.frames import FrameSet
from benchmarks.stats import Summary, overhead_pct, ratio, summarize
from contract import InputMapping, RawOutputs, merge_outputs, min_decoded_side, run_view, view_inputs
from contract import second_look as look
from contract.detect import look_input, looks_again
from fisheye import FisheyeCamera
from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.frame_decode import decode_frame, read_header
from service.pipeline import Pipeline, localize
from service.result import Detections
from service.runner import build_runner

STAGES = ("decode", "preprocess", "inference", "postprocess", "localization", "total")
# OpenCV's own thread count before the service's set-up lowers it (the naive pipeline keeps it).
_OPENCV_DEFAULT_THREADS = cv2.getNumThreads()


def staged_detect(pipeline: Pipeline, data: bytes, camera: FisheyeCamera,
                  threshold: float) -> tuple[dict[str, float], Detections]:
    """The calls of `Pipeline.detect`, each timed: stage -> ms (STAGES, and `decode_cpu`: the
    decoding thread's CPU time, which other processes' load does not inflate), and the detections;
    the second look too where the view has it, its time in inference as the service counts it."""
    info, view = pipeline.info, pipeline.config.view
    start, start_cpu = time.perf_counter(), time.thread_time()
    header = read_header(data)
    frame_camera = camera.scaled_to(header.size_wh)
    frame = decode_frame(data, min_decoded_side(info, frame_camera, view), pipeline.config.max_pixels, header)
    decoded, decoded_cpu = time.perf_counter(), time.thread_time()
    images, mapping = view_inputs(info, frame.rgb, frame_camera, view, pipeline.model.frame_threads())
    preprocessed = time.perf_counter()
    raw = run_view(pipeline.model, images, mapping)
    if looks_again(mapping):
        # the second look's patches run on the model too: their time is inference, as the service
        # counts it (`Pipeline.detect`'s timing)
        kept = pipeline.select(raw, mapping, threshold, frame_camera, frame.rgb, frame.scale_xy)
        inferred = selected = time.perf_counter()
    else:
        inferred = time.perf_counter()
        kept = pipeline.select(raw, mapping, threshold, frame_camera)
        selected = time.perf_counter()
    detections = localize(kept.boxes_cxcywh, kept.scores, frame_camera, kept.foot_px)
    done = time.perf_counter()
    marks = (start, decoded, preprocessed, inferred, selected, done)
    times = {stage: (b - a) * 1e3 for stage, a, b in zip(STAGES, marks, marks[1:], strict=False)}
    times["total"] = (done - start) * 1e3
    times["decode_cpu"] = (decoded_cpu - start_cpu) * 1e3
    return times, detections


def look_canvas(pipeline: Pipeline, data: bytes, camera: FisheyeCamera) -> NDArray[np.uint8] | None:
    """The second look's canvas (the model's input) for the frame `data` as the service would run
    it, made once so that the floor can time its run beside the view's; None where the view has no
    look or the frame gives no patch."""
    header = read_header(data)
    frame_camera = camera.scaled_to(header.size_wh)
    frame = decode_frame(data, min_decoded_side(pipeline.info, frame_camera, pipeline.config.view),
                         pipeline.config.max_pixels, header)
    images, mapping = view_inputs(pipeline.info, frame.rgb, frame_camera, pipeline.config.view)
    if not looks_again(mapping):
        return None
    # the first look's detections from the look's floor, as `select_looking` takes them
    raw = run_view(pipeline.model, images, mapping)
    first = pipeline.select(raw, mapping, look.FIRST_LOOK_FLOOR, frame_camera)
    found = look_input(pipeline.info, frame.rgb, frame.scale_xy, mapping, first)
    return None if found is None else found[2]


class NaivePipeline:
    """Full decode, the model's view made from the full frame, a default onnxruntime session; the
    service's post-processing."""

    def __init__(self, model_path: str | Path, pipeline: Pipeline, camera: FisheyeCamera) -> None:
        self.session = ort.InferenceSession(str(model_path), providers=["CPUExecutionProvider"])
        self.pipeline = pipeline
        self.camera = camera

    def model_input(self, data: bytes) -> tuple[list[NDArray[np.uint8]], InputMapping, FisheyeCamera]:
        return self.full_decode_input(data, self.pipeline, self.camera)

    @staticmethod
    def full_decode_input(data: bytes, pipeline: Pipeline, camera: FisheyeCamera
                          ) -> tuple[list[NDArray[np.uint8]], InputMapping, FisheyeCamera]:
        """Full decode of `data` and `pipeline`'s view of it: the model's inputs (the view's, then
        its nadir view where the plan has one), their mapping to frame px and the camera scaled to
        the frame."""
        bgr = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError("OpenCV cannot decode the frame")
        rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
        frame_camera = camera.scaled_to((rgb.shape[1], rgb.shape[0]))
        images, mapping = view_inputs(pipeline.info, rgb, frame_camera, pipeline.config.view)
        return images, mapping, frame_camera

    def detect(self, data: bytes, threshold: float) -> Detections:
        images, mapping, frame_camera = self.model_input(data)
        raws = []
        for image in images:
            boxes, scores = self.session.run(["boxes", "scores"], {"image": image[None]})
            raws.append(RawOutputs(np.asarray(boxes[0], np.float32), np.asarray(scores[0], np.float32)))
        kept = self.pipeline.select(merge_outputs(raws, mapping), mapping, threshold, frame_camera)
        return localize(kept.boxes_cxcywh, kept.scores, frame_camera)


@dataclass(frozen=True)
class InProcessResult:
    stages_ms: dict[str, Summary]
    pipeline_ms: Summary
    naive_ms: Summary
    floor_inference_ms: Summary
    floor_decode_ms: Summary           # decode alone (header + reduced-scale decode), its own slot
    pipeline_cpu_ms: Summary           # process CPU time of `Pipeline.detect` (all its threads)
    decode_cpu_ms: Summary             # CPU time of the decode stage (one thread)
    floor_inference_cpu_ms: Summary    # process CPU time of inference alone
    detections_per_frame: float
    decode_reduction: int              # the DCT scale the service decodes these frames at (1, 2, 4, 8)
    decoded_wh: tuple[int, int]

    @property
    def floor_ms(self) -> float:
        """decode alone + inference alone (p50): what any service must spend on a frame."""
        return self.floor_decode_ms.p50 + self.floor_inference_ms.p50

    def ratios(self) -> dict[str, float | None]:
        return {
            "naive_over_service_p50": ratio(self.naive_ms.p50, self.pipeline_ms.p50),
            "service_over_floor_inference_p50": ratio(self.pipeline_ms.p50, self.floor_inference_ms.p50),
            "service_overhead_pct_over_decode_plus_inference": overhead_pct(self.pipeline_ms.p50,
                                                                             self.floor_ms),
            # The same on CPU time, which the load of other processes inflates far less.
            "service_cpu_overhead_pct_over_decode_plus_inference": overhead_pct(
                self.pipeline_cpu_ms.p50, self.decode_cpu_ms.p50 + self.floor_inference_cpu_ms.p50),
        }

    def as_dict(self) -> dict[str, object]:
        return {
            "available": True,
            "stages_ms": {name: s.as_dict() for name, s in self.stages_ms.items()},
            "pipeline_ms": self.pipeline_ms.as_dict(),
            "naive_ms": self.naive_ms.as_dict(),
            "floor_inference_ms": self.floor_inference_ms.as_dict(),
            "floor_decode_ms": self.floor_decode_ms.as_dict(),
            "pipeline_cpu_ms": self.pipeline_cpu_ms.as_dict(),
            "decode_cpu_ms": self.decode_cpu_ms.as_dict(),
            "floor_inference_cpu_ms": self.floor_inference_cpu_ms.as_dict(),
            "floor_decode_plus_inference_p50_ms": self.floor_ms,
            "detections_per_frame": self.detections_per_frame,
            "decode_reduction": self.decode_reduction,
            "decoded_wh": list(self.decoded_wh),
            "ratios": self.ratios(),
        }


def _timed(call: Callable[[], object]) -> float:
    start = time.perf_counter()
    call()
    return (time.perf_counter() - start) * 1e3


def _timed_cpu(call: Callable[[], object]) -> tuple[float, float]:
    """Wall and process CPU ms of one call."""
    start, start_cpu = time.perf_counter(), time.process_time()
    call()
    return (time.perf_counter() - start) * 1e3, (time.process_time() - start_cpu) * 1e3


def _settle(seconds: float = 0.01) -> None:
    """A pause between measurements: thread pools that busy-wait after their work (onnxruntime's
    default session, OpenCV's pool) stop spinning before the next measurement starts."""
    time.sleep(seconds)


def service_pipeline(model_path: Path, threads: int) -> Pipeline:
    """The pipeline exactly as `fishloc serve --model model_path --threads threads` builds it."""
    runner = build_runner(Settings(model=model_path, threads=threads), ServiceMetrics())
    runner.close()  # only its pipeline is used; the runner's pool would sit idle
    return runner.pipeline


def _floor_inference(pipeline: Pipeline, view: tuple[list[NDArray[np.uint8]], InputMapping],
                     canvas: NDArray[np.uint8] | None) -> None:
    """The model alone on a frame's inputs: the view's, then the second look's canvas where it has one."""
    run_view(pipeline.model, *view)
    if canvas is not None:
        pipeline.model.run(canvas)


def run_in_process(model_path: Path, frames: FrameSet, camera: FisheyeCamera, threads: int,
                   runs: int, warmup: int, progress: Callable[[str], None] = print) -> InProcessResult:
    pipeline = service_pipeline(model_path, threads)
    naive = NaivePipeline(model_path, pipeline, camera)
    info = pipeline.info
    inputs = [naive.model_input(data)[:2] for data in frames.data]
    canvases = [look_canvas(pipeline, data, camera) for data in frames.data]  # the second look's, if any
    frame_camera = camera.scaled_to(read_header(frames.data[0]).size_wh)
    plan = pipeline.plan(frame_camera)
    threshold = pipeline.point(None if plan is None else plan.layout).min_score  # the point it serves at
    decoded_side = min_decoded_side(info, frame_camera, pipeline.config.view)
    service_threads = cv2.getNumThreads()

    def naive_detect(data: bytes) -> None:
        cv2.setNumThreads(_OPENCV_DEFAULT_THREADS)
        try:
            naive.detect(data, threshold)
        finally:
            cv2.setNumThreads(service_threads)

    stages: dict[str, list[float]] = {name: [] for name in STAGES}
    whole: list[float] = []
    whole_cpu: list[float] = []
    decode_cpu: list[float] = []
    floor_cpu: list[float] = []
    floor_decode: list[float] = []
    naive_ms: list[float] = []
    floor_ms: list[float] = []
    detections = 0
    progress(f"in-process: {warmup} warm-up + {runs} interleaved runs of service, staged, naive and floor")
    for index in range(warmup + runs):
        data = frames.data[index % len(frames)]
        # The naive session's pool spins after its runs (onnxruntime's default): it goes first and
        # gets the longest pause, so that its spinning does not land on the service's figures.
        naive_time = _timed(partial(naive_detect, data))
        _settle(0.05)
        times, found = staged_detect(pipeline, data, camera, threshold)
        _settle()
        decode_time = _timed(partial(decode_frame, data, decoded_side, pipeline.config.max_pixels))
        _settle()
        floor_time, floor_cpu_ms = _timed_cpu(partial(_floor_inference, pipeline, inputs[index % len(frames)],
                                                      canvases[index % len(frames)]))
        _settle()
        whole_ms, whole_cpu_ms = _timed_cpu(partial(pipeline.detect, data, camera, min_score=threshold))
        _settle()
        if index < warmup:
            continue
        for name in STAGES:
            stages[name].append(times[name])
        whole.append(whole_ms)
        whole_cpu.append(whole_cpu_ms)
        decode_cpu.append(times["decode_cpu"])
        floor_cpu.append(floor_cpu_ms)
        floor_decode.append(decode_time)
        naive_ms.append(naive_time)
        floor_ms.append(floor_time)
        detections += len(found)
    decoded = decode_frame(frames.data[0], decoded_side, pipeline.config.max_pixels)
    return InProcessResult(
        decode_reduction=decoded.reduction, decoded_wh=decoded.decoded_wh,
        stages_ms={name: summarize(values) for name, values in stages.items()},
        pipeline_cpu_ms=summarize(whole_cpu), decode_cpu_ms=summarize(decode_cpu),
        floor_inference_cpu_ms=summarize(floor_cpu), floor_decode_ms=summarize(floor_decode),
        pipeline_ms=summarize(whole), naive_ms=summarize(naive_ms), floor_inference_ms=summarize(floor_ms),
        detections_per_frame=detections / runs,
    )
