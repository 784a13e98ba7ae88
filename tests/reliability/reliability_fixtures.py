"""Fixtures of the reliability tests (load with `pytest_plugins = ["reliability_fixtures"]`)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from reliability_support import LiveServer, save_double_model, test_settings

from fisheye import FisheyeCamera, load_camera
from models import DEMO_CAMERA_PATH
from service.core.config import Settings


@pytest.fixture(scope="session")
def double_model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_double_model(tmp_path_factory.mktemp("models") / "double.onnx")


@pytest.fixture(scope="session")
def demo_camera() -> FisheyeCamera:
    return load_camera(DEMO_CAMERA_PATH)


@pytest.fixture
def settings_for(double_model_path: Path, tmp_path: Path) -> Callable[..., Settings]:
    def make(**overrides: Any) -> Settings:
        return test_settings(double_model_path, tmp_path, **overrides)

    return make


@pytest.fixture
def live_server(settings_for: Callable[..., Settings]) -> Iterator[LiveServer]:
    with LiveServer(settings_for()) as server:
        yield server


