"""An ONNX model that follows FishLoc's contract, run by onnxruntime.

Contract (DESIGN.md): input `image` uint8 [N, S, S, 3] RGB letterboxed; outputs `boxes` float32
[N, K, 4] radius-aligned (cx, cy, w, h) in input px around the input's centre, and `scores` float32
[N, K] sorted descending; `fishloc.*` metadata. This is the one place that reads that contract.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

BOX_FORMAT = "cxcywh_radius_aligned"


class ModelError(RuntimeError):
    """A model file that is missing, unreadable, or does not follow the ONNX contract."""


@dataclass(frozen=True)
class ModelInfo:
    """The model's `fishloc.*` metadata and where it came from."""

    name: str
    version: str
    input_size: int
    pad_value: int
    default_min_score: float
    trained_on: str
    box_format: str
    sha256: str

    def public(self) -> dict[str, object]:
        """The fields `GET /v1/model` answers with."""
        return {
            "name": self.name, "version": self.version, "input_size": self.input_size,
            "trained_on": self.trained_on, "box_format": self.box_format,
            "default_min_score": self.default_min_score, "pad_value": self.pad_value,
            "sha256": self.sha256,
        }


@dataclass(frozen=True)
class SessionThreads:
    """onnxruntime thread counts: `intra_op` threads within an operator, `inter_op` across them.

    `allow_spinning` lets idle pool threads busy-wait for the next operator (onnxruntime's default).
    Off here: on a few shared cores the spinning threads take the CPU from the JPEG decode of the
    next frame and from other processes; `fishloc bench` measured 1.5-2x higher latency with it on
    a 2-core machine (README, Benchmark).
    """

    intra_op: int
    inter_op: int = 1
    allow_spinning: bool = False

    def __post_init__(self) -> None:
        if self.intra_op < 1 or self.inter_op < 1:
            raise ValueError(f"thread counts must be ≥ 1, got {self.intra_op}, {self.inter_op}")


def _metadata(session: ort.InferenceSession, path: Path, digest: str) -> ModelInfo:
    props = session.get_modelmeta().custom_metadata_map
    missing = [key for key in ("fishloc.input_size",) if key not in props]
    if missing:
        raise ModelError(
            f"{path}: the model lacks the metadata {', '.join(missing)} (is it a FishLoc export?)"
        )
    try:
        input_size = int(props["fishloc.input_size"])
        pad_value = int(props.get("fishloc.pad_value", "0"))
        min_score = float(props.get("fishloc.default_min_score", "0.3"))
    except ValueError as error:
        raise ModelError(f"{path}: unreadable fishloc.* metadata: {error}") from None
    box_format = props.get("fishloc.box_format", BOX_FORMAT)
    if box_format != BOX_FORMAT:
        raise ModelError(f"{path}: fishloc.box_format is {box_format!r}, the service reads {BOX_FORMAT!r}")
    if not (0 <= pad_value <= 255 and 0.0 <= min_score <= 1.0 and input_size >= 8):
        raise ModelError(f"{path}: fishloc.* metadata out of range ({props})")
    return ModelInfo(
        name=props.get("fishloc.model_name", path.stem),
        version=props.get("fishloc.model_version", "unknown"),
        input_size=input_size,
        pad_value=pad_value,
        default_min_score=min_score,
        trained_on=props.get("fishloc.trained_on", "unknown"),
        box_format=box_format,
        sha256=digest,
    )


def _check_signature(session: ort.InferenceSession, path: Path, input_size: int) -> None:
    inputs = {node.name: node for node in session.get_inputs()}
    outputs = {node.name for node in session.get_outputs()}
    if set(inputs) != {"image"} or not {"boxes", "scores"} <= outputs:
        raise ModelError(
            f"{path}: expected input 'image' and outputs 'boxes', 'scores'; the model has inputs "
            f"{sorted(inputs)} and outputs {sorted(outputs)}"
        )
    image = inputs["image"]
    if image.type != "tensor(uint8)" or len(image.shape) != 4:
        raise ModelError(f"{path}: input 'image' must be uint8 [N, S, S, 3], got {image.type} {image.shape}")
    for axis, expected in ((1, input_size), (2, input_size), (3, 3)):
        if isinstance(image.shape[axis], int) and image.shape[axis] != expected:
            raise ModelError(
                f"{path}: input 'image' has shape {image.shape}, "
                f"metadata says [N, {input_size}, {input_size}, 3]"
            )


class OnnxModel:
    """A contract-following model in an onnxruntime session with explicit thread counts."""

    def __init__(self, path: str | Path, threads: SessionThreads) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ModelError(f"model file {self.path} does not exist")
        data = self.path.read_bytes()
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads.intra_op
        options.inter_op_num_threads = threads.inter_op
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.log_severity_level = 3
        spinning = "1" if threads.allow_spinning else "0"
        options.add_session_config_entry("session.intra_op.allow_spinning", spinning)
        options.add_session_config_entry("session.inter_op.allow_spinning", spinning)
        try:
            self.session = ort.InferenceSession(
                data, sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime raises several untyped errors for bad files
            raise ModelError(f"{self.path} is not a loadable ONNX model: {error}") from None
        self.threads = threads
        self.info = _metadata(self.session, self.path, hashlib.sha256(data).hexdigest())
        _check_signature(self.session, self.path, self.info.input_size)

    def run(self, image: NDArray[np.uint8]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """(S, S, 3) uint8 letterboxed RGB -> boxes (K, 4) input px and scores (K,)."""
        size = self.info.input_size
        if image.shape != (size, size, 3) or image.dtype != np.uint8:
            raise ValueError(
                f"model input must be ({size}, {size}, 3) uint8, got {image.shape} {image.dtype}"
            )
        boxes, scores = self.session.run(["boxes", "scores"], {"image": image[None]})
        boxes = np.asarray(boxes, dtype=np.float32)
        scores = np.asarray(scores, dtype=np.float32)
        if boxes.ndim != 3 or boxes.shape[0] != 1 or boxes.shape[2] != 4 or scores.shape != boxes.shape[:2]:
            raise ModelError(f"model outputs have shapes boxes {boxes.shape}, scores {scores.shape}")
        return boxes[0], scores[0]
