"""Building the service state: OpenCV's own thread pool is turned off, leaving the cores to
onnxruntime and to frames processed in parallel."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import cv2
import pytest

from service.core.config import Settings
from service.server import build_state


@pytest.fixture
def opencv_threads() -> Iterator[None]:
    """Put OpenCV's thread count back as it was (it is global to the process)."""
    before = cv2.getNumThreads()
    yield
    cv2.setNumThreads(before)


@pytest.mark.usefixtures("opencv_threads")
def test_building_the_state_leaves_opencv_one_thread(settings_for: Callable[..., Settings]) -> None:
    cv2.setNumThreads(4)
    assert cv2.getNumThreads() == 4  # so the check below sees the build's doing
    state = build_state(settings_for(threads=2))
    try:
        assert cv2.getNumThreads() == 1
    finally:
        state.runner.close()
        state.registry.close()
