"""TEST DOUBLE of a `polar` model (not a detector): a real ONNX graph whose one box sits on the
centroid of the strip's bright pixels (channel sum > 600), `BOX_WH` strip px in size, score 0.9,
with an optional `foot` output at the middle of the box's bottom edge. It lets the polar view's
plumbing (unwrap, strip boxes back to radius-aligned frame boxes, foot points) be checked against
the floor point a test drew a person at."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

HEIGHT, WIDTH, OVERLAP = 64, 256, 32
BOX_WH = (8.0, 20.0)
SCORE = 0.9
METADATA = {
    "fishloc.view": "polar", "fishloc.input_size": str(HEIGHT), "fishloc.pad_value": "0",
    "fishloc.box_format": "xyxy_polar", "fishloc.model_name": "polar-double",
    "fishloc.model_version": "0.0-test", "fishloc.trained_on": "nothing (test double)",
    "fishloc.default_min_score": "0.3", "fishloc.polar_width": str(WIDTH),
    "fishloc.polar_overlap": str(OVERLAP), "fishloc.polar_max_theta_deg": "90",
}


def _const(name: str, value: np.ndarray) -> onnx.NodeProto:
    return helper.make_node("Constant", [], [name], value=numpy_helper.from_array(value, name))


def _coordinate_nodes(planned: bool, height: int, width: int) -> list[onnx.NodeProto]:
    """`xs`, `ys`: each input pixel's column and row, fixed for a strip, from the input's shape for
    a planned view (any height and width)."""
    if not planned:
        rows, cols = np.mgrid[0:height, 0:width].astype(np.float32)
        return [_const("xs", cols), _const("ys", rows)]
    return [
        helper.make_node("Shape", ["image"], ["shape"]),
        _const("i1", np.array([1], dtype=np.int64)), _const("i2", np.array([2], dtype=np.int64)),
        _const("i3", np.array([3], dtype=np.int64)),
        _const("zero", np.array(0, dtype=np.int64)), _const("one", np.array(1, dtype=np.int64)),
        helper.make_node("Slice", ["shape", "i1", "i2"], ["h1"]),
        helper.make_node("Slice", ["shape", "i2", "i3"], ["w1"]),
        helper.make_node("Squeeze", ["h1"], ["h"]), helper.make_node("Squeeze", ["w1"], ["w"]),
        helper.make_node("Range", ["zero", "h", "one"], ["row_i"]),
        helper.make_node("Range", ["zero", "w", "one"], ["col_i"]),
        helper.make_node("Cast", ["row_i"], ["row_f"], to=TensorProto.FLOAT),
        helper.make_node("Cast", ["col_i"], ["col_f"], to=TensorProto.FLOAT),
        _const("row_shape", np.array([-1, 1], dtype=np.int64)),
        helper.make_node("Reshape", ["row_f", "row_shape"], ["row_col"]),  # (H, 1)
        helper.make_node("Mul", ["row_col", "col_f"], ["zero_hw"]),  # (H, W), used for its shape
        _const("f0", np.array(0.0, dtype=np.float32)),
        helper.make_node("Mul", ["zero_hw", "f0"], ["zeros"]),
        helper.make_node("Add", ["zeros", "col_f"], ["xs"]),
        helper.make_node("Add", ["zeros", "row_col"], ["ys"]),
    ]


def build_polar_double(foot: bool = False, bad_foot: bool = False,
                       metadata: dict[str, str] | None = None, planned: bool = False,
                       score: float = SCORE) -> onnx.ModelProto:
    """The double; `bad_foot` gives it a `foot` output of 4 numbers per box (the contract says 2);
    `planned`, an input of any height and width (`fishloc.view_planned`); `score` its box's score."""
    width = WIDTH + OVERLAP
    f32 = np.float32
    half = np.array([-BOX_WH[0] / 2, -BOX_WH[1] / 2, BOX_WH[0] / 2, BOX_WH[1] / 2], dtype=f32)
    nodes = [
        *_coordinate_nodes(planned, HEIGHT, width), _const("half", half[None, None]),
        _const("axes_c", np.array([3], dtype=np.int64)), _const("axes_hw", np.array([1, 2], dtype=np.int64)),
        _const("ax1", np.array([1], dtype=np.int64)), _const("bright", np.array(600.0, dtype=f32)),
        _const("eps", np.array(1e-6, dtype=f32)), _const("score", np.array([[score]], dtype=f32)),
        _const("foot_dy", np.array([[[0.0, BOX_WH[1] / 2]]], dtype=f32)),
        helper.make_node("Cast", ["image"], ["imgf"], to=TensorProto.FLOAT),
        helper.make_node("ReduceSum", ["imgf", "axes_c"], ["gray"], keepdims=0),
        helper.make_node("Sub", ["gray", "bright"], ["over"]),
        helper.make_node("Relu", ["over"], ["weight"]),
        helper.make_node("ReduceSum", ["weight", "axes_hw"], ["total"], keepdims=0),
        helper.make_node("Add", ["total", "eps"], ["total_e"]),
        helper.make_node("Mul", ["weight", "xs"], ["wx"]),
        helper.make_node("ReduceSum", ["wx", "axes_hw"], ["sx"], keepdims=0),
        helper.make_node("Div", ["sx", "total_e"], ["cx"]),
        helper.make_node("Mul", ["weight", "ys"], ["wy"]),
        helper.make_node("ReduceSum", ["wy", "axes_hw"], ["sy"], keepdims=0),
        helper.make_node("Div", ["sy", "total_e"], ["cy"]),
        helper.make_node("Unsqueeze", ["cx", "ax1"], ["cx1"]),
        helper.make_node("Unsqueeze", ["cy", "ax1"], ["cy1"]),
        helper.make_node("Concat", ["cx1", "cy1", "cx1", "cy1"], ["centre4"], axis=1),  # (N, 4)
        helper.make_node("Unsqueeze", ["centre4", "ax1"], ["centre"]),                 # (N, 1, 4)
        helper.make_node("Add", ["centre", "half"], ["boxes"]),
        helper.make_node("Mul", ["cx1", "eps"], ["tiny"]),
        helper.make_node("Add", ["tiny", "score"], ["scores"]),                         # (N, 1)
        helper.make_node("Concat", ["cx1", "cy1"], ["centre2"], axis=1),
        helper.make_node("Unsqueeze", ["centre2", "ax1"], ["centre3"]),
        helper.make_node("Add", ["centre3", "foot_dy"], ["foot_2"]),
        helper.make_node("Identity", ["boxes" if bad_foot else "foot_2"], ["foot"]),
    ]
    outputs = [helper.make_tensor_value_info("boxes", TensorProto.FLOAT, ["N", 1, 4]),
               helper.make_tensor_value_info("scores", TensorProto.FLOAT, ["N", 1])]
    if foot or bad_foot:
        outputs.append(helper.make_tensor_value_info("foot", TensorProto.FLOAT,
                                                     ["N", 1, 4 if bad_foot else 2]))
    dims: list[str | int] = ["N", "H", "W", 3] if planned else ["N", HEIGHT, width, 3]
    graph = helper.make_graph(nodes, "fishloc_polar_double",
                              [helper.make_tensor_value_info("image", TensorProto.UINT8, dims)], outputs)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    props = METADATA if metadata is None else metadata
    helper.set_model_props(model, {**props, "fishloc.view_planned": "1"} if planned else props)
    return model


def save_polar_double(path: Path, **kwargs: object) -> Path:
    onnx.save(build_polar_double(**kwargs), str(path))  # type: ignore[arg-type]
    return path
