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


def test_thread_counts_must_be_positive() -> None:
    with pytest.raises(ValueError):
        SessionThreads(0)
