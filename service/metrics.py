"""Prometheus metrics of one service instance (its own registry, so several apps can share a process)."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.exposition import CONTENT_TYPE_LATEST

from service.result import DetectionResult

# Stage latencies run from well under a millisecond (post-processing) to seconds (big frames on one core).
_STAGE_BUCKETS_S = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)

CONTENT_TYPE = CONTENT_TYPE_LATEST
# Camera ids come from clients; past this many distinct ids per metric, the rest share one label,
# so a client that invents ids cannot grow the exposition without bound.
MAX_CAMERA_LABELS = 256
OTHER_CAMERAS = "_other"


class ServiceMetrics:
    """Counters and histograms for requests, pipeline stages, frames and detections."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "fishloc_http_requests", "HTTP requests by route template, method and status.",
            ["route", "method", "status"], registry=self.registry,
        )
        self.request_seconds = Histogram(
            "fishloc_http_request_seconds", "HTTP request latency by route template.",
            ["route"], buckets=_STAGE_BUCKETS_S, registry=self.registry,
        )
        self.stage_seconds = Histogram(
            "fishloc_stage_seconds", "Pipeline latency per stage (decode, preprocess, inference, "
            "postprocess, total).", ["stage"], buckets=_STAGE_BUCKETS_S, registry=self.registry,
        )
        self.frames = Counter(
            "fishloc_frames", "Frames processed per camera and front end.",
            ["camera_id", "frontend"], registry=self.registry,
        )
        self.detections = Counter(
            "fishloc_detections", "People detected per camera.", ["camera_id"], registry=self.registry,
        )
        self.masked = Counter(
            "fishloc_masked_detections", "Detections dropped because their foot point lies in one of "
            "the camera's masks (mirrors, posters, screens).", ["camera_id"], registry=self.registry,
        )
        self.frame_errors = Counter(
            "fishloc_frame_errors", "Frames refused by the pipeline, by error code.", ["code"],
            registry=self.registry,
        )
        self.rejected = Counter(
            "fishloc_overload_rejections", "Frames refused because too many were in flight.", ["frontend"],
            registry=self.registry,
        )
        self.dropped = Counter(
            "fishloc_stream_dropped_frames", "Streamed frames answered DROPPED (a newer frame won).",
            ["camera_id"], registry=self.registry,
        )
        self.in_flight = Gauge("fishloc_in_flight", "Frames being processed now.", registry=self.registry)
        self.ready = Gauge("fishloc_ready", "1 once the model is loaded and warmed up.",
                           registry=self.registry)
        self._camera_labels: set[str] = set()
        self.model_info = Gauge(
            "fishloc_model_info", "The model being served (value 1).", ["name", "version", "input_size"],
            registry=self.registry,
        )

    def camera_label(self, camera_id: str) -> str:
        """`camera_id`, or `_other` once MAX_CAMERA_LABELS distinct ids have been labelled."""
        if camera_id in self._camera_labels:
            return camera_id
        if len(self._camera_labels) >= MAX_CAMERA_LABELS:
            return OTHER_CAMERAS
        self._camera_labels.add(camera_id)
        return camera_id

    def observe_result(self, result: DetectionResult, frontend: str) -> None:
        for stage, milliseconds in result.timing_ms.items():
            self.stage_seconds.labels(stage=stage).observe(milliseconds / 1e3)
        camera = self.camera_label(result.camera_id)
        self.frames.labels(camera_id=camera, frontend=frontend).inc()
        self.detections.labels(camera_id=camera).inc(len(result.detections))
        self.masked.labels(camera_id=camera).inc(result.masked)

    def count_dropped(self, camera_id: str) -> None:
        self.dropped.labels(camera_id=self.camera_label(camera_id)).inc()

    def exposition(self) -> bytes:
        return generate_latest(self.registry)
