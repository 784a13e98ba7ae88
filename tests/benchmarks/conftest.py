"""Fixtures of the benchmark tests: the service tests' plumbing test-double model."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# The test-double model lives with the service tests (tests/service is not a package).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "service"))

from service_doubles import save_double_model


@pytest.fixture(scope="session")
def double_model_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return save_double_model(tmp_path_factory.mktemp("models") / "double.onnx")
