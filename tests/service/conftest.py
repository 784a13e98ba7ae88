"""Fixtures of the service tests: the plumbing test-double model, the demo camera, server settings."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from service_doubles import save_double_model
from service_live_server import LiveServer

from fisheye import FisheyeCamera, load_camera
from models import DEMO_CAMERA_PATH
from service.core.config import Settings
from service.runner import InferenceRunner


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


@pytest.fixture
def serve_runner(double_model_path: Path
                 ) -> Callable[[list[str]], contextlib.AbstractContextManager[InferenceRunner]]:
    """The runner `fishloc serve` builds from its flags (and the environment), the double model on
    one thread: `with serve_runner(["--flag", "value"]) as runner: ...`, closed after."""
    from service.core.metrics import ServiceMetrics
    from service.runner import build_runner
    from service.serve_cli import add_arguments, settings_from_args

    @contextlib.contextmanager
    def build(argv: list[str]) -> Iterator[InferenceRunner]:
        parser = argparse.ArgumentParser()
        add_arguments(parser)
        args = parser.parse_args(["--model", str(double_model_path), "--threads", "1", *argv])
        runner = build_runner(settings_from_args(args), ServiceMetrics())
        try:
            yield runner
        finally:
            runner.close()

    return build
