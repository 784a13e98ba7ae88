"""Where a gateway's frames come from: a video file, an RTSP/HTTP stream, a folder of images or a
webcam (OpenCV), each yielding JPEG-encoded frames with an id and a capture time."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = frozenset({".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"})
JPEG_QUALITY = 90


@dataclass(frozen=True)
class SourceFrame:
    frame_id: str
    capture_time_ns: int
    jpeg: bytes


def encode_jpeg(bgr: NDArray[Any]) -> bytes:
    """(H, W, 3) BGR image -> JPEG bytes."""
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return bytes(data.tobytes())


class FolderSource:
    """The images of a folder in name order; JPEG files are sent as they are, others re-encoded."""

    live = False

    def __init__(self, folder: Path) -> None:
        self.files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise ValueError(f"{folder} holds no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
        self.native_fps: float | None = None

    def frames(self) -> Iterator[SourceFrame]:
        for file in self.files:
            data = file.read_bytes()
            if file.suffix.lower() not in (".jpg", ".jpeg"):
                image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
                if image is None:
                    log.warning("skipping %s: not a readable image", file)
                    continue
                data = encode_jpeg(image)
            yield SourceFrame(file.name, time.time_ns(), data)

    def close(self) -> None:
        pass


class CaptureSource:
    """An OpenCV VideoCapture: a video file, an RTSP/HTTP URL or a webcam index. A live source that
    stops delivering is reopened (with backoff) instead of ending."""

    def __init__(self, target: str | int, live: bool, max_backoff_s: float = 30.0) -> None:
        self.target = target
        self.live = live
        self.max_backoff_s = max_backoff_s
        self.capture = self._open()
        fps = float(self.capture.get(cv2.CAP_PROP_FPS) or 0.0)
        self.native_fps = fps if fps > 0 and not live else None

    def _open(self) -> cv2.VideoCapture:
        capture = cv2.VideoCapture(self.target)
        if not capture.isOpened():
            raise ValueError(f"cannot open video source {self.target!r}")
        return capture

    def frames(self) -> Iterator[SourceFrame]:
        index = 0
        backoff = 0.5
        while True:
            ok, image = self.capture.read()
            if not ok:
                if not self.live:
                    return
                log.warning("video source %r stopped; reopening in %.1f s", self.target, backoff)
                time.sleep(backoff)
                backoff = min(backoff * 2, self.max_backoff_s)
                self.capture.release()
                try:
                    self.capture = self._open()
                except ValueError as error:
                    log.warning("%s", error)
                continue
            backoff = 0.5
            yield SourceFrame(str(index), time.time_ns(), encode_jpeg(image))
            index += 1

    def close(self) -> None:
        self.capture.release()


FrameSource = FolderSource | CaptureSource


def open_source(source: str) -> FrameSource:
    """A folder, a webcam index ("0"), a URL (rtsp://, http://...) or a video file."""
    if source.isdigit():
        return CaptureSource(int(source), live=True)
    if "://" in source:
        return CaptureSource(source, live=True)
    path = Path(source)
    if path.is_dir():
        return FolderSource(path)
    if path.is_file():
        return CaptureSource(str(path), live=False)
    raise ValueError(f"source {source!r} is neither a folder, a video file, a URL nor a webcam index")
