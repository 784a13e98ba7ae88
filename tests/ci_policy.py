"""What a test does when something it needs is missing here: skip on a developer's machine, fail in
CI (`CI=true`, which `.ci/run` sets), where `.ci/run` installs everything the tests need."""

from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() == "true"


def skip_or_fail_in_ci(reason: str, ci_message: str | None = None) -> None:
    """pytest.skip(reason) here; in CI pytest.fail(ci_message or reason)."""
    if in_ci():
        pytest.fail(ci_message or reason)
    pytest.skip(reason)
