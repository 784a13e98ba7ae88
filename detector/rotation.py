"""Rotations about the principal point of the model input (its centre, ((S - 1) / 2, (S - 1) / 2)).

One convention everywhere: a rotation by `angle_rad` moves the point p to c + R(a)(p - c), with
R(a) = [[cos a, -sin a], [sin a, cos a]] in pixel coordinates (u right, v down), i.e. clockwise on
screen. Rotating an image or a feature map moves its content the same way, so rotated ground truth
lines up with rotated features. Radius-aligned boxes keep their `w` and `h` under such rotations.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numpy.typing import NDArray
from torch import Tensor
from torch.nn import functional

from detector.model import STRIDE


def rotate_points(points_px: NDArray[np.floating], angle_rad: float, input_size: int
                  ) -> NDArray[np.float64]:
    """(N, 2) input px -> (N, 2) input px rotated about the input centre."""
    centre = (input_size - 1) / 2.0
    cos_a, sin_a = math.cos(angle_rad), math.sin(angle_rad)
    offset = np.asarray(points_px, dtype=np.float64).reshape(-1, 2) - centre
    rotated = np.stack([cos_a * offset[:, 0] - sin_a * offset[:, 1],
                        sin_a * offset[:, 0] + cos_a * offset[:, 1]], axis=1)
    return rotated + centre


def rotate_boxes(boxes_cxcywh: NDArray[np.floating], angle_rad: float, input_size: int
                 ) -> NDArray[np.float64]:
    """(N, 4) radius-aligned boxes input px -> rotated (N, 4): centres move, `w`, `h` stay."""
    boxes = np.asarray(boxes_cxcywh, dtype=np.float64).reshape(-1, 4)
    return np.concatenate([rotate_points(boxes[:, :2], angle_rad, input_size), boxes[:, 2:]], axis=1)


def rotate_image(image: NDArray[np.uint8], angle_rad: float, pad_value: int = 0) -> NDArray[np.uint8]:
    """(S, S, 3) uint8 input rotated about its centre (bilinear; uncovered pixels get pad_value)."""
    import cv2

    size = image.shape[0]
    centre = (size - 1) / 2.0
    cos_a, sin_a = math.cos(angle_rad), math.sin(angle_rad)
    # Forward map src -> dst: dst = c + R(a)(src - c).
    matrix = np.array([[cos_a, -sin_a, centre - cos_a * centre + sin_a * centre],
                       [sin_a, cos_a, centre - sin_a * centre - cos_a * centre]])
    rotated = cv2.warpAffine(image, matrix, (size, size), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=(pad_value,) * 3)
    return np.asarray(rotated, dtype=np.uint8)


def rotate_features(features: Tensor, angles_rad: Tensor, input_size: int) -> Tensor:
    """(B, C, h, w) stride-4 features rotated about the input centre by (B,) angles (grid_sample).

    The output cell at p takes the (bilinear) feature at c + R(-a)(p - c); cells whose source lies
    outside the map get zeros.
    """
    h, w = features.shape[2:]  # features: (B, C, h, w)
    centre = (input_size - 1) / 2.0
    ys = torch.arange(h, dtype=features.dtype, device=features.device) * STRIDE + (STRIDE - 1) / 2 - centre
    xs = torch.arange(w, dtype=features.dtype, device=features.device) * STRIDE + (STRIDE - 1) / 2 - centre
    dy = ys[:, None].expand(h, w)[None]  # (1, h, w) px from the centre
    dx = xs[None, :].expand(h, w)[None]
    cos_a = torch.cos(angles_rad).to(features.dtype)[:, None, None]  # (B, 1, 1)
    sin_a = torch.sin(angles_rad).to(features.dtype)[:, None, None]
    source_x = cos_a * dx + sin_a * dy + centre  # R(-a) applied to (dx, dy)
    source_y = -sin_a * dx + cos_a * dy + centre
    # input px -> cell index -> grid_sample's [-1, 1] (align_corners=False: cell edges at ±1)
    grid_x = ((source_x - (STRIDE - 1) / 2) / STRIDE + 0.5) / w * 2 - 1
    grid_y = ((source_y - (STRIDE - 1) / 2) / STRIDE + 0.5) / h * 2 - 1
    grid = torch.stack([grid_x, grid_y], dim=-1)  # (B, h, w, 2)
    return functional.grid_sample(features, grid, mode="bilinear", padding_mode="zeros",
                                  align_corners=False)


def random_angles(batch: int, generator: torch.Generator | None = None) -> Tensor:
    """(batch,) angles uniform in [0, 2π)."""
    return torch.rand(batch, generator=generator) * (2 * math.pi)
