"""Prometheus metrics of one service instance (its own registry, so several apps can share a process)."""

from __future__ import annotations

from typing import Any

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.exposition import CONTENT_TYPE_LATEST

from service.result import DetectionResult
from sites import SiteLayout

# Stage latencies run from well under a millisecond (post-processing) to seconds (big frames on one core).
_STAGE_BUCKETS_S = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)

CONTENT_TYPE = CONTENT_TYPE_LATEST
# Camera ids come from clients; past this many distinct ids per metric, the rest share one label,
# so a client that invents ids cannot grow the exposition without bound.
MAX_CAMERA_LABELS = 256
OTHER_CAMERAS = "_other"
# Sites are bounded the same way; zones and lines per site are bounded by the registry (64 each).
MAX_SITE_LABELS = 64
# Fusion and tracking of one frame takes well under the stage latencies.
_FUSION_BUCKETS_S = (0.0001, 0.00025, 0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.1)


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
        self.site_people = Gauge("fishloc_site_people", "People tracked on a site now.", ["site"],
                                 registry=self.registry)
        self.zone_people = Gauge("fishloc_zone_people", "People in a zone of a site now.", ["site", "zone"],
                                 registry=self.registry)
        self.line_crossings = Counter(
            "fishloc_line_crossings", "Tracks crossing a counting line, by direction (in, out).",
            ["site", "line", "direction"], registry=self.registry,
        )
        self.site_frames = Counter(
            "fishloc_site_frames", "Frames of a site's cameras by what the tracker did with them: used, "
            "used_late (within the reordering window) or dropped_late.", ["site", "use"],
            registry=self.registry,
        )
        self.fusion_seconds = Histogram(
            "fishloc_site_fusion_seconds", "Fusion and tracking time of one frame of a site's camera.",
            buckets=_FUSION_BUCKETS_S, registry=self.registry,
        )
        # Behind a sites bus (`fishloc serve --sites-bus`): frames whose observation Redis did not take,
        # and frames answered before the tracker did; in a `fishloc sites` worker, its partitions and
        # the entries it applied (live, or replayed after taking a partition over).
        self.site_observations_undelivered = Counter(
            "fishloc_site_observations_undelivered", "Site observations the sites bus did not take "
            "(Redis unreachable): their frames were answered without track ids.", ["site"],
            registry=self.registry,
        )
        self.site_answers_late = Counter(
            "fishloc_site_answers_late", "Frames answered without track ids because no tracker answered "
            "within the wait (the frame is still tracked).", ["site"], registry=self.registry,
        )
        self.bus_partitions = Gauge("fishloc_sites_partitions", "Site partitions this worker owns now.",
                                    registry=self.registry)
        self.bus_entries = Counter(
            "fishloc_sites_entries", "Bus entries this worker applied: live, or replayed after a snapshot "
            "when it took a partition over.", ["how"], registry=self.registry,
        )
        self._site_labels: set[str] = set()
        self._zone_labels: dict[str, set[str]] = {}
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

    def site_label(self, site_id: str) -> str:
        """`site_id`, or `_other` once MAX_SITE_LABELS distinct sites have been labelled."""
        if site_id in self._site_labels or len(self._site_labels) < MAX_SITE_LABELS:
            self._site_labels.add(site_id)
            return site_id
        return OTHER_CAMERAS

    def observe_site(self, site_id: str, use: str, lines_before: dict[str, tuple[int, int]],
                     lines_after: dict[str, tuple[int, int]], occupancy: dict[str, Any] | None,
                     fusion_s: float) -> None:
        """One frame of a site: what the tracker did with it, the crossings it added, people now."""
        site = self.site_label(site_id)
        self.site_frames.labels(site=site, use=use).inc()
        self.fusion_seconds.observe(fusion_s)
        for line, after in lines_after.items():
            before = lines_before.get(line, (0, 0))
            for direction, now, then in zip(("in", "out"), after, before, strict=True):
                if now > then:  # a replayed late frame may undo a crossing; counters only grow
                    self.line_crossings.labels(site=site, line=line, direction=direction).inc(now - then)
        if occupancy is None or site != site_id:
            return
        self.site_people.labels(site=site).set(occupancy["count"])
        for zone, figures in occupancy["zones"].items():
            self.zone_people.labels(site=site, zone=zone).set(figures["count"])
            self._zone_labels.setdefault(site, set()).add(zone)

    def follow_layout(self, site_id: str, layout: SiteLayout) -> None:
        """Drop the zone gauges of zones a site no longer has."""
        site = self.site_label(site_id)
        for zone in self._zone_labels.get(site, set()) - set(layout.zones):
            self.zone_people.remove(site, zone)
            self._zone_labels[site].discard(zone)

    def forget_site(self, site_id: str) -> None:
        """A site no camera names any more: its gauges go (its counters stay, as counters do)."""
        if site_id not in self._site_labels:
            return
        self.follow_layout(site_id, SiteLayout())
        self.site_people.remove(site_id)

    def count_dropped(self, camera_id: str) -> None:
        self.dropped.labels(camera_id=self.camera_label(camera_id)).inc()

    def exposition(self) -> bytes:
        return generate_latest(self.registry)
