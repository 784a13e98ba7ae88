"""Runs the pipeline off the event loop, with a bound on the frames admitted at once.

Both front ends (REST and gRPC) share one runner: one thread pool sized to the inference threads,
one in-flight limit (beyond it a frame is refused at once, never queued without bound), one
readiness flag, one set of metrics.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import dataclasses
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2

from contract import OnnxModel, SessionThreads
from contract.views import DEFAULT_VIEW
from fisheye import FisheyeCamera
from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.frame_decode import FrameError
from service.latest import LatestFrames
from service.pipeline import Pipeline, PipelineConfig
from service.result import DetectionResult

log = logging.getLogger(__name__)


# What follows the pipeline for a camera of a site (`SiteHub.track`): the result with its track ids.
SiteTracking = Callable[[FisheyeCamera, DetectionResult, float], DetectionResult]
# Or, behind a sites bus (`BusSiteHub.forward`): on the event loop, after the pipeline.
SiteForwarding = Callable[[FisheyeCamera, DetectionResult, float], Awaitable[DetectionResult]]


class OverloadedError(RuntimeError):
    """Too many frames in flight; the caller should answer 503 / RESOURCE_EXHAUSTED."""

    def __init__(self, limit: int, retry_after_s: int) -> None:
        super().__init__(f"{limit} frames are being processed; retry in {retry_after_s} s")
        self.retry_after_s = retry_after_s


@dataclass(frozen=True)
class RunnerConfig:
    threads: int
    max_in_flight: int
    retry_after_s: int = 1


class InferenceRunner:
    """A Pipeline behind an admission limit and a thread pool."""

    def __init__(self, pipeline: Pipeline, config: RunnerConfig, metrics: ServiceMetrics) -> None:
        self.pipeline = pipeline
        self.config = config
        self.metrics = metrics
        self._executor = ThreadPoolExecutor(max_workers=config.threads, thread_name_prefix="fishloc-infer")
        self._lock = threading.Lock()
        self._in_flight = 0
        self._ready = threading.Event()
        self.latest = LatestFrames()  # what the viewer shows: each camera's last frame, any front end
        self.site_tracking: SiteTracking | None = None
        self.site_forwarding: SiteForwarding | None = None
        info = pipeline.info
        labels = {"name": info.name, "version": info.version, "input_size": str(info.input_size)}
        metrics.model_info.labels(**labels).set(1)

    @property
    def ready(self) -> bool:
        return self._ready.is_set()

    @property
    def in_flight(self) -> int:
        return self._in_flight

    async def warm_up(self) -> None:
        """Warm the model up in the pool, then mark the runner ready."""
        await asyncio.get_running_loop().run_in_executor(self._executor, self.pipeline.warm_up)
        self._ready.set()
        self.metrics.ready.set(1)
        log.info("model %s %s ready", self.pipeline.info.name, self.pipeline.info.version)

    def try_admit(self) -> bool:
        """Take an in-flight slot if one is free (release it with `release`)."""
        with self._lock:
            if self._in_flight >= self.config.max_in_flight:
                return False
            self._in_flight += 1
        self.metrics.in_flight.inc()
        return True

    def release(self) -> None:
        with self._lock:
            self._in_flight -= 1
        self.metrics.in_flight.dec()

    @contextlib.contextmanager
    def admitted(self, frontend: str) -> Iterator[None]:
        """Hold an in-flight slot for the block, or raise OverloadedError at once (a rejection of
        `frontend` in the metrics)."""
        if not self.try_admit():
            self.metrics.rejected.labels(frontend=frontend).inc()
            raise OverloadedError(self.config.max_in_flight, self.config.retry_after_s)
        try:
            yield
        finally:
            self.release()

    async def detect(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None,
                     frame_id: str | None, frontend: str,
                     capture_time: float | None = None) -> DetectionResult:
        """Admit, run the pipeline in the pool, record metrics. Raises OverloadedError or FrameError."""
        with self.admitted(frontend):
            return await self.run_admitted(data, camera, min_score=min_score, frame_id=frame_id,
                                           frontend=frontend, capture_time=capture_time)

    def _detect_and_track(self, data: bytes, camera: FisheyeCamera, min_score: float | None,
                          frame_id: str | None, capture_time: float) -> DetectionResult:
        result = self.pipeline.detect(data, camera, min_score=min_score, frame_id=frame_id)
        if self.site_tracking is None:
            return result
        # Called for cameras without a site too: one that left its site (by a write through another
        # process) ends its tracks there with its next frame.
        return self.site_tracking(camera, result, capture_time)

    async def run_admitted(self, data: bytes, camera: FisheyeCamera, *, min_score: float | None,
                           frame_id: str | None, frontend: str,
                           capture_time: float | None = None) -> DetectionResult:
        """Run a frame that already holds an in-flight slot; a frame of a site's camera joins its
        site's tracks at `capture_time` (Unix s; default: now, its arrival) before this returns."""
        when = time.time() if capture_time is None else capture_time
        loop = asyncio.get_running_loop()
        # run_in_executor does not carry context variables into the pool (asyncio.to_thread does):
        # without this, the pipeline's log lines would lose the request id.
        context = contextvars.copy_context()
        try:
            result = await loop.run_in_executor(self._executor, lambda: context.run(
                self._detect_and_track, data, camera, min_score, frame_id, when,
            ))
        except FrameError as error:
            self.metrics.frame_errors.labels(code=error.code).inc()
            raise
        if self.site_forwarding is not None:
            result = await self.site_forwarding(camera, result, when)
        self.metrics.observe_result(result, frontend)
        self.latest.record(data, result, frontend)
        return result

    def close(self) -> None:
        self._executor.shutdown(wait=True, cancel_futures=False)


def build_runner(settings: Settings, metrics: ServiceMetrics) -> InferenceRunner:
    """Load the model named by the settings (ModelError if it cannot be used) into a runner."""
    # The thread budget belongs to onnxruntime and to parallel frames; OpenCV's own pool would
    # compete with both for the same cores.
    cv2.setNumThreads(1)
    model = OnnxModel(settings.model, SessionThreads(intra_op=settings.threads, inter_op=1,
                                                     spinning=settings.onnx_spinning))
    view = dataclasses.replace(DEFAULT_VIEW, max_pixels=settings.max_view_pixels,
                               second_look_pixels=settings.second_look,
                               longest_person_ratio=settings.longest_person_ratio)
    pipeline = Pipeline(model, PipelineConfig(
        nms_iou=settings.nms_iou, max_pixels=settings.max_pixels, view=view,
        max_camera_view_pixels=settings.max_camera_view_pixels))
    config = RunnerConfig(threads=settings.threads, max_in_flight=settings.in_flight_limit,
                          retry_after_s=settings.retry_after_s)
    return InferenceRunner(pipeline, config, metrics)
