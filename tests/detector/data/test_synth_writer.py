"""`fishloc synth` output: the annotation format, determinism across worker counts, splits."""

import json
from pathlib import Path

import numpy as np
import pytest

from detector.data.palettes import preset_indices
from detector.data.readers import FrameAnnotations, read_dataset
from detector.data.readers import write_dataset as write_annotations
from detector.data.scenes import build_scene
from detector.data.synth import SynthConfig, render_frame
from detector.data.synth_writer import write_dataset
from fisheye import camera_from_dict
from service.cli import main

IMAGE_KEYS = {"id", "file_name", "width", "height", "scene_id", "split", "camera"}
ANNOTATION_KEYS = {"id", "image_id", "category_id", "rotated_box", "bbox", "location_m", "distance_m",
                   "visible_fraction", "area", "iscrowd"}
CONFIG = SynthConfig(size=256, kind="indoor", people=(2, 5), images_per_scene=2)


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_worker_count_does_not_change_the_output(tmp_path: Path) -> None:
    write_dataset(tmp_path / "one", 4, seed=3, split="seen", config=CONFIG, workers=1)
    write_dataset(tmp_path / "two", 4, seed=3, split="seen", config=CONFIG, workers=2)
    assert _tree(tmp_path / "one") == _tree(tmp_path / "two")


def test_annotations_follow_the_dataset_format(tmp_path: Path) -> None:
    document = write_dataset(tmp_path, 3, seed=8, split="unseen", config=CONFIG)
    on_disk = json.loads((tmp_path / "annotations.json").read_text())
    assert on_disk == document
    assert document["categories"] == [{"id": 1, "name": "person"}]
    assert [im["id"] for im in document["images"]] == [1, 2, 3]
    for image in document["images"]:
        assert set(image) == IMAGE_KEYS
        assert (tmp_path / image["file_name"]).is_file()
        assert image["split"] == "unseen"
        assert image["scene_id"].startswith("indoor-") and image["scene_id"][-5] == "u"
        camera = camera_from_dict(image["camera"])
        assert tuple(camera.image_size) == (image["width"], image["height"]) == (256, 256)
    ids = [a["id"] for a in document["annotations"]]
    assert ids == list(range(1, len(ids) + 1)) and ids
    for ann in document["annotations"]:
        assert set(ann) == ANNOTATION_KEYS
        assert ann["category_id"] == 1 and ann["iscrowd"] in (0, 1)
        assert len(ann["rotated_box"]) == 4 and len(ann["bbox"]) == 4 and len(ann["location_m"]) == 2
        assert ann["distance_m"] == pytest.approx(np.hypot(*ann["location_m"]), abs=1e-4)
        assert 0 < ann["visible_fraction"] <= 1 and ann["area"] >= 1


def _assert_same_frames(a: list[FrameAnnotations], b: list[FrameAnnotations]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert (x.path, x.image_id, x.width, x.height, x.scene_id, x.split, x.camera) == (
            y.path, y.image_id, y.width, y.height, y.scene_id, y.split, y.camera)
        for name in ("boxes_cxcywh", "locations_m", "distances_m", "visible_fraction", "crowd_cxcywh",
                     "bboxes_xywh", "areas_px"):
            np.testing.assert_array_equal(getattr(x, name), getattr(y, name), err_msg=name)


def test_rendered_set_reads_writes_and_reads_back_unchanged(tmp_path: Path) -> None:
    config = SynthConfig(size=256, kind="indoor", people=(4, 9), images_per_scene=2)
    write_dataset(tmp_path, 3, seed=3, split="seen", config=config)
    frames = read_dataset(tmp_path)
    # The reader gives back what the renderer drew (to the file's rounding).
    for frame, index in zip(frames, range(3), strict=True):
        truth = render_frame(3, "seen", index, config)
        people = [p for p in truth.people if not p.ignore]
        crowd = [p for p in truth.people if p.ignore]
        assert frame.camera == truth.camera and frame.scene_id == truth.scene_id
        assert frame.path == tmp_path / f"{index + 1:06d}.jpg" and frame.path.is_file()
        def rows(values: list[tuple[float, ...]], width: int) -> np.ndarray:
            return np.array(values, dtype=np.float64).reshape(-1, width)

        np.testing.assert_allclose(frame.boxes_cxcywh, rows([p.rotated_box for p in people], 4), atol=5e-4)
        np.testing.assert_allclose(frame.crowd_cxcywh, rows([p.rotated_box for p in crowd], 4), atol=5e-4)
        np.testing.assert_allclose(frame.locations_m, rows([p.location_m for p in people], 2), atol=5e-6)
        np.testing.assert_allclose(frame.distances_m, [p.distance_m for p in people], atol=5e-6)
        np.testing.assert_allclose(frame.visible_fraction, [p.visible_fraction for p in people], atol=5e-5)
        np.testing.assert_allclose(frame.bboxes_xywh, rows([p.bbox for p in people], 4), atol=5e-4)
        np.testing.assert_array_equal(frame.areas_px, [p.visible_px for p in people])
    assert sum(len(f) for f in frames) >= 6 and sum(len(f.crowd_cxcywh) for f in frames) >= 1
    write_annotations(frames, tmp_path / "again.json")
    again = read_dataset(tmp_path / "again.json")
    _assert_same_frames(frames, again)
    # The silhouette's axis-aligned box is kept, not rebuilt from the rotated box.
    original = json.loads((tmp_path / "annotations.json").read_text())["annotations"]
    rewritten = json.loads((tmp_path / "again.json").read_text())["annotations"]
    people_records = [a for a in original if not a["iscrowd"]]
    assert [a["bbox"] for a in people_records] == [a["bbox"] for a in rewritten if not a["iscrowd"]]
    assert [a["area"] for a in people_records] == [a["area"] for a in rewritten if not a["iscrowd"]]


def test_seen_and_unseen_scenes_share_no_palette_or_id() -> None:
    seen, unseen = set(preset_indices("seen")), set(preset_indices("unseen"))
    assert seen and unseen and not seen & unseen
    seen_ids = {build_scene("seen", i, "indoor").scene_id for i in range(3)}
    unseen_ids = {build_scene("unseen", i, "indoor").scene_id for i in range(3)}
    assert not seen_ids & unseen_ids


def test_cli_writes_frames_and_a_contact_sheet(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "set"
    sheet = tmp_path / "sheet.png"
    code = main(["synth", "--out", str(out), "--images", "2", "--size", "192", "--seed", "1",
                 "--kind", "outdoor", "--people", "1-3", "--workers", "1", "--quiet",
                 "--contact-sheet", str(sheet)])
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["000001.jpg", "000002.jpg", "annotations.json"]
    assert sheet.stat().st_size > 0
    assert "wrote 2 frames" in capsys.readouterr().out


def test_cli_refuses_a_bad_size(tmp_path: Path) -> None:
    assert main(["synth", "--out", str(tmp_path), "--images", "1", "--size", "4000", "--quiet"]) == 2
