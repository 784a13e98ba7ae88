"""Training targets of the centre-heatmap head, built from radius-aligned boxes in input pixels.

Each person puts a Gaussian peak (value 1) on the stride-4 cell nearest its box centre, and at that
cell the regression targets: `log w`, `log h` (input px) and the centre's offset from the cell centre
along the ray and across it (cells). Radius alignment is about the input centre, as in `decode`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor

from detector.model import STRIDE

FloatArray = NDArray[np.float32]


@dataclass(frozen=True)
class TargetConfig:
    """Peak width: sigma = max(min_sigma_cells, sigma_scale · sqrt(w·h) / stride) cells."""

    min_sigma_cells: float = 0.7
    sigma_scale: float = 0.15
    min_size_px: float = 1.0


@dataclass(frozen=True)
class Targets:
    """Batched targets: `heatmap` (B, 1, h, w), `regression` (B, 4, h, w), `mask` (B, h, w) bool."""

    heatmap: Tensor
    regression: Tensor
    mask: Tensor


def cell_centres_px(count: int) -> NDArray[np.float64]:
    """(count,) input-pixel coordinate of the centre of each stride-4 cell along one axis."""
    return np.arange(count, dtype=np.float64) * STRIDE + (STRIDE - 1) / 2.0


def build_targets(boxes_cxcywh: NDArray[np.floating], input_size: int, config: TargetConfig
                  ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """(N, 4) boxes input px -> heatmap (h, w), regression (4, h, w), mask (h, w) of one image.

    Boxes whose centre lies outside the input are left out. Where two people share a cell, the
    later box's regression wins (the heatmap keeps the maximum of both peaks).
    """
    size = input_size // STRIDE
    heatmap = np.zeros((size, size), dtype=np.float32)
    regression = np.zeros((4, size, size), dtype=np.float32)
    mask = np.zeros((size, size), dtype=bool)
    boxes = np.asarray(boxes_cxcywh, dtype=np.float64).reshape(-1, 4)
    centre = (input_size - 1) / 2.0
    grid = np.arange(size)
    for cx, cy, w, h in boxes:
        if not (-0.5 <= cx < input_size - 0.5 and -0.5 <= cy < input_size - 0.5):
            continue
        col = int(np.clip(np.rint((cx - (STRIDE - 1) / 2) / STRIDE), 0, size - 1))
        row = int(np.clip(np.rint((cy - (STRIDE - 1) / 2) / STRIDE), 0, size - 1))
        cell_x, cell_y = col * STRIDE + (STRIDE - 1) / 2, row * STRIDE + (STRIDE - 1) / 2
        dx, dy = cell_x - centre, cell_y - centre
        radius = float(np.hypot(dx, dy))
        cos_phi, sin_phi = (dx / radius, dy / radius) if radius > 1e-6 else (0.0, 0.0)
        off_x, off_y = (cx - cell_x) / STRIDE, (cy - cell_y) / STRIDE
        w_px, h_px = max(float(w), config.min_size_px), max(float(h), config.min_size_px)
        regression[:, row, col] = (
            np.log(w_px), np.log(h_px),
            off_x * cos_phi + off_y * sin_phi,  # along the ray
            -off_x * sin_phi + off_y * cos_phi,  # across it
        )
        mask[row, col] = True
        sigma = max(config.min_sigma_cells, config.sigma_scale * np.sqrt(w_px * h_px) / STRIDE)
        reach = int(np.ceil(3 * sigma))
        rows = grid[max(0, row - reach):row + reach + 1]
        cols = grid[max(0, col - reach):col + reach + 1]
        peak = np.exp(-((rows[:, None] - row) ** 2 + (cols[None, :] - col) ** 2) / (2 * sigma ** 2))
        window = heatmap[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
        np.maximum(window, peak.astype(np.float32), out=window)
    return heatmap, regression, mask


def build_batch_targets(boxes: Sequence[NDArray[np.floating]], input_size: int, config: TargetConfig,
                        device: torch.device | None = None) -> Targets:
    """One (N_i, 4) box array per image -> batched Targets tensors."""
    built = [build_targets(b, input_size, config) for b in boxes]
    heatmap = torch.from_numpy(np.stack([b[0] for b in built]))[:, None]
    regression = torch.from_numpy(np.stack([b[1] for b in built]))
    mask = torch.from_numpy(np.stack([b[2] for b in built]))
    return Targets(heatmap.to(device), regression.to(device), mask.to(device))
