"""Export parity: the same frames through torch and onnxruntime must give the same detections.

Both outputs are compared as sets, since two peaks of (nearly) equal score may leave `topk` in either
order: every entry of one output with a score of at least `BOX_SCORE_FLOOR` needs an entry of the
other whose score is within `score_atol` and whose box is within `box_atol_px` on every coordinate,
and the number of detections above the model's threshold must agree. A model with a `foot` output
has its foot points compared with their box, as two more coordinates. Lower entries are left out: in
flat, low heatmap regions (an untrained head, the black outside of the image circle) the 3x3 peak
test flips between neighbouring cells with rounding at the 1e-7 level, and such entries are never
detections.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn

from contract import OnnxModel

SCORE_ATOL = 1e-4
BOX_ATOL_PX = 1e-2
BOX_SCORE_FLOOR = 0.05


class ParityError(RuntimeError):
    """Torch and onnxruntime disagree on an exported model."""


@dataclass(frozen=True)
class ParityReport:
    frames: int
    max_score_error: float
    max_box_error_px: float
    detections_above_threshold: int
    threshold: float


def _worst_match(boxes_a: NDArray[np.float32], scores_a: NDArray[np.float32],
                 boxes_b: NDArray[np.float32], scores_b: NDArray[np.float32],
                 score_atol: float, box_atol_px: float) -> tuple[float, float]:
    """Over the entries of `a` above the floor: the (score, box) error of their best partner in `b`,
    worst case; a partner must be within both tolerances (inf, inf when one has none)."""
    keep = scores_a >= BOX_SCORE_FLOOR
    boxes_a, scores_a = boxes_a[keep], scores_a[keep]
    if len(scores_a) == 0:
        return 0.0, 0.0
    score_error = np.abs(scores_a[:, None] - scores_b[None, :])  # (Ka, Kb)
    box_error = np.abs(boxes_a[:, None, :] - boxes_b[None, :, :]).max(axis=2)  # (Ka, Kb) px
    cost = np.maximum(score_error / score_atol, box_error / box_atol_px)
    best = cost.argmin(axis=1)
    rows = np.arange(len(best))
    if np.any(cost[rows, best] > 1.0):
        return math.inf, math.inf
    return float(score_error[rows, best].max()), float(box_error[rows, best].max())


def synthetic_parity_frames(input_size: int, count: int = 4, seed: int = 0,
                            width: int | None = None) -> NDArray[np.uint8]:
    """(count, S, W, 3) uint8 frames (W = S unless given): a lit disc with blobs of several sizes
    (no two alike)."""
    import cv2

    rng = np.random.default_rng(seed)
    frame_w = input_size if width is None else width
    frames = np.zeros((count, input_size, frame_w, 3), dtype=np.uint8)
    centre = (frame_w // 2, input_size // 2)
    for frame in frames:
        cv2.circle(frame, centre, input_size // 2 - 2,
                   tuple(int(c) for c in rng.integers(60, 160, 3)), -1)
        for _ in range(12 * frame_w // input_size):
            axes = (int(rng.integers(2, input_size // 12)), int(rng.integers(2, input_size // 8)))
            cv2.ellipse(frame, (int(rng.integers(0, frame_w)), int(rng.integers(0, input_size))),
                        axes, float(rng.uniform(0, 180)), 0, 360,
                        tuple(int(c) for c in rng.integers(0, 256, 3)), -1)
        noise = rng.integers(-12, 13, frame.shape)
        frame[:] = np.clip(frame.astype(np.int64) + noise, 0, 255).astype(np.uint8)
    return frames


def check_parity(torch_model: nn.Module, model: OnnxModel, frames: NDArray[np.uint8],
                 threshold: float, score_atol: float = SCORE_ATOL,
                 box_atol_px: float = BOX_ATOL_PX) -> ParityReport:
    """Run model inputs `frames` (N, H, W, 3) uint8 through both (onnxruntime through the contract's
    reader, as the service runs it); ParityError when they disagree."""
    with torch.no_grad():
        torch_outputs = torch_model(torch.from_numpy(frames))
    torch_boxes = torch_outputs[0].numpy()
    torch_scores = torch_outputs[1].numpy()
    raw = model.run_batch(frames)
    onnx_boxes = np.stack([r.boxes for r in raw])
    onnx_scores = np.stack([r.scores for r in raw])
    torch_foot = torch_outputs[2].numpy() if len(torch_outputs) > 2 else None
    feet = [r.foot for r in raw if r.foot is not None]
    onnx_foot = np.stack(feet) if feet and len(feet) == len(raw) else None
    if (torch_foot is None) != (onnx_foot is None):
        raise ParityError(f"the foot output is in {'torch' if onnx_foot is None else 'onnxruntime'} only")
    if torch_foot is not None and onnx_foot is not None:
        torch_boxes = np.concatenate([torch_boxes, torch_foot], axis=-1)  # (N, K, 6)
        onnx_boxes = np.concatenate([onnx_boxes, onnx_foot], axis=-1)
    if onnx_boxes.shape != torch_boxes.shape or onnx_scores.shape != torch_scores.shape:
        raise ParityError(f"output shapes differ: torch {torch_boxes.shape}/{torch_scores.shape}, "
                          f"onnx {onnx_boxes.shape}/{onnx_scores.shape}")
    score_error = box_error = 0.0
    above = 0
    for i in range(len(frames)):
        for a, b in ((0, 1), (1, 0)):
            pair = ((onnx_boxes[i], onnx_scores[i]), (torch_boxes[i], torch_scores[i]))
            errors = _worst_match(*pair[a], *pair[b], score_atol, box_atol_px)
            if not math.isfinite(errors[0]):
                side = "onnxruntime" if a == 0 else "torch"
                raise ParityError(f"frame {i}: a {side} detection (score >= {BOX_SCORE_FLOOR}) has no "
                                  f"counterpart within {score_atol:g} in score and {box_atol_px:g} px")
            score_error, box_error = max(score_error, errors[0]), max(box_error, errors[1])
        n_onnx = int((onnx_scores[i] >= threshold).sum())
        n_torch = int((torch_scores[i] >= threshold).sum())
        if n_onnx != n_torch:
            raise ParityError(f"frame {i}: {n_onnx} detections above {threshold} in onnxruntime, "
                              f"{n_torch} in torch")
        above += n_onnx
    return ParityReport(len(frames), score_error, box_error, above, threshold)
