"""NanoDet-Plus-m's COCO weights, read from its ONNX (`../shared/pretrained/nanodet-plus-m_416.onnx`)
into `NanoDetPlus`.

That file (the official ncnn release converted to ONNX) folds every BatchNorm into its
convolution and names nodes by number, so the weights are mapped by graph, as YOLOX's are
(`detector.yolox.onnx_weights`): the ONNX's Conv nodes in the order the graph runs them are paired
with the network's convolutions in the order its forward runs them (recorded by hooks on a small
input). Every pair is checked: count, weight and bias shapes, stride, groups, padding, and whether
a LeakyReLU of NanoDet's slope follows; any mismatch raises `PretrainedWeightsError`, never a
partial load.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper
from torch import Tensor, nn

from detector.nanodet.blocks import LEAKY_SLOPE, ConvAct
from detector.nanodet.network import NanoDetConfig, NanoDetPlus
from detector.yolox.onnx_weights import (
    PretrainedWeightsError,
    check_complete,
    conv_attributes,
    expected_attributes,
    read_onnx,
)

EXPECTED = "NanoDet-Plus-m's ONNX"


def conv_order(model: NanoDetPlus) -> list[str]:
    """Paths of all Conv2d modules of `model` in the order its forward runs them."""
    paths = {module: name for name, module in model.named_modules() if isinstance(module, nn.Conv2d)}
    order: list[str] = []
    hooks = [conv.register_forward_hook(lambda module, _inputs, _output: order.append(paths[module]))
             for conv in paths]
    try:
        with torch.no_grad():
            model(torch.zeros(1, 3, 64, 64))
    finally:
        for hook in hooks:
            hook.remove()
    if len(order) != len(set(order)) or set(order) != set(paths.values()):
        raise AssertionError("the forward runs some convolution twice or never")
    return order


def _activated(model: NanoDetPlus, conv_path: str) -> bool:
    parent = model.get_submodule(conv_path.rpartition(".")[0]) if "." in conv_path else model
    return isinstance(parent, ConvAct) and parent.has_act


def _leaky_slopes(proto: onnx.ModelProto) -> dict[str, float]:
    """Tensor name -> the slope of the LeakyRelu that reads it (for the tensors one reads)."""
    slopes: dict[str, float] = {}
    for node in proto.graph.node:
        if node.op_type == "LeakyRelu":
            alphas = [onnx.helper.get_attribute_value(a) for a in node.attribute if a.name == "alpha"]
            slopes[node.input[0]] = float(alphas[0]) if alphas else 0.01  # ONNX's default
    return slopes


def nanodet_state_dict_from_onnx(path: str | Path, config: NanoDetConfig | None = None
                                 ) -> dict[str, Tensor]:
    """The state dict of `NanoDetPlus(config)` (default: NanoDet-Plus-m, 80 COCO classes) read from
    the ONNX at `path`; complete by construction, every tensor checked against its parameter."""
    path = Path(path)
    proto = read_onnx(path, EXPECTED)
    model = NanoDetPlus(config)
    initializers = {tensor.name: tensor for tensor in proto.graph.initializer}
    slopes = _leaky_slopes(proto)
    nodes = [node for node in proto.graph.node if node.op_type == "Conv"]
    order = conv_order(model)
    if len(nodes) != len(order):
        raise PretrainedWeightsError(f"{path}: not NanoDet-Plus-m: {len(nodes)} Conv nodes, "
                                     f"expected {len(order)}")
    state: dict[str, Tensor] = {}
    for index, (node, conv_path) in enumerate(zip(nodes, order, strict=True)):
        where = (f"{path}: not NanoDet-Plus-m: Conv node {index} ({node.name or node.output[0]}) "
                 f"vs {conv_path}")
        conv = model.get_submodule(conv_path)
        assert isinstance(conv, nn.Conv2d) and conv.bias is not None
        if len(node.input) != 3:
            raise PretrainedWeightsError(f"{where}: no bias (is BatchNorm folded?)")
        pairs = ((node.input[1], "weight", conv.weight), (node.input[2], "bias", conv.bias))
        for name, suffix, parameter in pairs:
            tensor = initializers.get(name)
            if tensor is None:
                raise PretrainedWeightsError(f"{where}: input {name!r} is not an initializer")
            array = numpy_helper.to_array(tensor)
            if array.dtype != np.float32 or tuple(array.shape) != tuple(parameter.shape):
                raise PretrainedWeightsError(f"{where}: {name!r} is {array.dtype} {tuple(array.shape)}, "
                                             f"expected float32 {tuple(parameter.shape)}")
            state[f"{conv_path}.{suffix}"] = torch.from_numpy(array.copy())
        attributes, expected = conv_attributes(node), expected_attributes(conv)
        if attributes != expected:
            raise PretrainedWeightsError(f"{where}: attributes {attributes}, expected {expected}")
        slope = slopes.get(node.output[0])
        if (slope is not None) != _activated(model, conv_path) or (
                slope is not None and abs(slope - LEAKY_SLOPE) > 1e-6):
            raise PretrainedWeightsError(f"{where}: activation {slope}, expected "
                                         f"{LEAKY_SLOPE if _activated(model, conv_path) else None}")
    return check_complete(state, model, path)


def load_nanodet_onnx(path: str | Path) -> NanoDetPlus:
    """NanoDet-Plus-m (80 COCO classes) with the weights of the ONNX at `path`, in eval mode."""
    model = NanoDetPlus(NanoDetConfig())
    model.load_state_dict(nanodet_state_dict_from_onnx(path, model.config), strict=True)
    return model.eval()
