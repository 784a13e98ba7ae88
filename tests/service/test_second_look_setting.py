"""`fishloc serve --second-look PIXELS` (env FISHLOC_SECOND_LOOK): the px the second look's patches
may take in the pipeline's views; out of range, refused before anything starts."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

import pytest
from pydantic import ValidationError

from fisheye.camera import MAX_SECOND_LOOK_PIXELS
from service.runner import InferenceRunner


@pytest.mark.parametrize(("argv", "env", "pixels"), [
    ([], {}, 0),
    (["--second-look", "786432"], {}, 786432),
    ([], {"FISHLOC_SECOND_LOOK": "50000"}, 50000),
])
def test_serve_plans_the_second_look_from_its_flag_or_the_environment(
        serve_runner: Callable[[list[str]], AbstractContextManager[InferenceRunner]],
        monkeypatch: pytest.MonkeyPatch, argv: list[str], env: dict[str, str], pixels: int) -> None:
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with serve_runner(argv) as runner:
        assert runner.pipeline.config.view.second_look_pixels == pixels


@pytest.mark.parametrize("pixels", ["-1", str(MAX_SECOND_LOOK_PIXELS + 1)])
def test_a_second_look_out_of_range_is_refused(monkeypatch: pytest.MonkeyPatch, pixels: str) -> None:
    from service.core.config import Settings

    monkeypatch.setenv("FISHLOC_SECOND_LOOK", pixels)
    with pytest.raises(ValidationError, match="second_look"):
        Settings()
