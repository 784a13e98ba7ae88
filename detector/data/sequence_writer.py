"""Writing a synthetic sequence: `DIR/<camera_id>/*.jpg` and `DIR/annotations.json`.

Frames are rendered in worker processes, each with its own `SequenceRenderer` (world, routes and
camera views built once per process); records come back in (step, camera) order, so the output is
the same whatever the number of workers. Each image record carries its camera (a camera file with
`site` and `site_pose`) and `capture_time`, the same for every camera of a step; each annotation its
`track_id` and `site_location_m`; the document's `site` the zones and lines (the bodies of the
service's zone and line PUTs) and `tracks`, every person's position at every step they are inside,
seen or not.
"""

from __future__ import annotations

import json
import multiprocessing
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2

from detector.data.sequence import SequenceConfig, SequenceFrame, SequenceRenderer
from detector.data.synth_writer import ANNOTATIONS_FILE, CATEGORIES, collect_records, person_record
from fisheye import camera_to_dict

_renderer: SequenceRenderer | None = None


def frame_file_name(camera_id: str, step: int) -> str:
    return f"{camera_id}/{step + 1:06d}.jpg"


def image_id(config: SequenceConfig, step: int, camera_index: int) -> int:
    return step * len(config.plan.cameras) + camera_index + 1


def frame_records(config: SequenceConfig, frame: SequenceFrame, camera_index: int
                  ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The `images` record of a frame and its `annotations` records (ids filled in later)."""
    number = image_id(config, frame.step, camera_index)
    image = {
        "id": number,
        "file_name": frame_file_name(frame.camera.id, frame.step),
        "width": frame.width,
        "height": frame.height,
        "scene_id": f"site-{config.plan.site_id}-{config.seed}",
        "split": "unseen",
        "camera": {**camera_to_dict(frame.camera), "site": config.plan.site_id},
        "capture_time": frame.capture_time,
        "step": frame.step,
    }
    annotations = []
    for person in frame.people:
        record = person_record(person.truth, number)
        record["track_id"] = person.track_id
        record["site_location_m"] = [round(v, 5) for v in person.site_location_m]
        annotations.append(record)
    return image, annotations


def _init_worker(config: SequenceConfig) -> None:
    global _renderer
    cv2.setNumThreads(1)  # the parallelism is across processes
    _renderer = SequenceRenderer(config)


def _work(task: tuple[int, int], out_dir: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    assert _renderer is not None
    step, camera_index = task
    frame = _renderer.render(step, camera_index)
    Path(out_dir, frame_file_name(frame.camera.id, step)).write_bytes(frame.jpeg)
    return frame_records(_renderer.config, frame, camera_index)


def _frames(config: SequenceConfig, out_dir: Path, workers: int
            ) -> Iterator[tuple[dict[str, Any], list[dict[str, Any]]]]:
    tasks = [(step, k) for step in range(config.steps) for k in range(len(config.plan.cameras))]
    if workers <= 1:
        _init_worker(config)
        for task in tasks:
            yield _work(task, str(out_dir))
        return
    context = multiprocessing.get_context("spawn")
    with context.Pool(workers, initializer=_init_worker, initargs=(config,)) as pool:
        yield from pool.imap(_Task(str(out_dir)), tasks, chunksize=8)


class _Task:
    """A picklable `_work` bound to the output folder."""

    def __init__(self, out_dir: str) -> None:
        self.out_dir = out_dir

    def __call__(self, task: tuple[int, int]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        return _work(task, self.out_dir)


def ground_truth_tracks(renderer: SequenceRenderer) -> list[dict[str, Any]]:
    """Every person's site position at every step they are inside: `{"track_id", "steps",
    "positions_m"}`."""
    out = []
    for walker in renderer.walkers:
        steps = [s for s in range(renderer.config.steps) if walker.present(s)]
        out.append({"track_id": walker.track_id, "steps": steps,
                    "positions_m": [[round(float(v), 5) for v in walker.positions_m[s]] for s in steps]})
    return out


def write_sequence(out_dir: str | Path, config: SequenceConfig, workers: int = 1,
                   on_frame: Callable[[], None] | None = None) -> dict[str, Any]:
    """Render every frame of `config` into `out_dir`, write `annotations.json`, return its content."""
    out = Path(out_dir)
    for camera in config.plan.cameras:
        (out / camera.id).mkdir(parents=True, exist_ok=True)
    image_records, annotations = collect_records(_frames(config, out, workers), on_frame)
    renderer = SequenceRenderer(config)
    document = {
        "info": {
            "description": "FishLoc synthetic site sequence: overhead fisheye cameras capturing in step",
            "generator": "fishloc synth --sequence",
            "seed": config.seed,
            "size": config.size,
            "fps": config.fps,
            "steps": config.steps,
            "people": len(renderer.walkers),
            "ignore_rule": (f"iscrowd=1 when visible_fraction < {config.min_visible_fraction} "
                            f"or fewer than {config.min_visible_px} visible pixels"),
        },
        "categories": CATEGORIES,
        "site": {**config.plan.to_dict(), "tracks": ground_truth_tracks(renderer)},
        "images": image_records,
        "annotations": annotations,
    }
    (out / ANNOTATIONS_FILE).write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
    return document
