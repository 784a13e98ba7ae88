"""YOLOX-Nano in torch against onnxruntime on the released ONNX it loads its weights from."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch
from numpy.typing import NDArray
from onnx import TensorProto, helper, numpy_helper
from torch import nn

from detector.yolox import (
    PERSON,
    PretrainedWeightsError,
    YoloxNano,
    class_scores,
    decode,
    keep_classes,
    load_yolox_onnx,
    to_onnx_layout,
)
from detector.yolox.onnx_weights import conv_order, match_convs
from models import ASSETS_DIR

ONNX_PATH = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"
SIZE = 416
STRIDES = (8, 16, 32)
PARITY_ATOL = 1e-4


def random_image(height: int = SIZE, width: int = SIZE, seed: int = 0) -> NDArray[np.float32]:
    """(1, 3, H, W) BGR 0-255 noise."""
    return np.random.default_rng(seed).uniform(0, 255, (1, 3, height, width)).astype(np.float32)


def smooth_image(height: int = SIZE, width: int = SIZE) -> NDArray[np.float32]:
    """(1, 3, H, W) BGR 0-255: gradients and slow waves, closer to a photograph than noise."""
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64)
    blue = 127.5 + 120 * np.sin(cols / 37.0) * np.cos(rows / 53.0)
    green = 255 * cols / width * 0.6 + 80 * np.cos((rows + cols) / 29.0) + 40
    red = 255 * rows / height * 0.7 + 60 * np.sin(np.hypot(rows - height / 3, cols - width / 2) / 17.0)
    return np.clip(np.stack([blue, green, red])[None], 0, 255).astype(np.float32)


@pytest.fixture(scope="module")
def model() -> YoloxNano:
    return load_yolox_onnx(ONNX_PATH)


@pytest.fixture(scope="module")
def session() -> ort.InferenceSession:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    return ort.InferenceSession(str(ONNX_PATH), options, providers=["CPUExecutionProvider"])


def run_torch(model: nn.Module, images: NDArray[np.float32]) -> list[torch.Tensor]:
    with torch.no_grad():
        maps: list[torch.Tensor] = model(torch.from_numpy(images))
    return maps


def numpy_decode(onnx_output: NDArray[np.float32], height: int, width: int) -> NDArray[np.float32]:
    """(B, A, 5 + C) ONNX `output` -> boxes in px: an implementation independent of `decode`."""
    cells, strides = [], []
    for s in STRIDES:
        rows, cols = np.indices((height // s, width // s))
        cells.append(np.stack([cols.ravel(), rows.ravel()], axis=1))
        strides.append(np.full(rows.size, s))
    cell = np.concatenate(cells)[None].astype(np.float64)  # (1, A, 2)
    stride = np.concatenate(strides)[None, :, None].astype(np.float64)  # (1, A, 1)
    out = onnx_output.astype(np.float64)
    return np.concatenate([(out[..., :2] + cell) * stride, np.exp(out[..., 2:4]) * stride, out[..., 4:]],
                          axis=-1)


# (a) parity with onnxruntime

@pytest.mark.parametrize("make_image", [random_image, smooth_image], ids=["random", "smooth"])
def test_torch_reproduces_onnxruntime(model: YoloxNano, session: ort.InferenceSession,
                                      make_image: Callable[[], NDArray[np.float32]]) -> None:
    images = make_image()
    expected = session.run(["output"], {"images": images})[0]  # (1, 3549, 85)
    maps = run_torch(model, images)
    got = to_onnx_layout(maps).numpy()
    assert expected.shape == got.shape == (1, 52 * 52 + 26 * 26 + 13 * 13, 85)
    assert float(np.abs(got - expected).max()) < PARITY_ATOL
    # decode() agrees with an independent decode of onnxruntime's output
    np.testing.assert_allclose(decode(maps).numpy(), numpy_decode(expected, SIZE, SIZE), rtol=1e-4, atol=1e-3)


def test_parity_catches_a_wrong_mapping(model: YoloxNano, session: ort.InferenceSession) -> None:
    # The class and box branches have identical shapes: swapping them is what a shape check misses.
    swapped = YoloxNano(model.config).eval()
    state = model.state_dict()
    for key in [k for k in state if k.startswith("head.cls_convs.0.")]:
        other = key.replace("cls_convs", "reg_convs")
        state[key], state[other] = state[other], state[key]
    swapped.load_state_dict(state)
    images = smooth_image()
    expected = session.run(["output"], {"images": images})[0]
    got = to_onnx_layout(run_torch(swapped, images)).numpy()
    assert float(np.abs(got - expected).max()) > 100 * PARITY_ATOL


def test_onnx_convs_map_to_the_torch_convs_in_forward_order(model: YoloxNano) -> None:
    proto = onnx.load(str(ONNX_PATH))
    matches = match_convs(proto, model, str(ONNX_PATH))
    assert len(matches) == 113 and len(proto.graph.initializer) == 236
    assert (matches[0].onnx_weight, matches[0].torch_conv) == ("1178", "backbone.stem.conv.conv")
    last = matches[-1]
    assert (last.onnx_weight, last.onnx_bias, last.torch_conv) == (
        "head.obj_preds.2.weight", "head.obj_preds.2.bias", "head.obj_preds.2")
    # conv_order is the order forward really runs the convolutions in
    ran: list[str] = []
    hooks = [module.register_forward_hook(lambda *_, name=name: ran.append(name))
             for name, module in model.named_modules() if isinstance(module, nn.Conv2d)]
    try:
        run_torch(model, random_image(64, 96))
    finally:
        for hook in hooks:
            hook.remove()
    # the stem's conv runs as its strided form (Focus.forward), through its weight, not its module
    assert ran == [name for name in conv_order(model) if name != "backbone.stem.conv.conv"]
    assert conv_order(model)[0] == "backbone.stem.conv.conv"


# (b) any input size that is a multiple of 32

def test_non_square_input_decodes_by_the_shape_rule(model: YoloxNano) -> None:
    height, width = 416, 832
    maps = run_torch(model, smooth_image(height, width))
    assert [tuple(m.shape) for m in maps] == [(1, 85, height // s, width // s) for s in STRIDES]
    decoded = decode(maps).numpy()
    anchors = sum((height // s) * (width // s) for s in STRIDES)
    assert decoded.shape == (1, anchors, 85)
    np.testing.assert_allclose(decoded, numpy_decode(to_onnx_layout(maps).numpy(), height, width),
                               rtol=1e-4, atol=1e-3)
    # the cell (row 3, col 40) of stride 16 sits after all 52 x 104 cells of stride 8
    index = (height // 8) * (width // 8) + 3 * (width // 16) + 40
    raw = maps[1][0, :, 3, 40].numpy()
    np.testing.assert_allclose(decoded[0, index, :4], [(raw[0] + 40) * 16, (raw[1] + 3) * 16,
                                                       np.exp(raw[2]) * 16, np.exp(raw[3]) * 16], rtol=1e-5)


def test_decode_of_zero_maps_is_the_cell_grid() -> None:
    maps = [torch.zeros(2, 6, 64 // s, 96 // s) for s in STRIDES]
    decoded = decode(maps)  # (2, 96 + 24 + 6, 6)
    assert decoded.shape == (2, 126, 6)
    np.testing.assert_array_equal(decoded[0, :3, :2].numpy(), [[0, 0], [8, 0], [16, 0]])
    np.testing.assert_array_equal(decoded[1, 12, :2].numpy(), [0, 8])  # row 1 of 12 columns
    np.testing.assert_array_equal(decoded[0, -1, :4].numpy(), [2 * 32, 1 * 32, 32, 32])
    np.testing.assert_array_equal(decoded[..., 4:].numpy(), 0.5)


# (c) a person-only copy

def test_person_only_keeps_the_person_scores(model: YoloxNano) -> None:
    person = model.to_person_only()
    assert person.config.num_classes == 1 and model.config.num_classes == 80
    images = random_image(seed=3)
    full = decode(run_torch(model, images))  # (1, A, 85)
    alone = decode(run_torch(person, images))  # (1, A, 6)
    assert alone.shape == (1, full.shape[1], 6)
    person_scores = class_scores(full)[..., PERSON]  # (1, A)
    assert float(person_scores.max()) > 1e-3  # not a comparison of zeros
    torch.testing.assert_close(class_scores(alone)[..., 0], person_scores, rtol=1e-5, atol=1e-9)
    torch.testing.assert_close(alone[..., :5], full[..., :5], rtol=1e-5, atol=1e-6)


def test_keep_classes_refuses_bad_indices(model: YoloxNano) -> None:
    for classes in ([], [80], [0, 0], [-1]):
        with pytest.raises(ValueError, match="classes"):
            keep_classes(model, classes)


# (d) files that are not YOLOX-Nano's weights

def _missing(tmp_path: Path) -> Path:
    return tmp_path / "nowhere" / "yolox_nano.onnx"


def _truncated(tmp_path: Path) -> Path:
    path = tmp_path / "truncated.onnx"
    path.write_bytes(ONNX_PATH.read_bytes()[:100_000])
    return path


def _other_model(tmp_path: Path) -> Path:
    weight = numpy_helper.from_array(np.ones((4, 3, 3, 3), np.float32), "w")
    bias = numpy_helper.from_array(np.zeros(4, np.float32), "b")
    nodes = [helper.make_node("Conv", ["x", "w", "b"], ["c"], pads=[1, 1, 1, 1]),
             helper.make_node("Relu", ["c"], ["y"])]
    graph = helper.make_graph(
        nodes, "tiny", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 8, 8])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4, 8, 8])], [weight, bias])
    proto = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)])
    onnx.checker.check_model(proto)
    path = tmp_path / "tiny.onnx"
    onnx.save(proto, str(path))
    return path


def _wrong_shape(tmp_path: Path) -> Path:
    proto = onnx.load(str(ONNX_PATH))
    for index, tensor in enumerate(proto.graph.initializer):
        if tensor.name == "head.cls_preds.1.weight":  # 81 classes instead of 80
            proto.graph.initializer[index].CopyFrom(
                numpy_helper.from_array(np.zeros((81, 64, 1, 1), np.float32), tensor.name))
    path = tmp_path / "yolox_81.onnx"
    onnx.save(proto, str(path))
    return path


@pytest.mark.parametrize("make_file", [_missing, _truncated, _other_model, _wrong_shape],
                         ids=["missing", "truncated", "not-yolox", "wrong-shape"])
def test_bad_files_raise_naming_the_file(tmp_path: Path, make_file: Callable[[Path], Path]) -> None:
    path = make_file(tmp_path)
    with pytest.raises(PretrainedWeightsError, match=re.escape(str(path))) as caught:
        load_yolox_onnx(path)
    assert isinstance(caught.value, ValueError)


@pytest.mark.parametrize("kernel_size", [1, 3])
def test_focus_runs_as_one_strided_convolution_with_the_block_stem_s_sums(kernel_size: int) -> None:
    from detector.yolox.blocks import Focus

    torch.manual_seed(2)
    stem = Focus(3, 8, kernel_size=kernel_size).eval()
    with torch.no_grad():
        stem.conv.conv.bias.normal_()
    image = torch.from_numpy(random_image(64, 96))
    blocks = torch.cat([image[..., ::2, ::2], image[..., 1::2, ::2], image[..., ::2, 1::2],
                        image[..., 1::2, 1::2]], dim=1)  # YOLOX's Focus: the 2x2 blocks as channels
    with torch.no_grad():
        torch.testing.assert_close(stem(image), stem.conv(blocks), atol=2e-4, rtol=1e-5)
    # a gradient step sees the same weight whichever way the sums run
    stem(image).sum().backward()
    assert stem.conv.conv.weight.grad is not None and stem.conv.conv.weight.grad.abs().sum() > 0
