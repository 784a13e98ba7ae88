"""The onnxruntime sessions get the thread counts and the spinning policy they are given."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contract import OnnxModel, SessionThreads
from service.runner import InferenceRunner


def _spins(session: Any) -> str:
    return str(session.get_session_options().get_session_config_entry("session.intra_op.allow_spinning"))


@pytest.mark.parametrize(("threads", "spinning", "second_set", "own_threads"), [
    (SessionThreads(2), "0", False, 2),                  # no busy-waiting pool threads
    (SessionThreads(1, spinning="on"), "1", False, 1),
    # a second, spinning set on all threads for a frame alone; frames that overlap get half each
    (SessionThreads(2, spinning="alone"), "0", True, 1),
    (SessionThreads(4, spinning="alone"), "0", True, 2),
    (SessionThreads(1, spinning="alone"), "0", True, 1),
])
def test_session_options(double_model_path: Path, threads: SessionThreads, spinning: str,
                         second_set: bool, own_threads: int) -> None:
    model = OnnxModel(double_model_path, threads)
    options = model.session.get_session_options()
    assert options.intra_op_num_threads == own_threads
    assert options.inter_op_num_threads == threads.inter_op
    assert _spins(model.session) == spinning
    assert options.get_session_config_entry("session.inter_op.allow_spinning") == spinning
    # however they wait within a run, the pools go idle when it returns (the next frame's decode)
    assert options.get_session_config_entry("session.force_spinning_stop") == "1"
    assert (model._spinning is not None) is second_set
    if model._spinning is not None:
        assert _spins(model._spinning.session) == "1"
        assert model._spinning.session.get_session_options().intra_op_num_threads == threads.intra_op


def test_alone_spins_only_while_no_other_frame_is_in_flight(double_model_path: Path) -> None:
    model = OnnxModel(double_model_path, SessionThreads(1, spinning="alone"))
    used: list[str] = []
    for sessions, name in ((model._sessions, "quiet"), (model._spinning, "spinning")):
        assert sessions is not None
        run = sessions.session.run

        def recording(*args: Any, run: Any = run, name: str = name) -> Any:
            used.append(name)
            return run(*args)

        sessions.session.run = recording  # type: ignore[method-assign]
    image = model.blank_input()
    model.run(image)                       # nothing else in flight
    with model.frame():
        model.run(image)                   # its own frame alone
        with model.frame():
            model.run(image)               # another frame in flight
        model.run(image)                   # alone again
    assert used == ["spinning", "spinning", "quiet", "spinning"]
    assert (model._frames, model._runs) == (0, 0)
    # a bad input changes nothing: the count is released with the error
    with pytest.raises(ValueError):
        model.run(np.zeros((3, 3, 3), np.uint8))
    assert model._runs == 0


def test_an_unknown_policy_is_refused() -> None:
    with pytest.raises(ValueError, match="spinning"):
        SessionThreads(1, spinning="sometimes")


@pytest.mark.parametrize(("argv", "env", "spinning", "second_set"), [
    ([], {}, "0", True),                                  # the default: "alone"
    (["--onnx-spinning", "on"], {}, "1", False),
    ([], {"FISHLOC_ONNX_SPINNING": "off"}, "0", False),
])
def test_serve_takes_the_spinning_policy_from_its_flag_or_the_environment(
        serve_runner: Callable[[list[str]], AbstractContextManager[InferenceRunner]],
        monkeypatch: pytest.MonkeyPatch, argv: list[str], env: dict[str, str], spinning: str,
        second_set: bool) -> None:
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    with serve_runner(argv) as runner:
        model = runner.pipeline.model
        assert _spins(model.session) == spinning and (model._spinning is not None) is second_set


def test_thread_counts_must_be_positive() -> None:
    with pytest.raises(ValueError):
        SessionThreads(0)


def test_a_frame_alone_gets_every_thread_for_its_unwrap(double_model_path: Path) -> None:
    model = OnnxModel(double_model_path, SessionThreads(2))
    assert model.frame_threads() == 2                  # nothing in flight
    with model.frame():
        assert model.frame_threads() == 2              # its own frame alone
        with model.frame():
            assert model.frame_threads() == 1          # frames overlap: one thread each
        assert model.frame_threads() == 2
    assert OnnxModel(double_model_path, SessionThreads(1)).frame_threads() == 1


def test_the_pipeline_unwraps_on_the_threads_the_model_gives_a_frame(
        double_model_path: Path, demo_camera: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    import cv2

    import service.pipeline as pipeline_module
    from service.pipeline import Pipeline

    pipeline = Pipeline(OnnxModel(double_model_path, SessionThreads(2)))
    asked: list[int] = []

    def recording(*args: Any) -> Any:
        asked.append(args[4])
        return real(*args)

    real = pipeline_module.view_inputs
    monkeypatch.setattr(pipeline_module, "view_inputs", recording)
    width, height = demo_camera.image_size
    ok, jpeg = cv2.imencode(".jpg", np.zeros((height, width, 3), np.uint8))
    assert ok
    pipeline.detect(jpeg.tobytes(), demo_camera)
    with pipeline.model.frame():                       # another frame in flight
        pipeline.detect(jpeg.tobytes(), demo_camera)
    assert asked == [2, 1]
