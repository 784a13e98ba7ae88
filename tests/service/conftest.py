"""Fixtures of the service tests: the plumbing test-double model, the demo camera, server settings."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from service_doubles import save_double_model
from service_live_server import LiveServer

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
    """Settings of a test server: the double model, a fresh SQLite file, free ports, one thread."""

    def make(**overrides: Any) -> Settings:
        values: dict[str, Any] = {
            "model": double_model_path, "database": str(tmp_path / "cameras.db"), "http_port": 0,
            "grpc_port": -1, "threads": 1, "log_json": True,
        }
        values.update(overrides)
        return Settings(**values)

    return make


@pytest.fixture
def live_server(settings_for: Callable[..., Settings]) -> Iterator[LiveServer]:
    with LiveServer(settings_for()) as server:
        yield server
