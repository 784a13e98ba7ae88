"""YOLOX-Nano's COCO weights, read from YOLOX's own ONNX export into `YoloxNano`.

The export folds every BatchNorm into its convolution and names the results by number (`1178`,
`1179`, ...); only the head's 1x1 predictions, which have no BatchNorm, keep their torch names
(`head.cls_preds.0.weight`). So the weights are mapped by graph: the ONNX's Conv nodes, in the
order the graph runs them, are paired with `conv_order(model)`, the network's convolutions in the
order YOLOX's forward runs them. Every pair is checked (count, weight and bias shapes, stride,
groups, padding, and the name where the export kept one); any mismatch raises
`PretrainedWeightsError`, never a partial load.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper
from torch import Tensor, nn

from detector.yolox.blocks import BaseConv, Bottleneck, CSPLayer, DWConv, Focus, SPPBottleneck
from detector.yolox.network import YoloxConfig, YoloxNano

NECK_ORDER = ("lateral_conv0", "c3_p4", "reduce_conv1", "c3_p3", "bu_conv2", "c3_n3", "bu_conv1", "c3_n4")


class PretrainedWeightsError(ValueError):
    """The weights file is missing, unreadable, or not YOLOX-Nano; the message names the file."""


@dataclass(frozen=True)
class ConvMatch:
    """One convolution of the ONNX graph and the torch Conv2d it loads into."""

    onnx_weight: str  # initializer names
    onnx_bias: str
    torch_conv: str  # module path of the nn.Conv2d, e.g. "backbone.stem.conv.conv"


def _block_convs(model: nn.Module, path: str) -> list[str]:
    """Paths of the Conv2d modules of the block at `path`, in the order its forward runs them."""
    block = model.get_submodule(path)
    if isinstance(block, nn.Conv2d):
        return [path]
    if isinstance(block, BaseConv):
        return [f"{path}.conv"]
    if isinstance(block, DWConv):
        return [f"{path}.dconv.conv", f"{path}.pconv.conv"]
    if isinstance(block, Focus):
        return [f"{path}.conv.conv"]
    if isinstance(block, Bottleneck):
        return [*_block_convs(model, f"{path}.conv1"), *_block_convs(model, f"{path}.conv2")]
    if isinstance(block, CSPLayer):
        # conv1, conv2 (the bypass), then the bottlenecks on conv1's output, then conv3
        bottlenecks = [c for i in range(len(block.m)) for c in _block_convs(model, f"{path}.m.{i}")]
        return [f"{path}.conv1.conv", f"{path}.conv2.conv", *bottlenecks, f"{path}.conv3.conv"]
    if isinstance(block, SPPBottleneck):
        return [f"{path}.conv1.conv", f"{path}.conv2.conv"]
    if isinstance(block, nn.Sequential):
        return [c for i in range(len(block)) for c in _block_convs(model, f"{path}.{i}")]
    raise TypeError(f"no conv order known for {type(block).__name__} at {path}")


def conv_order(model: YoloxNano) -> list[str]:
    """Paths of all Conv2d modules of `model` in the order YOLOX's forward runs them: backbone,
    neck (top-down then bottom-up), then per level the stem, class branch and prediction, box
    branch, box and objectness predictions (the order of the Conv nodes of YOLOX's export)."""
    blocks = [f"backbone.{name}" for name in ("stem", "dark2", "dark3", "dark4", "dark5")]
    blocks += [f"neck.{name}" for name in NECK_ORDER]
    for level in range(len(model.head.stems)):
        blocks += [f"head.{name}.{level}" for name in
                   ("stems", "cls_convs", "cls_preds", "reg_convs", "reg_preds", "obj_preds")]
    order = [conv for block in blocks for conv in _block_convs(model, block)]
    every = {name for name, module in model.named_modules() if isinstance(module, nn.Conv2d)}
    if len(order) != len(set(order)) or set(order) != every:
        raise AssertionError(f"conv_order misses or repeats convolutions: {sorted(every ^ set(order))}")
    return order


def read_onnx(path: Path, expected: str = "YOLOX-Nano's ONNX export") -> onnx.ModelProto:
    """The ONNX at `path` without external data; PretrainedWeightsError naming it if unreadable."""
    if not path.is_file():
        raise PretrainedWeightsError(f"{path}: no such file (expected {expected})")
    try:
        return onnx.load(str(path), load_external_data=False)
    except Exception as error:  # protobuf's DecodeError (untyped to mypy), OSError, ...
        raise PretrainedWeightsError(f"{path}: not a readable ONNX file ({error})") from error


def conv_attributes(node: onnx.NodeProto) -> dict[str, list[int] | int | str]:
    attributes = {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}
    return {
        "kernel_shape": list(attributes.get("kernel_shape", [])),
        "strides": list(attributes.get("strides", [1, 1])),
        "pads": list(attributes.get("pads", [0, 0, 0, 0])),
        "dilations": list(attributes.get("dilations", [1, 1])),
        "group": int(attributes.get("group", 1)),
        "auto_pad": attributes.get("auto_pad", b"NOTSET").decode(),
    }


def expected_attributes(conv: nn.Conv2d) -> dict[str, list[int] | int | str]:
    assert not isinstance(conv.padding, str), "our blocks always give explicit padding"
    pad_h, pad_w = conv.padding
    return {
        "kernel_shape": list(conv.kernel_size),
        "strides": list(conv.stride),
        "pads": [pad_h, pad_w, pad_h, pad_w],
        "dilations": list(conv.dilation),
        "group": conv.groups,
        "auto_pad": "NOTSET",
    }


def match_convs(proto: onnx.ModelProto, model: YoloxNano, source: str) -> list[ConvMatch]:
    """Pair every Conv node of `proto` with a Conv2d of `model`, checking each pair; raises
    PretrainedWeightsError naming `source` on the first mismatch."""
    initializers = {tensor.name: tensor for tensor in proto.graph.initializer}
    nodes = [node for node in proto.graph.node if node.op_type == "Conv"]
    order = conv_order(model)
    if len(nodes) != len(order):
        raise PretrainedWeightsError(f"{source}: not YOLOX-Nano: {len(nodes)} Conv nodes, "
                                     f"expected {len(order)}")
    matches: list[ConvMatch] = []
    used: set[str] = set()
    for index, (node, conv_path) in enumerate(zip(nodes, order, strict=True)):
        where = f"{source}: not YOLOX-Nano: Conv node {index} ({node.name or node.output[0]}) vs {conv_path}"
        conv = model.get_submodule(conv_path)
        assert isinstance(conv, nn.Conv2d) and conv.bias is not None
        if len(node.input) != 3:
            raise PretrainedWeightsError(f"{where}: no bias (is BatchNorm folded?)")
        weight_name, bias_name = node.input[1], node.input[2]
        for name, suffix, parameter in ((weight_name, "weight", conv.weight), (bias_name, "bias", conv.bias)):
            tensor = initializers.get(name)
            if tensor is None:
                raise PretrainedWeightsError(f"{where}: input {name!r} is not an initializer")
            if name in used:
                raise PretrainedWeightsError(f"{where}: {name!r} feeds more than one convolution")
            used.add(name)
            if not name.isdigit() and name != f"{conv_path}.{suffix}":
                # Only the head's predictions (no BatchNorm to fold) keep a torch name, ours too.
                raise PretrainedWeightsError(f"{where}: named {name!r}, expected {conv_path}.{suffix}")
            if tensor.data_type != onnx.TensorProto.FLOAT:
                raise PretrainedWeightsError(f"{where}: {name!r} is not float32")
            if tuple(tensor.dims) != tuple(parameter.shape):
                raise PretrainedWeightsError(f"{where}: {name!r} has shape {tuple(tensor.dims)}, "
                                             f"expected {tuple(parameter.shape)}")
        attributes, expected = conv_attributes(node), expected_attributes(conv)
        if attributes != expected:
            raise PretrainedWeightsError(f"{where}: attributes {attributes}, expected {expected}")
        matches.append(ConvMatch(weight_name, bias_name, conv_path))
    return matches


def yolox_state_dict_from_onnx(path: str | Path, config: YoloxConfig | None = None) -> dict[str, Tensor]:
    """The state dict of `YoloxNano(config)` (default: Nano, 80 COCO classes) read from the ONNX
    at `path`; complete by construction, every tensor checked against its parameter."""
    path = Path(path)
    proto = read_onnx(path)
    model = YoloxNano(config)
    initializers = {tensor.name: tensor for tensor in proto.graph.initializer}
    state: dict[str, Tensor] = {}
    for match in match_convs(proto, model, str(path)):
        for onnx_name, suffix in ((match.onnx_weight, "weight"), (match.onnx_bias, "bias")):
            array = numpy_helper.to_array(initializers[onnx_name])
            state[f"{match.torch_conv}.{suffix}"] = torch.from_numpy(np.array(array, dtype=np.float32))
    return check_complete(state, model, path)


def check_complete(state: dict[str, Tensor], model: nn.Module, path: Path) -> dict[str, Tensor]:
    """`state` if it holds every parameter of `model` and nothing else (a network of convolutions
    alone, read from the ONNX at `path`); PretrainedWeightsError naming the file otherwise."""
    expected = set(model.state_dict())
    if set(state) != expected:
        raise PretrainedWeightsError(f"{path}: loaded {len(state)} tensors for {len(expected)} "
                                     f"parameters; missing {sorted(expected - set(state))[:5]}")
    return state


def load_yolox_onnx(path: str | Path) -> YoloxNano:
    """YOLOX-Nano (80 COCO classes) with the weights of the ONNX at `path`, in eval mode."""
    model = YoloxNano(YoloxConfig())
    model.load_state_dict(yolox_state_dict_from_onnx(path, model.config), strict=True)
    return model.eval()
