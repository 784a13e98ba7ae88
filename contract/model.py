"""A contract-following ONNX model in an onnxruntime session with explicit thread counts.

Inputs and outputs are checked on load against the model's own metadata: input `image` uint8
[N, H, W, 3] (a square of `input_size` for the `fisheye` view, the strip for `polar`), outputs
`boxes` float32 [N, K, 4], `scores` float32 [N, K] and, optionally, `foot` float32 [N, K, 2].
"""

from __future__ import annotations

import dataclasses
import hashlib
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from contract.metadata import ModelError, ModelInfo, parse_metadata

FOOT_OUTPUT = "foot"


@dataclass(frozen=True)
class SessionThreads:
    """onnxruntime thread counts: `intra_op` threads within an operator, `inter_op` across them.

    `allow_spinning` lets idle pool threads busy-wait for the next operator (onnxruntime's default)
    instead of sleeping: a frame alone on the cores is answered about a fifth sooner (0.7.2, 2952²
    frames, 2 cores), for about a fifth fewer frames per second once several run at once, whose
    threads then spin against each other (README, "Spinning inference threads"). Off by default;
    `fishloc serve --onnx-spinning` turns it on. Either way the pools stop spinning as soon as a
    run returns (`session.force_spinning_stop`), so they never take the CPU from the next frame's
    decode.
    """

    intra_op: int
    inter_op: int = 1
    allow_spinning: bool = False

    def __post_init__(self) -> None:
        if self.intra_op < 1 or self.inter_op < 1:
            raise ValueError(f"thread counts must be ≥ 1, got {self.intra_op}, {self.inter_op}")


@dataclass(frozen=True)
class RawOutputs:
    """One image's model outputs: `boxes` (K, 4) in input px (view's format), `scores` (K,)
    descending, `foot` (K, 2) input px or None when the model has no `foot` output."""

    boxes: NDArray[np.float32]
    scores: NDArray[np.float32]
    foot: NDArray[np.float32] | None = None

    def __post_init__(self) -> None:
        k = len(self.scores)
        if self.boxes.shape != (k, 4) or self.scores.shape != (k,) or (
                self.foot is not None and self.foot.shape != (k, 2)):
            foot_shape = None if self.foot is None else self.foot.shape
            raise ModelError(f"model outputs have shapes boxes {self.boxes.shape}, scores "
                             f"{self.scores.shape}, foot {foot_shape}")


def _check_dims(name: str, shape: list[object], expected: tuple[int | None, ...], path: Path) -> None:
    """`shape` (an onnxruntime shape: ints, names or None) against `expected` (None: any)."""
    if len(shape) != len(expected) or any(
            isinstance(dim, int) and want is not None and dim != want
            for dim, want in zip(shape, expected, strict=True)):
        wanted = ", ".join("?" if want is None else str(want) for want in expected)
        raise ModelError(f"{path}: '{name}' has shape {shape}, the contract wants [{wanted}]")


def _check_signature(session: ort.InferenceSession, path: Path, info: ModelInfo) -> bool:
    """Check the session's inputs and outputs against `info`; True when it has a `foot` output."""
    inputs = {node.name: node for node in session.get_inputs()}
    outputs = {node.name: node for node in session.get_outputs()}
    if set(inputs) != {"image"} or not {"boxes", "scores"} <= set(outputs):
        raise ModelError(
            f"{path}: expected input 'image' and outputs 'boxes', 'scores'; the model has inputs "
            f"{sorted(inputs)} and outputs {sorted(outputs)}"
        )
    image = inputs["image"]
    if image.type != "tensor(uint8)":
        raise ModelError(f"{path}: input 'image' must be uint8, got {image.type}")
    width, height = info.input_wh
    if info.planned:
        _check_dims("image", list(image.shape), (None, None, None, 3), path)
        if any(isinstance(dim, int) for dim in list(image.shape)[1:3]):
            raise ModelError(f"{path}: fishloc.view_planned needs a dynamic height and width, "
                             f"the input 'image' has shape {list(image.shape)}")
    else:
        _check_dims("image", list(image.shape), (None, height, width, 3), path)
    _check_dims("boxes", list(outputs["boxes"].shape), (None, None, 4), path)
    _check_dims("scores", list(outputs["scores"].shape), (None, None), path)
    if FOOT_OUTPUT in outputs:
        _check_dims(FOOT_OUTPUT, list(outputs[FOOT_OUTPUT].shape), (None, None, 2), path)
        return True
    return False


def _boxes_only(data: bytes) -> bytes:
    """An ONNX model's bytes -> those of its graph cut to the nodes `boxes` and `scores` need."""
    import onnx
    from onnx.utils import Extractor

    model = onnx.load_from_string(data)
    return bytes(Extractor(model).extract_model(["image"], ["boxes", "scores"]).SerializeToString())


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
        options.add_session_config_entry("session.force_spinning_stop", "1")  # idle between runs
        try:
            self.session = ort.InferenceSession(
                data, sess_options=options, providers=["CPUExecutionProvider"]
            )
        except Exception as error:  # onnxruntime raises several untyped errors for bad files
            raise ModelError(f"{self.path} is not a loadable ONNX model: {error}") from None
        self.threads = threads
        props = dict(self.session.get_modelmeta().custom_metadata_map)
        self.info = parse_metadata(props, str(self.path), hashlib.sha256(data).hexdigest())
        self.has_foot = _check_signature(self.session, self.path, self.info)
        self._outputs = ["boxes", "scores", FOOT_OUTPUT] if self.has_foot else ["boxes", "scores"]
        # The session of the graph cut to boxes and scores (`run_boxes`), made on first use: only a
        # view with the nadir view needs it. Where it cannot pay, the full session serves.
        self._cut: tuple[bytes, ort.SessionOptions] | None = (
            (data, options) if self.has_foot and self.info.planned else None)
        self._boxes_session: ort.InferenceSession | None = None
        self._cut_lock = threading.Lock()

    def _boxes_only_session(self) -> ort.InferenceSession | None:
        """A planned model's nadir view places its people by the box side: a second session of the
        graph cut to `boxes` and `scores` skips the foot branch there (onnxruntime runs every node
        of a graph whatever outputs are asked for; 17 against 29 ms for the 448 px crop, README
        "The nadir view ..."). None where there is nothing to skip: the full session serves. The two
        sessions run one after the other and their pools stop spinning when a run returns, so with
        `allow_spinning` too they do not spin against each other."""
        with self._cut_lock:
            if self._cut is not None:
                data, options = self._cut
                self._cut = None
                try:
                    self._boxes_session = ort.InferenceSession(
                        _boxes_only(data), sess_options=options, providers=["CPUExecutionProvider"])
                except Exception:  # a graph onnx cannot cut: the full session serves the nadir view too
                    self._boxes_session = None
            return self._boxes_session

    def blank_input(self) -> NDArray[np.uint8]:
        """An input of the model's shape filled with its pad value (for warm-up)."""
        width, height = self.info.input_wh
        return np.full((height, width, 3), self.info.pad_value, dtype=np.uint8)

    def _check_input(self, images: NDArray[np.uint8]) -> None:
        """ValueError unless `images` is a batch of inputs the model takes."""
        width, height = self.info.input_wh
        if self.info.planned:
            if images.ndim != 4 or images.shape[3] != 3 or images.shape[1] % 32 or images.shape[2] % 32 or (
                    images.dtype != np.uint8):
                raise ValueError(f"model input must be (N, H, W, 3) uint8 with H and W multiples of 32, "
                                 f"got {images.shape} {images.dtype}")
        elif images.ndim != 4 or images.shape[1:] != (height, width, 3) or images.dtype != np.uint8:
            raise ValueError(f"model input must be (N, {height}, {width}, 3) uint8, "
                             f"got {images.shape} {images.dtype}")

    def run_batch(self, images: NDArray[np.uint8]) -> list[RawOutputs]:
        """(N, H, W, 3) uint8 RGB inputs -> one RawOutputs each."""
        self._check_input(images)
        found = self.session.run(self._outputs, {"image": images})
        boxes, scores = (np.asarray(found[i], dtype=np.float32) for i in (0, 1))
        foot = np.asarray(found[2], dtype=np.float32) if self.has_foot else None
        if boxes.ndim != 3 or boxes.shape[0] != len(images):
            raise ModelError(f"model outputs have shapes boxes {boxes.shape}, scores {scores.shape}")
        return [RawOutputs(boxes[i], scores[i], None if foot is None else foot[i])
                for i in range(len(images))]

    def run(self, image: NDArray[np.uint8]) -> RawOutputs:
        """(H, W, 3) uint8 RGB input -> its RawOutputs."""
        return self.run_batch(image[None])[0]

    def run_boxes(self, image: NDArray[np.uint8]) -> RawOutputs:
        """(H, W, 3) uint8 RGB input -> its boxes and scores alone (`foot` None), without running
        the foot branch where the graph has one."""
        session = self._boxes_only_session()
        if session is None:
            return dataclasses.replace(self.run(image), foot=None)
        self._check_input(image[None])
        boxes, scores = (np.asarray(out[0], dtype=np.float32)
                         for out in session.run(["boxes", "scores"], {"image": image[None]}))
        return RawOutputs(boxes, scores)
