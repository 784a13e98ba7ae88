"""`python -m benchmarks.runtimes`: the network cut to its candidates, and what the command refuses."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.runtimes import block_image, main, network_graph, onnxruntime_runner, parse_size
from contract import OnnxModel, SessionThreads
from models import DEFAULT_MODEL_PATH


def test_the_cut_graph_holds_every_candidate_the_model_ranks() -> None:
    # the full graph's scores are the top of the cut graph's (its peak cells, ranked by TopK)
    image = block_image(416, 768, seed=3)
    assert image.shape == (1, 416, 768, 3) and image.dtype == np.uint8
    *candidates, ranked = onnxruntime_runner(network_graph(DEFAULT_MODEL_PATH), threads=1)(image)
    cells = ranked.shape[1]
    assert cells == (416 * 768) // 64 + (416 * 768) // 256 + (416 * 768) // 1024  # strides 8, 16, 32
    assert [c.shape[:2] for c in candidates] == [(1, cells)] * len(candidates)
    scores = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(1)).run(image[0]).scores
    assert 0 < len(scores) <= 300
    np.testing.assert_allclose(np.sort(ranked[0])[::-1][:len(scores)], scores, atol=1e-6)


def test_a_graph_without_candidates_is_refused(tmp_path: Path) -> None:
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph([helper.make_node("Relu", ["x"], ["y"])], "plain",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    onnx.save(helper.make_model(graph), tmp_path / "plain.onnx")
    with pytest.raises(ValueError, match="no candidates"):
        network_graph(tmp_path / "plain.onnx")
    assert main(["--model", str(tmp_path / "plain.onnx")]) == 2


def test_without_openvino_the_command_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "openvino", None)  # its import then raises ImportError
    assert main(["--model", str(DEFAULT_MODEL_PATH), "--runs", "1", "--input", "64x64"]) == 2
    assert "pip install openvino" in capsys.readouterr().err


@pytest.mark.parametrize("text", ["416", "416x", "0x64", "400x64", "axb"])
def test_an_input_size_is_h_x_w_in_multiples_of_32(text: str) -> None:
    assert parse_size("416X1792") == (416, 1792)
    with pytest.raises(argparse.ArgumentTypeError):
        parse_size(text)
