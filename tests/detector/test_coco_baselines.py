"""The COCO files of `../shared/pretrained/` read as their READMEs write them down, and a COCO file
read in windows on a planned view (`detector.baselines.TiledCocoModel`)."""

from __future__ import annotations

import itertools
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from contract import ModelRunner, OnnxModel, SessionThreads
from detector.baselines import CocoPersonNetwork, TiledCocoModel, window_cores, window_starts
from detector.data.readers import read_dataset
from fisheye import load_camera
from models import ASSETS_DIR, DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "pretrained"
FILES = {"yolox": ASSETS_DIR / "pretrained" / "yolox_nano.onnx",
         "nanodet-plus": SHARED / "nanodet-plus-m_416.onnx",
         "picodet": SHARED / "picodet_s_416_coco.onnx"}


def _sample_bgr() -> NDArray[np.uint8]:
    bgr = cv2.imread(str(ROOT / "samples" / "000001.jpg"))
    assert bgr is not None
    return np.asarray(bgr, dtype=np.uint8)


def _upright_crop() -> tuple[NDArray[np.uint8], float, float, float]:
    """A 416² BGR crop of a shipped sample frame where its people stand upright (the square above
    the frame's centre, as the rotated-crops baseline cuts it), with its left and top edge and
    side in frame px."""
    bgr = _sample_bgr()
    height, width = bgr.shape[:2]
    side = min(height, width) // 2
    left, top = width // 2 - side // 2, height // 2 - side
    crop = bgr[top:top + side, left:left + side]
    image = np.asarray(cv2.resize(crop, (416, 416), interpolation=cv2.INTER_AREA), dtype=np.uint8)
    return image, float(left), float(top), float(side)


def _network(family: str) -> CocoPersonNetwork:
    if not FILES[family].is_file():
        pytest.skip(f"{FILES[family]} is not here")
    return CocoPersonNetwork(FILES[family], threads=1)


@pytest.mark.parametrize("family", list(FILES))
def test_each_file_is_recognised_and_boxes_the_samples_people(family: str) -> None:
    crop, left, top, side = _upright_crop()
    network = _network(family)
    assert network.family == family
    boxes, scores = network.person_boxes(crop)
    assert boxes.shape == (len(scores), 4) and np.all((scores >= 0) & (scores <= 1))
    # Each of its three best boxes lies on an annotated person of the frame (the samples' own
    # radius-aligned boxes; above the centre the ray runs up the crop, so a box's height is the
    # person's extent along it): centre within a third of the person's length, height 0.6-1.6x.
    # A wrong cell offset, side order or bin scale in the decoding moves or stretches every box.
    frame = read_dataset(ROOT / "samples" / "annotations.json")[0]
    people = frame.boxes_cxcywh
    best = boxes[np.argsort(-scores)[:3]] * (side / 416)
    best[:, :2] += (left, top)
    for cx, cy, _, height in best:
        nearest = int(np.argmin(np.hypot(people[:, 0] - cx, people[:, 1] - cy)))
        along = people[nearest, 3]
        assert np.hypot(people[nearest, 0] - cx, people[nearest, 1] - cy) < along / 3
        assert 0.6 < height / along < 1.6, (height, along)


def test_a_file_of_another_kind_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"fishloc-default\.onnx: wants one"):
        CocoPersonNetwork(DEFAULT_MODEL_PATH)
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ValueError, match=r"junk\.onnx: not a readable ONNX model"):
        CocoPersonNetwork(junk)


@pytest.mark.parametrize("length, overlap", [(416, 128), (300, 128), (417, 128), (1792, 128), (1000, 0)])
def test_windows_cover_the_length_and_every_point_has_one_owner(length: int, overlap: int) -> None:
    starts = window_starts(length, 416, overlap)
    cores = window_cores(starts, 416, length)
    assert starts[0] == 0 and (length <= 416 or starts[-1] == length - 416)
    assert all(b - a <= 416 - overlap for a, b in itertools.pairwise(starts))
    assert cores[0][0] == 0 and cores[-1][1] == length
    assert all(a[1] == b[0] for a, b in itertools.pairwise(cores))  # a partition
    for start, (low, high) in zip(starts, cores, strict=True):
        assert start <= low < high <= start + 416  # each window owns only what it sees


def test_tiled_windows_report_what_one_window_sees() -> None:
    """Two copies of one crop side by side (416 x 832): the last window is the second copy exactly,
    so the boxes it owns are the crop's own boxes there, moved 416 px; the first window's are the
    crop's in its share."""
    model = TiledCocoModel.like(FILES["yolox"], DEFAULT_MODEL_PATH, threads=1)
    crop = _upright_crop()[0]
    rgb = np.ascontiguousarray(np.concatenate([crop, crop], axis=1)[..., ::-1])
    raw = model.run(rgb)
    assert np.all(np.diff(raw.scores) <= 0) and raw.foot is None
    boxes, scores = model.network.person_boxes(crop)
    keep = scores >= model.floor_score
    boxes, scores = boxes[keep], scores[keep]
    starts = window_starts(832, 416, model.overlap)
    (_, first_high), *_, (last_low, _) = window_cores(starts, 416, 832)
    centres = (raw.boxes[:, 0] + raw.boxes[:, 2]) / 2
    right = np.sort(raw.scores[centres >= last_low])
    assert np.allclose(right, np.sort(scores[boxes[:, 0] + 416 >= last_low]), atol=1e-6)
    left = np.sort(raw.scores[centres < first_high])
    assert np.allclose(left, np.sort(scores[boxes[:, 0] < first_high]), atol=1e-6)


def test_a_tiled_model_runs_in_the_services_planned_views() -> None:
    model = TiledCocoModel.like(FILES["yolox"], DEFAULT_MODEL_PATH, threads=1)
    reference = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(intra_op=1)).info
    assert model.info.planned and model.info.polar == reference.polar and model.info.view_points == ()
    assert (model.info.default_min_score, model.info.nms_iou) == (0.3, 0.5)
    rgb = np.ascontiguousarray(_sample_bgr()[..., ::-1])
    camera = load_camera(DEMO_CAMERA_PATH).scaled_to((rgb.shape[1], rgb.shape[0]))
    found = ModelRunner(model).detect([rgb], [camera], 0.3)[0]
    assert len(found.scores) >= 1 and np.all(found.scores >= 0.3)
