from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from detector.decode import decode, dense_boxes
from detector.model import STRIDE, build_model, polar_channels, tiny_config
from detector.rotation import rotate_boxes, rotate_features, rotate_image, rotate_points
from detector.targets import TargetConfig, build_targets

SIZE = 64


def test_network_output_shape_and_decoded_contract() -> None:
    config = tiny_config(SIZE)
    net = build_model(config).eval()
    images = torch.randn(3, 3, SIZE, SIZE)
    with torch.no_grad():
        out = net(images)
        boxes, scores = decode(out, SIZE, config.max_detections)
    assert out.shape == (3, 5, SIZE // STRIDE, SIZE // STRIDE)
    assert boxes.shape == (3, config.max_detections, 4) and scores.shape == (3, config.max_detections)
    assert torch.all(scores[:, 1:] <= scores[:, :-1])
    assert torch.all(boxes[..., 2:] > 0)


def test_polar_channels_point_away_from_the_input_centre() -> None:
    polar = polar_channels(16, 16, SIZE, torch.zeros(1))[0]  # (3, 16, 16)
    # cell (row 0, col 15) sits at (61.5, 1.5): up-right of the centre 31.5
    np.testing.assert_allclose(polar[:2, 0, 15].numpy(), np.array([30, -30]) / math.hypot(30, 30), atol=1e-6)
    assert float(polar[2, 0, 15]) == pytest.approx(math.hypot(30, 30) / 32, rel=1e-6)


@pytest.mark.parametrize("box", [[20.3, 12.7, 6.0, 14.0], [45.9, 40.2, 8.0, 17.0], [33.0, 30.0, 5.0, 5.0]])
def test_targets_decode_back_to_their_boxes(box: list[float]) -> None:
    heatmap, regression, mask = build_targets(np.array([box]), SIZE, TargetConfig())
    assert mask.sum() == 1 and heatmap.max() == pytest.approx(1.0)
    predictions = torch.from_numpy(np.concatenate([np.where(mask, 20.0, -20.0)[None], regression]))[None]
    boxes, scores = decode(predictions.float(), SIZE, 5)
    np.testing.assert_allclose(boxes[0, 0].numpy(), box, atol=1e-4)
    assert float(scores[0, 0]) > 0.99 and float(scores[0, 1]) < 1e-6


def test_rotations_share_one_convention() -> None:
    # Points, boxes, images and features all turn the same way about the input centre.
    centre = (SIZE - 1) / 2
    np.testing.assert_allclose(rotate_points(np.array([[centre + 10, centre]]), math.pi / 2, SIZE),
                               [[centre, centre + 10]], atol=1e-9)  # +x -> +v (down): clockwise
    np.testing.assert_allclose(rotate_boxes(np.array([[centre + 10, centre, 3, 7]]), math.pi, SIZE),
                               [[centre - 10, centre, 3, 7]], atol=1e-9)
    image = np.zeros((SIZE, SIZE, 3), np.uint8)
    image[30:34, 50:54] = 255  # a blob right of the centre
    turned = rotate_image(image, math.pi / 2)
    ys, xs = np.nonzero(turned[..., 0] > 128)
    assert abs(xs.mean() - centre) < 1 and ys.mean() > centre + 15  # now below the centre
    features = torch.zeros(1, 1, SIZE // STRIDE, SIZE // STRIDE)
    features[0, 0, 7, 13] = 1.0  # the cell at (53.5, 29.5)
    rotated = rotate_features(features, torch.tensor([math.pi / 2]), SIZE)[0, 0]
    expected = rotate_points(np.array([[53.5, 29.5]]), math.pi / 2, SIZE)[0]  # (33.5, 53.5)
    row, col = np.unravel_index(int(torch.argmax(rotated)), rotated.shape)
    assert (col * STRIDE + 1.5, row * STRIDE + 1.5) == tuple(expected)
    assert float(rotated.max()) == pytest.approx(1.0)


def test_dense_boxes_offsets_follow_the_ray() -> None:
    predictions = torch.zeros(1, 5, 16, 16)
    predictions[0, 3] = 0.5  # half a cell outwards along the ray everywhere
    boxes = dense_boxes(predictions, SIZE)[0]
    cell = np.array([61.5, 1.5])
    centre = (SIZE - 1) / 2
    unit = (cell - centre) / np.linalg.norm(cell - centre)
    np.testing.assert_allclose(boxes[:2, 0, 15].numpy(), cell + 2.0 * unit, atol=1e-5)
    np.testing.assert_allclose(boxes[2:, 0, 15].numpy(), [1.0, 1.0], atol=1e-6)
