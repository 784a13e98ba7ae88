"""Design (b): YOLOX-Nano on the letterboxed fisheye frame with a radius-aligned head."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from torch import Tensor, nn

from contract import FisheyeInput, ModelRunner, OnnxModel, RawOutputs, SessionThreads, select_detections
from detector.checkpoint import Checkpoint, load_checkpoint, save_checkpoint
from detector.data.readers import FrameAnnotations, read_dataset
from detector.graph import contract_info, contract_module
from detector.yolox.finetune import FinetuneConfig, Finetuner
from detector.yolox.fisheye import FisheyeContract, FisheyeDetectorConfig
from detector.yolox.frames import (
    FisheyeFrameDataset,
    FrameAugment,
    affine_about,
    frame_input,
    radius_aligned_to_yolox,
    training_info,
    transform_boxes,
)
from detector.yolox.loss import PolarDetectionLoss
from detector.yolox.network import STRIDES, YoloxNano
from detector.yolox.polar import EDGE_TO_CENTRE_PX, PolarDetectorConfig, init_from_pretrained
from detector.yolox.strips import collate_strips
from fisheye import Letterbox, camera_from_dict
from models import ASSETS_DIR
from service.cli import main

ONNX_PATH = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"
CONFIG = FisheyeDetectorConfig(input_size=64)
QUIET = FrameAugment.none()


@pytest.fixture(scope="module")
def pretrained() -> YoloxNano:
    return init_from_pretrained(str(ONNX_PATH), CONFIG)


def disc_frame(folder: Path, principal_point: tuple[float, float], box: tuple[float, float, float, float],
               size: int = 128) -> FrameAnnotations:
    """A black frame with one bright disc (radius 8 px) at the centre of its one radius-aligned box."""
    radius = size / 2 - 2
    camera = camera_from_dict({"id": "disc", "altitude_m": 3.0, "image_size": [size, size],
                               "principal_point": list(principal_point),
                               "focal_px": [radius / (math.pi / 2)] * 2, "kb": [1.0]})
    image = np.zeros((size, size, 3), np.uint8)
    shift = 4  # sub-pixel centre
    centre = (round(box[0] * 2**shift), round(box[1] * 2**shift))
    cv2.circle(image, centre, 8 * 2**shift, (255, 255, 255), -1, lineType=cv2.LINE_AA, shift=shift)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "disc.png"
    cv2.imwrite(str(path), image)
    return FrameAnnotations(path=path, image_id=1, width=size, height=size, camera=camera, scene_id="disc",
                            split="seen", boxes_cxcywh=np.array([box]), locations_m=np.zeros((1, 2)),
                            distances_m=np.zeros(1), visible_fraction=np.ones(1))


def yolox_to_cxcywh(labels_xyxy: np.ndarray) -> np.ndarray:
    """What FisheyeContract outputs for a YOLOX box: centre − 0.5, w, h."""
    centre = (labels_xyxy[:, :2] + labels_xyxy[:, 2:]) / 2 - EDGE_TO_CENTRE_PX
    return np.concatenate([centre, labels_xyxy[:, 2:] - labels_xyxy[:, :2]], axis=1)


class MapsOf(nn.Module):
    """A stand-in network whose stride-8 maps decode to `labels_xyxy` (one cell each), nothing else."""

    def __init__(self, labels_xyxy: np.ndarray, size: int) -> None:
        super().__init__()
        maps = [torch.full((1, 6, size // s, size // s), -12.0) for s in STRIDES]
        stride = STRIDES[0]
        for rank, (x1, y1, x2, y2) in enumerate(labels_xyxy):
            cx, cy = (x1 + x2) / 2 / stride, (y1 + y2) / 2 / stride
            col, row = math.floor(cx), math.floor(cy)
            score_logit = 12.0 - rank  # distinct scores, labels in order
            maps[0][0, :, row, col] = torch.tensor([cx - col, cy - row, math.log((x2 - x1) / stride),
                                                    math.log((y2 - y1) / stride), score_logit, score_logit])
        self.maps = maps

    def forward(self, images: Tensor) -> list[Tensor]:
        return [m.expand(len(images), -1, -1, -1) for m in self.maps]


# ----- labels


@pytest.mark.parametrize("principal_point", [(63.5, 63.5), (70.0, 57.0)])
def test_labels_read_back_through_the_contract_are_the_frame_boxes(
        principal_point: tuple[float, float], tmp_path: Path) -> None:
    boxes = np.array([[95.0, 63.5, 9.0, 21.0], [40.0, 30.0, 12.0, 18.0], [*principal_point, 14.0, 14.0]])
    frame = disc_frame(tmp_path, principal_point, tuple(boxes[0]))
    frame = FrameAnnotations(**{**vars(frame), "boxes_cxcywh": boxes, "locations_m": np.zeros((3, 2)),
                                "distances_m": np.zeros(3), "visible_fraction": np.ones(3)})
    sample = FisheyeFrameDataset([frame], CONFIG, QUIET)[0]
    assert len(sample.labels_xyxy) == 3  # the box over the principal point stays
    contract = FisheyeContract(MapsOf(sample.labels_xyxy, 64), max_detections=10)  # type: ignore[arg-type]
    with torch.no_grad():
        boxes_input, scores = contract(torch.from_numpy(sample.image[None]))
    np.testing.assert_allclose(boxes_input[0, :3].numpy(), yolox_to_cxcywh(sample.labels_xyxy), atol=1e-4)
    raw = RawOutputs(boxes_input[0].numpy(), scores[0].numpy())
    mapping = FisheyeInput(Letterbox.fit((128, 128), 64))
    found = select_detections(raw, mapping, principal_point, min_score=0.5, nms_iou=None)
    np.testing.assert_allclose(found.boxes_cxcywh, boxes, atol=1e-3)


@pytest.mark.parametrize("boxes", [np.zeros((0, 4)), np.array([[10.0, 20.0, 4.0, 8.0]])])
def test_yolox_labels_and_back(boxes: np.ndarray) -> None:
    labels = radius_aligned_to_yolox(boxes)
    assert labels.shape == (len(boxes), 4)
    np.testing.assert_allclose(yolox_to_cxcywh(labels), boxes)


@pytest.mark.parametrize("mirror", [False, True])
def test_rotation_and_mirror_keep_boxes_radius_aligned_about_the_principal_point(mirror: bool) -> None:
    pp = (30.0, 20.0)
    boxes = np.array([[50.0, 20.0, 4.0, 8.0], [30.0, 45.0, 6.0, 10.0]])
    matrix = affine_about(pp, 1.1, mirror)
    moved = transform_boxes(boxes, matrix)
    np.testing.assert_allclose(matrix[:, :2] @ np.asarray(pp) + matrix[:, 2], pp)  # p stays
    radii = np.hypot(*(boxes[:, :2] - pp).T)
    np.testing.assert_allclose(np.hypot(*(moved[:, :2] - pp).T), radii)
    np.testing.assert_array_equal(moved[:, 2:], boxes[:, 2:])


@pytest.mark.parametrize("principal_point", [(63.5, 63.5), (70.0, 57.0)])
def test_rotated_labels_stay_on_the_people(principal_point: tuple[float, float], tmp_path: Path) -> None:
    box = (principal_point[0] + 30.0, principal_point[1] - 12.0, 10.0, 18.0)
    frame = disc_frame(tmp_path, principal_point, box)
    dataset = FisheyeFrameDataset([frame], CONFIG, FrameAugment(rotation=True, flip=0.5, brightness=0.0,
                                                                 contrast=0.0, saturation=0.0, hue_deg=0.0,
                                                                 blur=0.0, jpeg=0.0), seed=1)
    _, boxes_input, pp = frame_input(frame, training_info(CONFIG))
    np.testing.assert_allclose(pp, (np.asarray(principal_point) + 0.5) / 2 - 0.5)
    radius = float(np.hypot(*(boxes_input[0, :2] - pp)))
    centres = []
    for epoch in range(6):
        dataset.set_epoch(epoch)
        sample = dataset[0]
        assert sample.principal_point_xy == pp
        (label,) = yolox_to_cxcywh(sample.labels_xyxy)
        np.testing.assert_allclose(label[2:], boxes_input[0, 2:])  # w, h stay
        assert abs(float(np.hypot(*(label[:2] - pp))) - radius) < 1e-9  # still about the principal point
        weight = sample.image[..., 0].astype(np.float64)
        rows, cols = np.indices(weight.shape)
        centroid = np.array([(cols * weight).sum(), (rows * weight).sum()]) / weight.sum()
        assert np.abs(centroid - label[:2]).max() < 0.3  # the disc moved with its label
        centres.append(label[:2])
    assert len({tuple(np.round(c, 3)) for c in centres}) == 6


# ----- loss and loop


def test_the_loss_learns_on_letterboxed_frames(pretrained: YoloxNano,
                                               toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128, people=3))
    dataset = FisheyeFrameDataset(frames, CONFIG, QUIET)
    images, labels = collate_strips([dataset[0], dataset[1]])
    assert images.shape == (2, 3, 64, 64) and [len(x) for x in labels] == [3, 3]
    student = init_from_pretrained(str(ONNX_PATH), CONFIG).train()
    teacher = init_from_pretrained(str(ONNX_PATH), CONFIG).eval().requires_grad_(False)
    loss = PolarDetectionLoss()
    with torch.no_grad():
        teacher_maps = teacher(images)
    start = loss(student(images), labels, teacher_maps)
    assert abs(start["distill"].item()) < 1e-6
    optimizer = torch.optim.AdamW(student.parameters(), lr=1e-3)
    for _ in range(12):
        terms = loss(student(images), labels, teacher_maps)
        optimizer.zero_grad()
        terms["total"].backward()  # type: ignore[no-untyped-call]
        optimizer.step()
    end = loss(student(images), labels, teacher_maps)
    assert end["total"].item() < 0.75 * start["total"].item()


def _finetuner(pretrained: YoloxNano, frames: list[FrameAnnotations], out: Path) -> Finetuner:
    config = FinetuneConfig(epochs=2, batch_size=2, lr=1e-3, warmup_steps=2, seed=4, device="cpu",
                            checkpoint_every_s=0.0, augment=FrameAugment())
    return Finetuner(CONFIG, config, out, pretrained, frames, None, "toy", progress=False)


def test_resume_mid_epoch_equals_training_straight(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    frames = read_dataset(toy_dataset(count=4, size=128, people=2))
    straight = _finetuner(pretrained, frames, tmp_path / "straight")
    straight.fit()
    first = _finetuner(pretrained, frames, tmp_path / "cut")
    first.fit(stop_after_steps=1)
    resumed = _finetuner(pretrained, frames, tmp_path / "cut")
    resumed.resume(tmp_path / "cut" / "last.pt")
    assert (resumed.epoch, resumed.batch, resumed.step) == (0, 1, 1)
    resumed.fit()
    assert straight.step == resumed.step == 4
    for key, value in straight.model.state_dict().items():
        torch.testing.assert_close(resumed.model.state_dict()[key], value, atol=1e-6, rtol=0, msg=key)
    assert any(not torch.equal(v, pretrained.state_dict()[k]) for k, v in straight.model.state_dict().items())
    records = [json.loads(line) for line in (tmp_path / "cut" / "log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in records] == [1, 2] and "labels_left_out" in records[0]
    assert load_checkpoint(tmp_path / "cut" / "last.pt").config == CONFIG


def test_the_other_views_augmentation_is_refused(pretrained: YoloxNano, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="FrameAugment"):
        Finetuner(CONFIG, FinetuneConfig(device="cpu"), tmp_path, pretrained, [], progress=False)


# ----- CLI and export


def _cli(out: Path, data: Path, view: str, *extra: str) -> int:
    size = ["--input-size", "64"] if view == "fisheye" else ["--strip", "64", "256", "32"]
    return main(["train", "--init-from", str(ONNX_PATH), "--view", view, "--data", str(data), "--out",
                 str(out), "--quiet", "--threads", "1", *size, *extra])


def test_cli_trains_the_fisheye_view_and_refuses_to_resume_a_polar_run(
        toy_dataset: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = toy_dataset(count=2, size=128, people=2)
    fisheye_run, polar_run = tmp_path / "fisheye", tmp_path / "polar"
    assert _cli(fisheye_run, data, "fisheye", "--epochs", "1", "--batch-size", "2", "--val", str(data)) == 0
    record = json.loads((fisheye_run / "log.jsonl").read_text().splitlines()[0])
    assert {"mAP", "AP50", "recall"} <= set(record["val"])
    assert load_checkpoint(fisheye_run / "last.pt").config == CONFIG
    assert _cli(polar_run, data, "polar", "--epochs", "0") == 0
    for out, view in ((polar_run, "fisheye"), (fisheye_run, "polar")):
        before = {p.name: p.read_bytes() for p in out.iterdir()}
        assert _cli(out, data, view, "--resume") == 2
        error = capsys.readouterr().err
        assert str(out / "last.pt") in error and "--view" in error
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _cli(tmp_path / "x", data, "fisheye", "--zoom", "0.8", "1.0") == 2
    assert _cli(tmp_path / "x", data, "fisheye", "--nadir-view", "0.5") == 2
    assert _cli(tmp_path / "x", data, "fisheye", "--rand-conv", "0.5") == 2
    assert main(["train", "--view", "fisheye", "--data", str(data), "--out", str(tmp_path / "y")]) == 2


@pytest.mark.slow
def test_export_passes_parity_and_reads_as_a_fisheye_model(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    checkpoint = Checkpoint(CONFIG, pretrained.state_dict())
    save_checkpoint(tmp_path / "fisheye.pt", checkpoint)
    assert main(["export", "--checkpoint", str(tmp_path / "fisheye.pt"), "--output",
                 str(tmp_path / "fisheye.onnx")]) == 0
    model = OnnxModel(tmp_path / "fisheye.onnx", SessionThreads(intra_op=1))
    assert (model.info.view, model.info.box_format, model.info.input_size) == (
        "fisheye", "cxcywh_radius_aligned", 64)
    assert model.info.name == "fishloc-yolox-nano-fisheye" and "Apache-2.0" in model.info.licence
    assert model.info.name == contract_info(checkpoint).name
    frame = read_dataset(toy_dataset(count=1, size=128, people=2))[0]
    rgb = cv2.cvtColor(cv2.imread(str(frame.path)), cv2.COLOR_BGR2RGB)
    assert frame.camera is not None
    (found,) = ModelRunner(model).detect([rgb], [frame.camera], min_score=0.0)
    assert len(found.scores) > 0 and np.all(np.diff(found.scores) <= 0)
    image, _, _ = frame_input(frame, training_info(CONFIG))
    with torch.no_grad():
        torch_boxes, _ = contract_module(checkpoint)(torch.from_numpy(image[None]))
    raw = model.run(image)
    np.testing.assert_allclose(raw.boxes[:5], torch_boxes[0, :5].numpy(), atol=1e-2)


def test_polar_configs_are_not_fisheye_ones() -> None:
    assert PolarDetectorConfig().arch != CONFIG.arch
    with pytest.raises(ValueError, match="multiple of 32"):
        FisheyeDetectorConfig(input_size=100)
