"""Toy fisheye frames for detector tests: people drawn as radius-aligned rectangles."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from detector.data.readers import FrameAnnotations, write_dataset
from fisheye import camera_from_dict, cxcywh_to_corners

PERSON_HEIGHT_M = 1.7

# Tiny models gain nothing from intra-op threads, and on a busy machine they lose a lot to them.
torch.set_num_threads(1)


def toy_camera_dict(size: int) -> dict[str, object]:
    """An ideal equidistant lens whose 90° circle nearly fills a size x size frame."""
    radius = size / 2 - 2
    return {"id": "toy", "altitude_m": 3.0, "image_size": [size, size],
            "principal_point": [(size - 1) / 2, (size - 1) / 2],
            "focal_px": [radius / (np.pi / 2)] * 2, "kb": [1.0], "max_theta_deg": 90}


def make_toy_dataset(folder: Path, count: int, size: int = 128, seed: int = 0, people: int = 3,
                     split: str = "seen") -> Path:
    """Write `count` frames and their annotations.json into `folder`; returns the json path."""
    rng = np.random.default_rng(seed)
    camera = camera_from_dict(toy_camera_dict(size))
    pp = camera.principal_point
    frames = []
    folder.mkdir(parents=True, exist_ok=True)
    for index in range(count):
        image = np.zeros((size, size, 3), np.uint8)
        cv2.circle(image, (size // 2, size // 2), size // 2 - 2, (90, 90, 90), -1)
        boxes, locations = [], []
        for _ in range(people):
            distance = rng.uniform(0.8, 6.0)
            angle = rng.uniform(0, 2 * np.pi)
            xy = np.array([distance * np.cos(angle), distance * np.sin(angle)])
            foot = camera.floor_to_pixels(xy[None])[0]
            head = camera.world_to_pixels(np.array([[xy[0], xy[1], PERSON_HEIGHT_M]]))[0]
            centre = (foot + head) / 2
            h = float(np.linalg.norm(head - foot)) + 4.0
            w = max(4.0, 0.45 * h)
            box = np.array([centre[0], centre[1], w, h])
            corners = cxcywh_to_corners(box[None], pp)[0]
            colour = tuple(int(c) for c in rng.integers(150, 256, 3))
            cv2.fillPoly(image, [np.round(corners).astype(np.int32)], colour, lineType=cv2.LINE_AA)
            boxes.append(box)
            locations.append(xy)
        path = folder / f"{index:04d}.png"
        cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        locations_m = np.array(locations)
        frames.append(FrameAnnotations(
            path=path, image_id=index + 1, width=size, height=size, camera=camera,
            scene_id=f"toy-{index % 2}", split=split, boxes_cxcywh=np.array(boxes),
            locations_m=locations_m, distances_m=np.hypot(locations_m[:, 0], locations_m[:, 1]),
            visible_fraction=np.ones(len(boxes)),
        ))
    target = folder / "annotations.json"
    write_dataset(frames, target, {"description": "toy frames for tests"})
    return target


@pytest.fixture
def toy_dataset(tmp_path: Path) -> Callable[..., Path]:
    def factory(count: int = 4, size: int = 128, seed: int = 0, people: int = 3,
                split: str = "seen", name: str = "toy") -> Path:
        return make_toy_dataset(tmp_path / name, count, size, seed, people, split)
    return factory
