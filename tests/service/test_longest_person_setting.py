"""`fishloc serve --longest-person-ratio RATIO` (env FISHLOC_LONGEST_PERSON_RATIO): the bound on a
candidate's length along the ray in the pipeline's views; out of range, refused before anything
starts."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager

import pytest
from pydantic import ValidationError

from service.runner import InferenceRunner


@pytest.mark.parametrize(("argv", "env", "ratio"), [
    ([], {}, None),
    (["--longest-person-ratio", "1.8"], {}, 1.8),
    ([], {"FISHLOC_LONGEST_PERSON_RATIO": "2.5"}, 2.5),
])
def test_serve_bounds_a_persons_length_from_its_flag_or_the_environment(
        serve_runner: Callable[[list[str]], AbstractContextManager[InferenceRunner]],
        monkeypatch: pytest.MonkeyPatch, argv: list[str], env: dict[str, str], ratio: float | None) -> None:
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with serve_runner(argv) as runner:
        assert runner.pipeline.config.view.longest_person_ratio == ratio


@pytest.mark.parametrize("ratio", ["0.5", "11", "nan", "long"])
def test_a_length_bound_out_of_range_is_refused(monkeypatch: pytest.MonkeyPatch, ratio: str) -> None:
    from service.core.config import Settings

    monkeypatch.setenv("FISHLOC_LONGEST_PERSON_RATIO", ratio)
    with pytest.raises(ValidationError, match="longest_person_ratio"):
        Settings()
