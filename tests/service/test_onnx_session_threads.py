"""The onnxruntime session gets the thread counts and the spinning policy it is given."""

from __future__ import annotations

from pathlib import Path

import pytest

from contract import OnnxModel, SessionThreads


@pytest.mark.parametrize(("threads", "spinning"), [
    (SessionThreads(2), "0"),                       # the default: no busy-waiting pool threads
    (SessionThreads(1, allow_spinning=True), "1"),
])
def test_session_options(double_model_path: Path, threads: SessionThreads, spinning: str) -> None:
    options = OnnxModel(double_model_path, threads).session.get_session_options()
    assert options.intra_op_num_threads == threads.intra_op
    assert options.inter_op_num_threads == threads.inter_op
    assert options.get_session_config_entry("session.intra_op.allow_spinning") == spinning
    assert options.get_session_config_entry("session.inter_op.allow_spinning") == spinning
    # however they wait within a run, the pools go idle when it returns (the next frame's decode)
    assert options.get_session_config_entry("session.force_spinning_stop") == "1"


@pytest.mark.parametrize(("argv", "env", "spinning"), [
    ([], {}, "0"),
    (["--onnx-spinning"], {}, "1"),
    ([], {"FISHLOC_ONNX_SPINNING": "1"}, "1"),
])
def test_serve_takes_the_spinning_policy_from_its_flag_or_the_environment(
        double_model_path: Path, monkeypatch: pytest.MonkeyPatch, argv: list[str], env: dict[str, str],
        spinning: str) -> None:
    import argparse

    from service.core.metrics import ServiceMetrics
    from service.runner import build_runner
    from service.serve_cli import add_arguments, settings_from_args

    for name, value in env.items():
        monkeypatch.setenv(name, value)
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--model", str(double_model_path), "--threads", "1", *argv])
    runner = build_runner(settings_from_args(args), ServiceMetrics())
    try:
        options = runner.pipeline.model.session.get_session_options()
        assert options.get_session_config_entry("session.intra_op.allow_spinning") == spinning
    finally:
        runner.close()


def test_thread_counts_must_be_positive() -> None:
    with pytest.raises(ValueError):
        SessionThreads(0)
