"""Live gateway sources (webcam index, RTSP/HTTP URL) with OpenCV's VideoCapture replaced by a
scripted camera: one that cannot be opened at first, delivers a few frames, stops, and comes back."""

from __future__ import annotations

import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from service.gateway import frame_sources
from service.gateway.frame_sources import CaptureSource, ReopenPolicy, open_source


class ScriptedCapture:
    """A VideoCapture that delivers `frames` frames (None: it cannot be opened), then fails to read."""

    def __init__(self, camera: ScriptedCamera, frames: int | None) -> None:
        self.camera = camera
        self.frames = frames
        self.released = False

    def isOpened(self) -> bool:  # noqa: N802 (OpenCV's name)
        return self.frames is not None

    def read(self) -> tuple[bool, NDArray[np.uint8] | None]:
        if not self.frames:
            return False, None
        self.frames -= 1
        self.camera.delivered += 1
        return True, np.full((32, 32, 3), 20 * self.camera.delivered, dtype=np.uint8)

    def get(self, prop: int) -> float:
        return 25.0

    def release(self) -> None:
        self.released = True


class ScriptedCamera:
    """Stands in for cv2.VideoCapture: each open takes the next entry of `sessions`; frame k of
    all sessions together is filled with 20 * (k + 1)."""

    def __init__(self, sessions: list[int | None]) -> None:
        self.sessions = list(sessions)
        self.targets: list[str | int] = []
        self.captures: list[ScriptedCapture] = []
        self.delivered = 0

    def __call__(self, target: str | int) -> ScriptedCapture:
        self.targets.append(target)
        capture = ScriptedCapture(self, self.sessions.pop(0) if self.sessions else None)
        self.captures.append(capture)
        return capture


def _pixel(jpeg: bytes) -> int:
    image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    return round(float(image.mean()))


@pytest.mark.parametrize(("source", "target"), [("0", 0), ("rtsp://x", "rtsp://x")])
def test_a_live_source_is_opened_again_with_backoff(monkeypatch: pytest.MonkeyPatch, source: str,
                                                    target: str | int) -> None:
    camera = ScriptedCamera([None, 2, None, None, 3, None, None, None])
    monkeypatch.setattr(frame_sources.cv2, "VideoCapture", camera)
    live = open_source(source, ReopenPolicy(first_backoff_s=0.5, max_backoff_s=2.0, max_attempts=3))
    assert isinstance(live, CaptureSource) and live.live and live.native_fps is None
    assert live.capture is None  # not opened yet, and no error: it is tried again
    waits: list[float] = []

    def no_wait(timeout: float) -> bool:  # record the backoff instead of sleeping through it
        waits.append(timeout)
        return False

    monkeypatch.setattr(live._stopped, "wait", no_wait)
    frames = list(live.frames())
    live.close()
    assert [f.frame_id for f in frames] == ["0", "1", "2", "3", "4"]
    assert [_pixel(f.jpeg) for f in frames] == [20, 40, 60, 80, 100]
    # Opened: at start (fails), again (2 frames), twice more in vain, a third time (3 frames),
    # then three vain attempts and it gives up. A delivered frame resets the backoff.
    assert camera.targets == [target] * 8
    assert waits == [0.5, 0.5, 1.0, 2.0, 0.5, 1.0, 2.0]
    assert all(c.released for c in camera.captures)


def test_stop_ends_a_source_that_never_opens(monkeypatch: pytest.MonkeyPatch) -> None:
    camera = ScriptedCamera([])
    monkeypatch.setattr(frame_sources.cv2, "VideoCapture", camera)
    live = open_source("rtsp://x", ReopenPolicy(first_backoff_s=0.001, max_backoff_s=0.01))
    outcome: list[object] = []
    reader = threading.Thread(target=lambda: outcome.append(next(iter(live.frames()), None)))
    reader.start()
    opened_again = threading.Event()
    for _ in range(1000):  # a bound, not an assertion: it retries until stopped
        if len(camera.targets) >= 3:
            opened_again.set()
            break
        opened_again.wait(0.01)
    live.stop()
    reader.join(30)
    assert opened_again.is_set() and not reader.is_alive() and outcome == [None]


def test_a_video_file_that_cannot_be_opened_is_refused(tmp_path: Path) -> None:
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"not a video")
    with pytest.raises(ValueError, match="cannot open video source"):
        open_source(str(clip))


def test_an_opencv_without_video_input_is_a_clear_error(monkeypatch: pytest.MonkeyPatch,
                                                         tmp_path: Path) -> None:
    """The service image's OpenCV is built without videoio: a video source says so and what to do."""
    monkeypatch.delattr(cv2, "VideoCapture")
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"a video")
    for source in (str(clip), "rtsp://127.0.0.1:1/stream", "0"):
        with pytest.raises(ValueError, match=r"no video input.*pip install"):
            open_source(source)
    (tmp_path / "frames").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "a.jpg"), np.zeros((8, 8, 3), np.uint8))
    assert next(open_source(str(tmp_path / "frames")).frames()).jpeg[:2] == b"\xff\xd8"  # images still read


@pytest.mark.parametrize("policy", [
    {"first_backoff_s": 0.0}, {"first_backoff_s": 2.0, "max_backoff_s": 1.0}, {"max_attempts": -1},
])
def test_invalid_reopen_policies_are_refused(policy: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        ReopenPolicy(**policy)  # type: ignore[arg-type]
