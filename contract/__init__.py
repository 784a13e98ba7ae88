"""The one reader of FishLoc's ONNX model contract (DESIGN.md), torch-free.

The service, `fishloc eval`, the benchmarks and the exporter's parity check all run models through
this package, so that what is evaluated is exactly what is served:

- `metadata`: the `fishloc.*` metadata of both views (`fisheye`, `polar`), read and written;
- `model`: an onnxruntime session whose inputs and outputs are checked against the contract;
- `views`: how a decoded frame becomes the model's input and how its outputs map back to frame px;
- `detect`: score threshold, rotated NMS and the typed per-frame result.
"""

from contract.detect import (
    FrameDetections,
    ModelRunner,
    merge_outputs,
    reduce_like_decode,
    run_view,
    select_detections,
    view_inputs,
)
from contract.metadata import (
    BOX_FORMATS,
    VIEW_FISHEYE,
    VIEW_POLAR,
    ModelError,
    ModelInfo,
    OperatingPoint,
    PolarSpec,
    metadata_props,
    parse_metadata,
)
from contract.model import OnnxModel, RawOutputs, SessionThreads
from contract.views import FisheyeInput, InputMapping, PolarInput, min_decoded_side, polar_grid, prepare_input

__all__ = [
    "BOX_FORMATS",
    "VIEW_FISHEYE",
    "VIEW_POLAR",
    "FisheyeInput",
    "FrameDetections",
    "InputMapping",
    "ModelError",
    "ModelInfo",
    "ModelRunner",
    "OnnxModel",
    "OperatingPoint",
    "PolarInput",
    "PolarSpec",
    "RawOutputs",
    "SessionThreads",
    "merge_outputs",
    "metadata_props",
    "min_decoded_side",
    "parse_metadata",
    "polar_grid",
    "prepare_input",
    "reduce_like_decode",
    "run_view",
    "select_detections",
    "view_inputs",
]
