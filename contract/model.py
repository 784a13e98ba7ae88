"""A contract-following ONNX model in an onnxruntime session with explicit thread counts.

Inputs and outputs are checked on load against the model's own metadata: input `image` uint8
[N, H, W, 3] (a square of `input_size` for the `fisheye` view, the strip for `polar`), outputs
`boxes` float32 [N, K, 4], `scores` float32 [N, K] and, optionally, `foot` float32 [N, K, 2].
"""

from __future__ import annotations

import contextlib
import hashlib
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray

from contract.metadata import ModelError, ModelInfo, parse_metadata

FOOT_OUTPUT = "foot"


# How a model's thread pools wait between a run's operators (`SessionThreads.spinning`).
SpinningPolicy = Literal["off", "alone", "on"]
SPINNING_POLICIES: tuple[str, ...] = get_args(SpinningPolicy)


@dataclass(frozen=True)
class SessionThreads:
    """onnxruntime thread counts: `intra_op` threads within an operator, `inter_op` across them.

    `spinning` says whether idle pool threads busy-wait for the next operator (onnxruntime's
    `allow_spinning`) instead of sleeping until they are woken, about 600 times a run of the
    shipped graph:
    - "off": they sleep;
    - "on": they spin in every run; a frame alone on the cores is answered about a fifth sooner
      (0.7.2, 2952² frames, 2 cores), and once several frames run at once their threads spin
      against each other, for about a fifth fewer frames per second;
    - "alone": a frame that has the model to itself (`OnnxModel.frame`) runs in sessions whose
      pools spin on all `intra_op` threads; a frame that shares it, in sessions of half the
      threads whose pools sleep: the latency of "on" for one stream, and more frames per second
      than "off" for several (README, "Spinning inference threads").
    Whichever, pools stop spinning as soon as a run returns (`session.force_spinning_stop`), so
    they never take the CPU from the next frame's decode.
    """

    intra_op: int
    inter_op: int = 1
    spinning: SpinningPolicy = "off"

    def __post_init__(self) -> None:
        if self.intra_op < 1 or self.inter_op < 1:
            raise ValueError(f"thread counts must be ≥ 1, got {self.intra_op}, {self.inter_op}")
        if self.spinning not in SPINNING_POLICIES:
            raise ValueError(f"spinning must be one of {SPINNING_POLICIES}, got {self.spinning!r}")


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


def session_options(threads: SessionThreads, spinning: bool, intra_op: int) -> ort.SessionOptions:
    """onnxruntime's options for a session of the service's: `intra_op` threads, pools that spin or
    sleep (`SessionThreads`), every graph optimisation, sequential execution."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = intra_op
    options.inter_op_num_threads = threads.inter_op
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    options.log_severity_level = 3
    flag = "1" if spinning else "0"
    options.add_session_config_entry("session.intra_op.allow_spinning", flag)
    options.add_session_config_entry("session.inter_op.allow_spinning", flag)
    options.add_session_config_entry("session.force_spinning_stop", "1")  # idle between runs
    return options


class _Sessions:
    """The model's graph in one onnxruntime session, and the graph cut to `boxes` and `scores`
    (`run_boxes`) in a second one, made on first use: only a view with the nadir view needs it.
    A planned model's nadir view places its people by the box side, and onnxruntime runs every
    node of a graph whatever outputs are asked for: the cut skips the foot branch there (17
    against 29 ms for the 448 px crop, docs/DETECTOR.md "The nadir view ..."). Where there is nothing to
    skip, or onnx cannot cut the graph, the full session serves."""

    def __init__(self, session: ort.InferenceSession, cut: tuple[bytes, ort.SessionOptions] | None) -> None:
        self.session = session
        self._cut = cut
        self._boxes_session: ort.InferenceSession | None = None
        self._lock = threading.Lock()

    def boxes_session(self) -> ort.InferenceSession:
        with self._lock:
            if self._cut is not None:
                data, options = self._cut
                self._cut = None
                try:
                    self._boxes_session = ort.InferenceSession(
                        _boxes_only(data), sess_options=options, providers=["CPUExecutionProvider"])
                except Exception:  # a graph onnx cannot cut: the full session serves the nadir view too
                    self._boxes_session = None
            return self._boxes_session or self.session


class OnnxModel:
    """A contract-following model in onnxruntime sessions with explicit thread counts and a
    spinning policy (`SessionThreads`)."""

    def __init__(self, path: str | Path, threads: SessionThreads) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ModelError(f"model file {self.path} does not exist")
        data = self.path.read_bytes()
        # Under "alone" the model's own sessions serve frames that overlap: each gets half the
        # threads, sleeping, so that two frames at once share the cores without waking each
        # other's pools (on 2 cores one thread each, no wake-ups at all).
        shared = max(1, threads.intra_op // 2) if threads.spinning == "alone" else threads.intra_op
        options = session_options(threads, spinning=threads.spinning == "on", intra_op=shared)
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
        cuts = self.has_foot and self.info.planned
        self._sessions = _Sessions(self.session, (data, options) if cuts else None)
        # "alone": the same graph again in sessions whose pools spin, for a frame that has the model
        # to itself; `_frames` and `_runs` count what is in flight (`frame`, `_chosen`).
        self._spinning: _Sessions | None = None
        if threads.spinning == "alone":
            spin = session_options(threads, spinning=True, intra_op=threads.intra_op)
            self._spinning = _Sessions(
                ort.InferenceSession(data, sess_options=spin, providers=["CPUExecutionProvider"]),
                (data, spin) if cuts else None)
        self._frames = 0
        self._runs = 0
        self._count_lock = threading.Lock()

    @contextlib.contextmanager
    def frame(self) -> Iterator[None]:
        """Marks one frame in flight, from its decode to its last run: under the "alone" policy a
        run spins only while no other frame is in flight (`SessionThreads`)."""
        with self._count_lock:
            self._frames += 1
        try:
            yield
        finally:
            with self._count_lock:
                self._frames -= 1

    def frame_threads(self) -> int:
        """The threads a frame's own work beside inference (its unwrap) may take now: every
        `intra_op` thread while at most that frame is in flight (`frame`), one while frames overlap,
        so that the cores a lone frame leaves idle serve it and overlapping frames do not fight."""
        with self._count_lock:
            return self.threads.intra_op if self._frames <= 1 else 1

    @contextlib.contextmanager
    def _chosen(self) -> Iterator[_Sessions]:
        """The sessions a run goes to: the spinning ones where the policy is "alone" and nothing
        else is in flight (at most this run's own frame, no other run), else the model's own."""
        with self._count_lock:
            alone = self._frames <= 1 and self._runs == 0
            chosen = self._spinning if alone and self._spinning is not None else self._sessions
            self._runs += 1
        try:
            yield chosen
        finally:
            with self._count_lock:
                self._runs -= 1

    def warm_up(self, image: NDArray[np.uint8], boxes_image: NDArray[np.uint8] | None = None) -> None:
        """One run of `image` (and a boxes-only run of `boxes_image`) in every session set the
        policy may choose, so that no frame pays for a session's lazy set-up."""
        for sessions in (self._sessions, self._spinning):
            if sessions is not None:
                self._run_in(sessions.session, self._outputs, image[None])
                if boxes_image is not None:
                    self._run_in(sessions.boxes_session(), ["boxes", "scores"], boxes_image[None])

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

    def _run_in(self, session: ort.InferenceSession, outputs: list[str], images: NDArray[np.uint8]
                ) -> list[NDArray[Any]]:
        self._check_input(images)
        return [np.asarray(out) for out in session.run(outputs, {"image": images})]

    def run_batch(self, images: NDArray[np.uint8]) -> list[RawOutputs]:
        """(N, H, W, 3) uint8 RGB inputs -> one RawOutputs each."""
        with self._chosen() as sessions:
            found = self._run_in(sessions.session, self._outputs, images)
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
        the foot branch where the graph has one (`_Sessions`)."""
        with self._chosen() as sessions:
            found = self._run_in(sessions.boxes_session(), ["boxes", "scores"], image[None])
        boxes, scores = (np.asarray(found[i][0], dtype=np.float32) for i in (0, 1))
        return RawOutputs(boxes, scores)
