from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from detector.data.dataset import AugmentConfig, DetectionDataset, collate, letterboxed
from detector.data.readers import read_dataset


def _colour_at(image: np.ndarray, point: np.ndarray) -> np.ndarray:
    u, v = np.rint(point).astype(int)
    return image[v, u].astype(int)


def test_letterbox_maps_boxes_onto_the_drawn_people(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=1, size=128))
    image, boxes = letterboxed(frames[0], 64)
    assert image.shape == (64, 64, 3) and boxes.shape == (3, 4)
    np.testing.assert_allclose(boxes[:, 2:], frames[0].boxes_cxcywh[:, 2:] / 2)
    for box in boxes:  # people are bright (>= 150), the floor is grey 90
        assert _colour_at(image, box[:2]).min() > 120


def test_rotation_augmentation_moves_image_and_boxes_together(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128))
    augment = AugmentConfig(rotation=True, flip=True, photometric=False)
    dataset = DetectionDataset(frames, 128, augment, seed=3)
    for epoch in range(3):
        dataset.set_epoch(epoch)
        for index in range(len(dataset)):
            sample = dataset[index]
            for box in sample.boxes_cxcywh:
                assert _colour_at(sample.image.numpy(), box[:2]).min() > 120
            np.testing.assert_allclose(sorted(sample.boxes_cxcywh[:, 3]), sorted(frames[index].boxes_cxcywh[:, 3]))


def test_augmentation_is_a_function_of_seed_epoch_and_index(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128))
    augment = AugmentConfig(rotation=True)
    first, second = DetectionDataset(frames, 128, augment, seed=1), DetectionDataset(frames, 128, augment, seed=1)
    second.set_epoch(1)
    assert not np.array_equal(first[0].image.numpy(), second[0].image.numpy())
    second.set_epoch(0)
    np.testing.assert_array_equal(first[0].image.numpy(), second[0].image.numpy())
    batch = collate([first[0], first[1]])
    assert batch.images.shape == (2, 128, 128, 3) and len(batch.boxes) == 2 and batch.indices == [0, 1]
