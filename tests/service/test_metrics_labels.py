"""Camera-id labels of the metrics stay bounded whatever ids clients send."""

from __future__ import annotations

from service.core.metrics import MAX_CAMERA_LABELS, OTHER_CAMERAS, ServiceMetrics


def test_camera_labels_are_bounded_and_stable() -> None:
    metrics = ServiceMetrics()
    for index in range(MAX_CAMERA_LABELS + 50):
        metrics.count_dropped(f"invented-{index}")
    metrics.count_dropped("invented-0")  # an id labelled before keeps its label
    text = metrics.exposition().decode()
    samples = [line for line in text.splitlines() if line.startswith("fishloc_stream_dropped_frames_total{")]
    assert len(samples) == MAX_CAMERA_LABELS + 1
    assert f'fishloc_stream_dropped_frames_total{{camera_id="{OTHER_CAMERAS}"}} 50.0' in samples
    assert 'fishloc_stream_dropped_frames_total{camera_id="invented-0"} 2.0' in samples
    assert metrics.camera_label("invented-1") == "invented-1"
    assert metrics.camera_label("new-camera") == OTHER_CAMERAS
