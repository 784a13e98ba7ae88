"""The latest frame of each camera and its result, whichever front end (REST or gRPC) it came from.

The viewer shows it; nothing else reads it. Memory stays bounded: one encoded frame per camera,
at most `max_cameras` cameras and `max_bytes` of frames in all (the least recently updated camera
is forgotten first). Recording only keeps a reference to bytes the request already holds; no frame
is copied, decoded or re-encoded on the detection path.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from dataclasses import dataclass

from service.result import DetectionResult

_JPEG_MAGIC = b"\xff\xd8\xff"
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def sniff_media_type(data: bytes) -> str:
    """The media type of encoded frame bytes, from their first bytes."""
    if data.startswith(_JPEG_MAGIC):
        return "image/jpeg"
    if data.startswith(_PNG_MAGIC):
        return "image/png"
    return "application/octet-stream"


@dataclass(frozen=True)
class LatestFrame:
    """One camera's most recent frame: the encoded bytes as they arrived and the pipeline's result.

    `sequence` grows by one with every frame recorded in this process (any camera), so a client can
    tell a new frame from the one it already shows.
    """

    camera_id: str
    sequence: int
    received_unix_s: float
    frontend: str
    data: bytes
    result: DetectionResult

    @property
    def media_type(self) -> str:
        return sniff_media_type(self.data)


@dataclass(frozen=True)
class LatestFramesConfig:
    max_cameras: int = 256
    max_bytes: int = 256 * 1024 * 1024

    def __post_init__(self) -> None:
        if self.max_cameras < 1 or self.max_bytes < 1:
            raise ValueError("max_cameras and max_bytes must be positive")


class LatestFrames:
    """A thread-safe map camera id -> LatestFrame, bounded in cameras and bytes."""

    def __init__(self, config: LatestFramesConfig | None = None) -> None:
        self.config = config or LatestFramesConfig()
        self._frames: OrderedDict[str, LatestFrame] = OrderedDict()
        self._bytes = 0
        self._sequence = 0
        self._lock = threading.Lock()

    def record(self, data: bytes, result: DetectionResult, frontend: str) -> LatestFrame | None:
        """Keep `data` and `result` as the latest frame of `result.camera_id`. A frame larger than
        the whole byte budget is not kept (None)."""
        if len(data) > self.config.max_bytes:
            return None
        with self._lock:
            self._sequence += 1
            frame = LatestFrame(
                camera_id=result.camera_id, sequence=self._sequence, received_unix_s=time.time(),
                frontend=frontend, data=data, result=result,
            )
            previous = self._frames.pop(frame.camera_id, None)
            if previous is not None:
                self._bytes -= len(previous.data)
            self._frames[frame.camera_id] = frame
            self._bytes += len(data)
            while len(self._frames) > self.config.max_cameras or self._bytes > self.config.max_bytes:
                _, evicted = self._frames.popitem(last=False)
                self._bytes -= len(evicted.data)
            return frame

    def get(self, camera_id: str) -> LatestFrame | None:
        with self._lock:
            return self._frames.get(camera_id)

    def forget(self, camera_id: str) -> bool:
        """Drop a camera's frame (e.g. when the camera is deleted); True if there was one."""
        with self._lock:
            frame = self._frames.pop(camera_id, None)
            if frame is None:
                return False
            self._bytes -= len(frame.data)
            return True

    def camera_ids(self) -> list[str]:
        """Cameras with a frame, least recently updated first."""
        with self._lock:
            return list(self._frames)

    @property
    def total_bytes(self) -> int:
        with self._lock:
            return self._bytes

    def __len__(self) -> int:
        with self._lock:
            return len(self._frames)
