"""`fishloc serve --second-look N` (env FISHLOC_SECOND_LOOK): the patches of the second look the
pipeline's views are planned with; out of range, refused before anything starts."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

import pytest
from pydantic import ValidationError

from fisheye.view_plan import MAX_SECOND_LOOK_PATCHES
from service.runner import InferenceRunner


@pytest.mark.parametrize(("argv", "env", "patches"), [
    ([], {}, 12),
    (["--second-look", "0"], {}, 0),
    ([], {"FISHLOC_SECOND_LOOK": "5"}, 5),
])
def test_serve_plans_the_second_look_from_its_flag_or_the_environment(
        serve_runner: Callable[[list[str]], AbstractContextManager[InferenceRunner]],
        monkeypatch: pytest.MonkeyPatch, argv: list[str], env: dict[str, str], patches: int) -> None:
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with serve_runner(argv) as runner:
        assert runner.pipeline.config.view.second_look_patches == patches


@pytest.mark.parametrize("patches", ["-1", str(MAX_SECOND_LOOK_PATCHES + 1)])
def test_a_second_look_out_of_range_is_refused(monkeypatch: pytest.MonkeyPatch, patches: str) -> None:
    from service.core.config import Settings

    monkeypatch.setenv("FISHLOC_SECOND_LOOK", patches)
    with pytest.raises(ValidationError, match="second_look"):
        Settings()
