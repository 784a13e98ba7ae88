"""Where a gateway's frames come from: a video file, an RTSP/HTTP stream, a folder of images or a
webcam (OpenCV), each yielding JPEG-encoded frames with an id and a capture time."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace
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
    camera_id: str | None = None  # set by InterleavedSource; None: the gateway's one camera


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

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


@dataclass(frozen=True)
class ReopenPolicy:
    """How a live source that cannot be opened, or stops delivering, is opened again: waits of
    `first_backoff_s` doubling up to `max_backoff_s`, at most `max_attempts` times in a row
    (None: until the gateway stops)."""

    first_backoff_s: float = 0.5
    max_backoff_s: float = 30.0
    max_attempts: int | None = None

    def __post_init__(self) -> None:
        if not 0 < self.first_backoff_s <= self.max_backoff_s:
            raise ValueError(f"invalid backoff {self}")
        if self.max_attempts is not None and self.max_attempts < 0:
            raise ValueError(f"max_attempts must be >= 0, got {self.max_attempts}")


class CaptureSource:
    """An OpenCV VideoCapture: a video file, an RTSP/HTTP URL or a webcam index.

    A video file that cannot be opened is a ValueError. A live source (URL or webcam) that cannot be
    opened yet, or that stops delivering, is opened again with backoff (`ReopenPolicy`) instead of
    ending: cameras reboot and networks drop.
    """

    def __init__(self, target: str | int, live: bool, reopen: ReopenPolicy | None = None) -> None:
        if not hasattr(cv2, "VideoCapture"):
            raise ValueError(f"cannot open video source {target!r}: this OpenCV has no video input "
                             "(the service image's is built without it); run the gateway from a pip "
                             "install, whose opencv-python-headless reads video, or give it a folder "
                             "of images")
        self.target = target
        self.live = live
        self.reopen = reopen or ReopenPolicy()
        self._stopped = threading.Event()
        self._backoff_s = self.reopen.first_backoff_s
        self.capture: cv2.VideoCapture | None = self._try_open()
        if self.capture is None and not live:
            raise ValueError(f"cannot open video source {self.target!r}")
        fps = float(self.capture.get(cv2.CAP_PROP_FPS) or 0.0) if self.capture is not None else 0.0
        self.native_fps = fps if fps > 0 and not live else None
        if self.capture is None:
            log.warning("cannot open video source %r yet; retrying", self.target)

    def _try_open(self) -> cv2.VideoCapture | None:
        capture = cv2.VideoCapture(self.target)
        if capture.isOpened():
            return capture
        capture.release()
        return None

    def _open_again(self) -> cv2.VideoCapture | None:
        """Wait and open, with growing waits; None once stopped or out of attempts."""
        attempts = 0
        while self.reopen.max_attempts is None or attempts < self.reopen.max_attempts:
            log.warning("video source %r unavailable; opening it again in %.1f s", self.target,
                        self._backoff_s)
            if self._stopped.wait(self._backoff_s):
                return None
            self._backoff_s = min(self._backoff_s * 2, self.reopen.max_backoff_s)
            attempts += 1
            capture = self._try_open()
            if capture is not None:
                return capture
        log.warning("giving up on video source %r after %d attempts", self.target, attempts)
        return None

    def frames(self) -> Iterator[SourceFrame]:
        index = 0
        while not self._stopped.is_set():
            if self.capture is None:
                self.capture = self._open_again()
                if self.capture is None:
                    return
            ok, image = self.capture.read()
            if not ok:
                if not self.live:
                    return
                self.capture.release()
                self.capture = None
                continue
            self._backoff_s = self.reopen.first_backoff_s
            yield SourceFrame(str(index), time.time_ns(), encode_jpeg(image))
            index += 1

    def stop(self) -> None:
        """Make `frames` end soon, from any thread (a wait between attempts ends at once)."""
        self._stopped.set()

    def close(self) -> None:
        if self.capture is not None:
            self.capture.release()


class InterleavedSource:
    """Several cameras' sources as one stream: a frame of each camera in turn (cameras of one site
    that capture in step stay in step), each tagged with its camera id; it ends when all have."""

    def __init__(self, sources: Mapping[str, FrameSource]) -> None:
        if not sources:
            raise ValueError("an interleaved source needs at least one camera")
        self.sources = dict(sources)
        rates: list[float | None] = [source.native_fps for source in self.sources.values()]
        # Paced as one stream: each camera at its own rate means all of them n times as often.
        known = [rate for rate in rates if rate is not None]
        self.native_fps: float | None = min(known) * len(rates) if len(known) == len(rates) else None

    def frames(self) -> Iterator[SourceFrame]:
        streams = {camera_id: iter(source.frames()) for camera_id, source in self.sources.items()}
        while streams:
            for camera_id in list(streams):
                frame = next(streams[camera_id], None)
                if frame is None:
                    del streams[camera_id]
                    continue
                yield replace(frame, camera_id=camera_id)

    def stop(self) -> None:
        for source in self.sources.values():
            source.stop()

    def close(self) -> None:
        for source in self.sources.values():
            source.close()


FrameSource = FolderSource | CaptureSource | InterleavedSource


def open_source(source: str, reopen: ReopenPolicy | None = None) -> FrameSource:
    """A folder, a webcam index ("0"), a URL (rtsp://, http://...) or a video file; `reopen` is
    how a live source (webcam or URL) is opened again."""
    if source.isdigit():
        return CaptureSource(int(source), live=True, reopen=reopen)
    if "://" in source:
        return CaptureSource(source, live=True, reopen=reopen)
    path = Path(source)
    if path.is_dir():
        return FolderSource(path)
    if path.is_file():
        return CaptureSource(str(path), live=False)
    raise ValueError(f"source {source!r} is neither a folder, a video file, a URL nor a webcam index")
