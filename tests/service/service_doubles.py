"""Test doubles for the service tests: small ONNX models that follow FishLoc's model contract.

TEST DOUBLE, not a detector. The graph is real (onnxruntime runs it on the letterboxed input), but
what it "detects" is chosen by construction, so the pipeline's plumbing can be checked exactly:

- box 0 sits at the centroid of the bright pixels of the input (channel sum > 600), with a fixed
  size; its score is 0.9 when there are bright pixels and 0 otherwise. A test draws a bright disk
  where it wants a person and knows the true box in frame pixels.
- boxes 1-3 are constants in input pixels: A (score 0.8), A' (A shifted by ~1.8 px, score 0.75, so
  rotated NMS must remove it) and C (score 0.2, under the default threshold 0.3).

Scores and boxes leave the graph sorted by TopK, as the contract asks.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

INPUT_SIZE = 256
BLOB_WH = (10.0, 24.0)  # input px (w across the ray, h along it)
BLOB_SCORE = 0.9
BRIGHT_SUM = 600.0
CONSTANT_BOXES = np.array([
    [180.0, 70.0, 12.0, 30.0],   # A
    [181.5, 71.0, 12.0, 30.0],   # A', suppressed by NMS
    [60.0, 150.0, 10.0, 24.0],   # C, low score
], dtype=np.float32)
CONSTANT_SCORES = np.array([0.8, 0.75, 0.2], dtype=np.float32)
DEFAULT_MIN_SCORE = 0.3
METADATA = {
    "fishloc.input_size": str(INPUT_SIZE),
    "fishloc.pad_value": "0",
    "fishloc.box_format": "cxcywh_radius_aligned",
    "fishloc.model_name": "plumbing-double",
    "fishloc.model_version": "0.0-test",
    "fishloc.trained_on": "nothing (test double)",
    "fishloc.default_min_score": str(DEFAULT_MIN_SCORE),
}


def _const(name: str, value: np.ndarray) -> onnx.NodeProto:
    return helper.make_node("Constant", [], [name], value=numpy_helper.from_array(value, name))


def build_double_model(size: int = INPUT_SIZE, metadata: dict[str, str] | None = None,
                       input_dtype: int = TensorProto.UINT8) -> onnx.ModelProto:
    """The test-double graph described in the module docstring, for an input of side `size`."""
    K = 1 + len(CONSTANT_BOXES)
    rows, cols = np.mgrid[0:size, 0:size].astype(np.float32)
    f32 = np.float32
    nodes = [
        _const("xs", cols), _const("ys", rows),
        _const("axes_c", np.array([3], dtype=np.int64)), _const("axes_hw", np.array([1, 2], dtype=np.int64)),
        _const("ax1", np.array([1], dtype=np.int64)), _const("ax2", np.array([2], dtype=np.int64)),
        _const("bright", np.array(BRIGHT_SUM, dtype=f32)), _const("eps", np.array(1e-6, dtype=f32)),
        _const("norm", np.array(1000.0, dtype=f32)), _const("one", np.array(1.0, dtype=f32)),
        _const("zero", np.array(0.0, dtype=f32)), _const("blob_score", np.array(BLOB_SCORE, dtype=f32)),
        _const("blob_w", np.array(BLOB_WH[0], dtype=f32)), _const("blob_h", np.array(BLOB_WH[1], dtype=f32)),
        _const("const_boxes", CONSTANT_BOXES[None]), _const("const_scores", CONSTANT_SCORES[None]),
        _const("k", np.array([K], dtype=np.int64)), _const("ones_i", np.ones((1, 1, 4), dtype=np.int64)),
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
        helper.make_node("Div", ["total", "norm"], ["t"]),
        helper.make_node("Min", ["t", "one"], ["sat"]),
        helper.make_node("Mul", ["sat", "blob_score"], ["score0"]),
        helper.make_node("Unsqueeze", ["cx", "ax1"], ["cx1"]),        # (N, 1)
        helper.make_node("Unsqueeze", ["cy", "ax1"], ["cy1"]),
        helper.make_node("Unsqueeze", ["score0", "ax1"], ["score01"]),
        helper.make_node("Mul", ["cx1", "zero"], ["zeros1"]),
        helper.make_node("Add", ["zeros1", "one"], ["ones1"]),        # (N, 1) of ones
        helper.make_node("Mul", ["ones1", "blob_w"], ["w1"]),
        helper.make_node("Mul", ["ones1", "blob_h"], ["h1"]),
        helper.make_node("Concat", ["cx1", "cy1", "w1", "h1"], ["blob_box"], axis=1),  # (N, 4)
        helper.make_node("Unsqueeze", ["blob_box", "ax1"], ["blob_box3"]),           # (N, 1, 4)
        helper.make_node("Unsqueeze", ["ones1", "ax2"], ["ones3"]),                  # (N, 1, 1)
        helper.make_node("Mul", ["ones3", "const_boxes"], ["const_boxes_n"]),       # (N, K-1, 4)
        helper.make_node("Mul", ["ones1", "const_scores"], ["const_scores_n"]),     # (N, K-1)
        helper.make_node("Concat", ["blob_box3", "const_boxes_n"], ["all_boxes"], axis=1),
        helper.make_node("Concat", ["score01", "const_scores_n"], ["all_scores"], axis=1),
        helper.make_node("TopK", ["all_scores", "k"], ["scores", "order"], axis=1, largest=1, sorted=1),
        helper.make_node("Unsqueeze", ["order", "ax2"], ["order3"]),
        helper.make_node("Mul", ["order3", "ones_i"], ["order4"]),                  # (N, K, 4)
        helper.make_node("GatherElements", ["all_boxes", "order4"], ["boxes"], axis=1),
    ]
    graph = helper.make_graph(
        nodes, "fishloc_plumbing_double",
        [helper.make_tensor_value_info("image", input_dtype, ["N", size, size, 3])],
        [helper.make_tensor_value_info("boxes", TensorProto.FLOAT, ["N", K, 4]),
         helper.make_tensor_value_info("scores", TensorProto.FLOAT, ["N", K])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    props = dict(METADATA, **{"fishloc.input_size": str(size)}) if metadata is None else metadata
    helper.set_model_props(model, props)
    onnx.checker.check_model(model)
    return model


def save_double_model(path: Path, **kwargs: object) -> Path:
    onnx.save(build_double_model(**kwargs), str(path))  # type: ignore[arg-type]
    return path
