"""INT8 static quantisation (onnxruntime QDQ, per-channel weights) of an exported FishLoc model.

Only the convolutions are quantised: the decode at the end of the graph (sigmoid, max-pool peak test,
top-K, box geometry) stays float so that scores and coordinates keep their precision. Calibration
runs the float model over letterboxed frames. `integer_op_counts` reads the graph that onnxruntime
actually runs (after its fusions) to show that the quantised convolutions became integer kernels.
"""

from __future__ import annotations

import tempfile
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from numpy.typing import NDArray
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_static,
)

INTEGER_CONV_OPS = ("QLinearConv", "ConvInteger")


class _FramesReader(CalibrationDataReader):
    def __init__(self, frames: NDArray[np.uint8], batch: int = 1) -> None:
        self._batches: Iterator[NDArray[np.uint8]] = iter(
            [frames[i:i + batch] for i in range(0, len(frames), batch)])

    def get_next(self) -> dict[str, NDArray[np.uint8]] | None:
        batch = next(self._batches, None)
        return None if batch is None else {"image": batch}


def quantize_int8(float_model: str | Path, output: str | Path, calibration_frames: NDArray[np.uint8]
                  ) -> None:
    """Write an INT8 QDQ model calibrated on (N, S, S, 3) uint8 letterboxed frames."""
    if len(calibration_frames) == 0:
        raise ValueError("INT8 calibration needs at least one frame")
    quantize_static(
        str(float_model),
        str(output),
        _FramesReader(calibration_frames),
        quant_format=QuantFormat.QDQ,
        op_types_to_quantize=["Conv"],
        per_channel=True,
        activation_type=QuantType.QUInt8,
        weight_type=QuantType.QInt8,
        calibrate_method=CalibrationMethod.MinMax,
    )
    # quantize_static drops nothing from metadata_props on current versions; make sure of it.
    source, quantized = onnx.load(str(float_model)), onnx.load(str(output))
    present = {p.key for p in quantized.metadata_props}
    for prop in source.metadata_props:
        if prop.key not in present:
            quantized.metadata_props.add(key=prop.key, value=prop.value)
    onnx.save(quantized, str(output))


def integer_op_counts(model_path: str | Path) -> dict[str, int]:
    """Op-type counts of the graph onnxruntime executes on the CPU (after graph optimisation)."""
    with tempfile.TemporaryDirectory() as folder:
        optimized = Path(folder) / "optimized.onnx"
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED
        options.optimized_model_filepath = str(optimized)
        ort.InferenceSession(str(model_path), options, providers=["CPUExecutionProvider"])
        graph = onnx.load(str(optimized)).graph
        return dict(Counter(node.op_type for node in graph.node))


def check_integer_convolutions(model_path: str | Path) -> dict[str, int]:
    """RuntimeError unless every convolution of the optimised graph is an integer kernel."""
    counts = integer_op_counts(model_path)
    integer = sum(counts.get(op, 0) for op in INTEGER_CONV_OPS)
    float_convs = counts.get("Conv", 0) + counts.get("FusedConv", 0)
    if integer == 0 or float_convs > 0:
        raise RuntimeError(
            f"{model_path}: onnxruntime runs {integer} integer and {float_convs} float convolutions; "
            "the quantised model does not execute its convolutions as integer kernels"
        )
    return counts
