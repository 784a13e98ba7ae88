"""Writing a synthetic data set: JPEG frames and the COCO-style `annotations.json` beside them.

Frames are rendered in worker processes (numpy and OpenCV only, no torch); each worker writes its
JPEGs and sends back their annotation records, which the parent numbers in frame order, so the
output is the same whatever the number of workers.
"""

from __future__ import annotations

import json
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from functools import partial
from pathlib import Path
from typing import Any

import cv2

from detector.data.ground_truth import PersonTruth
from detector.data.synth import SynthConfig, SynthFrame, render_frame
from fisheye import camera_to_dict

ANNOTATIONS_FILE = "annotations.json"
CATEGORIES = [{"id": 1, "name": "person"}]


def file_name(index: int) -> str:
    return f"{index + 1:06d}.jpg"


def frame_records(frame: SynthFrame) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The `images` record of a frame and its `annotations` records (ids filled in later)."""
    image = {
        "id": frame.index + 1,
        "file_name": file_name(frame.index),
        "width": frame.width,
        "height": frame.height,
        "scene_id": frame.scene_id,
        "split": frame.split,
        "camera": camera_to_dict(frame.camera),
    }
    return image, [person_record(person, frame.index + 1) for person in frame.people]


def person_record(person: PersonTruth, image_id: int) -> dict[str, Any]:
    """The `annotations` record of one person in a frame (its `id` filled in later)."""
    return {
        "id": 0,
        "image_id": image_id,
        "category_id": 1,
        "rotated_box": [round(v, 3) for v in person.rotated_box],
        "bbox": [round(v, 3) for v in person.bbox],
        "location_m": [round(v, 5) for v in person.location_m],
        "distance_m": round(person.distance_m, 5),
        "visible_fraction": round(person.visible_fraction, 4),
        "area": person.visible_px,
        "iscrowd": int(person.ignore),
    }


def _work(index: int, seed: int, split: str, config: SynthConfig, out_dir: str
          ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    frame = render_frame(seed, split, index, config)
    Path(out_dir, file_name(index)).write_bytes(frame.jpeg)
    return frame_records(frame)


def _init_worker() -> None:
    # One thread per process: the parallelism is across processes.
    cv2.setNumThreads(1)


def _frames(images: int, seed: int, split: str, config: SynthConfig, out_dir: Path, workers: int
            ) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]]]]:
    work = partial(_work, seed=seed, split=split, config=config, out_dir=str(out_dir))
    if workers <= 1:
        yield from map(work, range(images))
        return
    context = multiprocessing.get_context("spawn")
    with context.Pool(workers, initializer=_init_worker) as pool:
        # Chunks of one scene keep each scene's cached surroundings in one worker.
        yield from pool.imap(work, range(images), chunksize=config.images_per_scene)


Records = tuple[dict[str, Any], list[dict[str, Any]]]  # a frame's image record and its annotations


def collect_records(frames: Iterable[Records], on_frame: Callable[[], None] | None = None
                    ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The `images` and `annotations` lists of frames' records, the annotations numbered in order."""
    image_records: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for image, people in frames:
        image_records.append(image)
        for record in people:
            record["id"] = len(annotations) + 1
            annotations.append(record)
        if on_frame is not None:
            on_frame()
    return image_records, annotations


def write_dataset(out_dir: str | Path, images: int, seed: int, split: str, config: SynthConfig,
                  workers: int = 1, on_frame: Callable[[], None] | None = None) -> dict[str, Any]:
    """Render `images` frames into `out_dir`, write `annotations.json`, and return its content."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    frames = _frames(images, seed, split, config, out, workers)
    image_records, annotations = collect_records(frames, on_frame)
    document = {
        "info": {
            "description": "FishLoc synthetic overhead fisheye frames",
            "generator": "fishloc synth",
            "seed": seed,
            "split": split,
            "size": config.size,
            "kind": config.kind or "mixed",
            "style": config.style or "mixed",
            "images_per_scene": config.images_per_scene,
            "boxes": ("the whole silhouette's, what hides a person ignored" if config.boxes == "whole"
                      else "the visible silhouette's"),
            "ignore_rule": (f"iscrowd=1 when visible_fraction < {config.min_visible_fraction} "
                            f"or fewer than {config.min_visible_px} visible pixels"),
        },
        "categories": CATEGORIES,
        "images": image_records,
        "annotations": annotations,
    }
    (out / ANNOTATIONS_FILE).write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    return document


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)))
