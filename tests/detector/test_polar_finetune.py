from __future__ import annotations

import copy
import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper

from contract.views import nadir_input, polar_grid, upright_to_radius_aligned, view_plan
from detector.checkpoint import Checkpoint, load_checkpoint, save_checkpoint, save_release
from detector.data.dataset import load_rgb
from detector.data.readers import FrameAnnotations, read_dataset
from detector.model import tiny_config
from detector.yolox.finetune import FinetuneConfig, Finetuner
from detector.yolox.loss import PolarDetectionLoss, anchors_of, assign, feature_distillation
from detector.yolox.network import YoloxNano
from detector.yolox.polar import EDGE_TO_CENTRE_PX, PolarDetectorConfig, init_from_pretrained
from detector.yolox.strips import (
    PolarStripDataset,
    StripAugment,
    collate_strips,
    frame_nadir,
    frame_strip,
    nadir_labels,
    place_labels,
    rand_conv,
    roll_strip,
    training_info,
    turn_square,
)
from fisheye.view_plan import NadirPiece
from models import ASSETS_DIR
from service.cli import main

ONNX_PATH = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"
CONFIG = PolarDetectorConfig(input_size=64, polar_width=256, polar_overlap=32)
STRIP = ["--strip", "64", "256", "32"]


@pytest.fixture(scope="module")
def pretrained() -> YoloxNano:
    return init_from_pretrained(str(ONNX_PATH), CONFIG)


# ----- labels


@pytest.mark.parametrize("shift", [0, 37, 200])
def test_rolled_strip_labels_map_back_to_the_frame_boxes(toy_dataset: Callable[..., Path],
                                                         shift: int) -> None:
    frame = read_dataset(toy_dataset(count=1, size=128, people=4))[0]
    info = training_info(CONFIG)
    strip, xyxy, _, full_turns = frame_strip(frame, info)
    assert full_turns == 0 and len(xyxy) == 4
    image, moved = roll_strip(strip, xyxy, shift, CONFIG.polar_overlap)
    assert frame.camera is not None
    start_rad = 2 * math.pi * shift / CONFIG.polar_width
    grid = dataclasses.replace(polar_grid(info, frame.camera), start_rad=start_rad)
    # A roll by k columns is the unwrap started 2πk/width later: its boxes map back alike.
    assert image.shape == (64, 288, 3)
    np.testing.assert_allclose(grid.polar_to_radius_aligned(moved), frame.boxes_cxcywh, atol=1e-6)
    centres = (moved[:, 0] + moved[:, 2]) / 2
    assert np.all((centres >= -0.5) & (centres < CONFIG.polar_width - 0.5))


def test_roll_is_the_unwrap_with_a_later_start_angle() -> None:
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (96, 96, 3), dtype=np.uint8)
    from fisheye.polar import PolarGrid

    base = PolarGrid((47.5, 47.5), 45.0, 32, 64, 0)
    rolled, _ = roll_strip(base.unwrap(frame), np.zeros((0, 4)), 10, 16)
    direct = dataclasses.replace(base, start_rad=2 * math.pi * 10 / 64, overlap=16).unwrap(frame)
    assert np.abs(rolled.astype(int) - direct.astype(int)).max() <= 1  # float maps, bilinear rounding


def test_person_below_the_lens_is_left_out(toy_dataset: Callable[..., Path]) -> None:
    frame = read_dataset(toy_dataset(count=1, size=128, people=2))[0]
    below = np.array([[*frame.principal_point, 10.0, 20.0]])
    frame = dataclasses.replace(
        frame, boxes_cxcywh=np.concatenate([frame.boxes_cxcywh, below]),
        locations_m=np.concatenate([frame.locations_m, [[0.0, 0.0]]]),
        distances_m=np.append(frame.distances_m, 0.0),
        visible_fraction=np.append(frame.visible_fraction, 1.0), bboxes_xywh=None, areas_px=None)
    _, xyxy, _, full_turns = frame_strip(frame, training_info(CONFIG))
    assert full_turns == 1 and len(xyxy) == 2


@pytest.mark.parametrize(("boxes", "expected"), [
    (np.zeros((0, 4)), np.zeros((0, 4))),
    (np.array([[100.0, 10, 120, 40]]), np.array([[100.0, 10, 120, 40]])),  # middle: one copy
    # across the seam: the left remnant (over half) and the whole copy in the overlap
    (np.array([[-8.0, 10, 10, 40]]), np.array([[-0.5, 10, 10, 40], [248, 10, 266, 40]])),
    # near the start: also whole in the overlap
    (np.array([[2.0, 10, 20, 40]]), np.array([[2.0, 10, 20, 40], [258, 10, 276, 40]])),
    # mostly past the top of the strip: dropped
    (np.array([[100.0, -40, 120, 5]]), np.zeros((0, 4))),
])
def test_label_copies_at_the_seam(boxes: np.ndarray, expected: np.ndarray) -> None:
    np.testing.assert_allclose(place_labels(boxes, 256, (288, 64)), expected.reshape(-1, 4))


def test_samples_are_reproducible_and_flipped_labels_stay_in_the_strip(
        toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128, people=3))
    dataset = PolarStripDataset(frames, CONFIG, StripAugment(flip=1.0), seed=3)
    dataset.set_epoch(1)
    first, again = dataset[0], dataset[0]
    np.testing.assert_array_equal(first.image, again.image)
    np.testing.assert_array_equal(first.labels_xyxy, again.labels_xyxy)
    dataset.set_epoch(2)
    assert not np.array_equal(first.image, dataset[0].image)
    labels = first.labels_xyxy - EDGE_TO_CENTRE_PX
    assert len(labels) >= 3 and np.all(labels[:, :2] >= -0.5) and np.all(labels[:, 2] <= 287.5)
    images, targets = collate_strips([first, dataset[1]])
    assert images.shape == (2, 3, 64, 288) and len(targets) == 2


@pytest.mark.parametrize("scale", [1.5, 0.75])
def test_a_band_scale_strip_is_the_band_of_a_planned_view(toy_dataset: Callable[..., Path],
                                                          scale: float) -> None:
    frame = read_dataset(toy_dataset(count=1, size=128, people=4))[0]
    info = training_info(CONFIG)
    _, xyxy, feet, _ = frame_strip(frame, info)
    band, band_xyxy, band_feet, _ = frame_strip(frame, info, band_scale=scale)
    # the rows and columns times the scale over the same radii: people that much larger (or
    # smaller, a view whose budget shrinks its band) in both directions
    rows, columns = round(64 * scale), round(256 * scale)
    assert band.shape == (rows, columns, 3)
    sizes, band_sizes = xyxy[:, 2:] - xyxy[:, :2], band_xyxy[:, 2:] - band_xyxy[:, :2]
    np.testing.assert_allclose(band_sizes, scale * sizes, rtol=0.05)
    np.testing.assert_allclose(band_feet[:, :2] + 0.5, scale * (feet[:, :2] + 0.5), rtol=0.05, atol=0.5)
    np.testing.assert_allclose(band_feet[:, 2], feet[:, 2] / scale, rtol=0.05)  # metres per strip px
    # samples keep the served rows so that batches stack: a window about a person of a larger
    # band, a smaller one padded below its rim
    dataset = PolarStripDataset([frame], CONFIG, StripAugment(band_scales=(scale,), flip=0.0), seed=1)
    dataset.set_epoch(0)
    sample = dataset[0]
    assert sample.image.shape == (64, columns + 32, 3)
    labels = sample.labels_xyxy - EDGE_TO_CENTRE_PX
    inside = min(rows, 64) - 0.5
    assert len(labels) >= 1 and np.all(labels[:, 1] >= -0.5) and np.all(labels[:, 3] <= inside)
    assert len(sample.feet) == len(labels)
    assert np.all(sample.image[rows:] == info.pad_value) and not np.all(sample.image[:rows] == info.pad_value)
    with pytest.raises(ValueError, match="band_scales"):
        StripAugment(band_scales=(0.4,))


def test_nadir_labels_read_back_as_each_persons_box() -> None:
    nadir = NadirPiece(centre_px=(500.0, 400.0), half_px=150.0, side=384, column=0, owned_px=80.0)
    # across, along: on the image's axes the ellipse's upright box reads back exactly
    on_axes = np.array([[560.0, 400.0, 30.0, 70.0], [500.0, 330.0, 40.0, 60.0], [420.0, 400.0, 50.0, 50.0]])
    np.testing.assert_allclose(upright_to_radius_aligned(nadir, nadir_labels(nadir, on_axes)), on_axes,
                               atol=1e-9)
    # the first, 60 px right of the centre: 70 along the ray (x), 30 across, 1.28 input px a px
    centre, half = np.array([210.0, 150.0]) * 1.28 - 0.5, np.array([35.0, 15.0]) * 1.28
    np.testing.assert_allclose(nadir_labels(nadir, on_axes)[0], [*(centre - half), *(centre + half)])
    # on a diagonal ray the upright box is a square: the service reads it back about the same
    # centre as a round person of the ellipse's mean square axis, and a round person exactly
    diagonal = np.array([[560.0, 460.0, 30.0, 70.0], [450.0, 350.0, 40.0, 40.0]])
    back = upright_to_radius_aligned(nadir, nadir_labels(nadir, diagonal))
    np.testing.assert_allclose(back[:, :2], diagonal[:, :2], atol=1e-9)
    np.testing.assert_allclose(back[0, 2:], 2 * math.sqrt((35 ** 2 + 15 ** 2) / 2), atol=1e-9)
    np.testing.assert_allclose(back[1], diagonal[1], atol=1e-9)


@pytest.mark.parametrize("quarters", [0, 1, 2, 3])
@pytest.mark.parametrize("flip", [False, True])
def test_a_turned_square_keeps_each_label_on_its_person(quarters: int, flip: bool) -> None:
    image = np.zeros((32, 32, 3), np.uint8)
    image[4:10, 20:30] = 255  # a person at x 20-29, y 4-9 (pixel centres)
    turned, labels = turn_square(image, np.array([[20.0, 4.0, 29.0, 9.0]]), quarters, flip)
    ys, xs = np.nonzero(turned[..., 0])
    np.testing.assert_array_equal(labels[0], [xs.min(), ys.min(), xs.max(), ys.max()])


def test_a_nadir_sample_is_the_served_nadir_view_turned(toy_dataset: Callable[..., Path]) -> None:
    frame = read_dataset(toy_dataset(count=1, size=128, people=16, seed=2))[0]
    info = training_info(CONFIG)
    assert frame.camera is not None
    nadir = view_plan(info, frame.camera).nadir
    assert nadir is not None and nadir.side <= CONFIG.input_size
    view, labels = frame_nadir(frame, info) or (None, None)
    assert view is not None and labels is not None and len(labels) >= 1
    served = nadir_input(nadir, load_rgb(frame), frame.camera.image_size, info.pad_value)
    np.testing.assert_array_equal(view, served)  # the view the service runs: a 128 px frame is not reduced
    augment = dataclasses.replace(StripAugment.none(), nadir_view=1.0)
    dataset = PolarStripDataset([frame], CONFIG, augment, seed=2)
    for epoch in range(6):
        dataset.set_epoch(epoch)
        sample = dataset[0]
        # padded to the strips' size, so that it stacks with them; no feet (taken from the box)
        assert sample.image.shape == (64, 288, 3) and np.all(np.isnan(sample.feet))
        assert np.all(sample.image[:, nadir.side:] == info.pad_value)
        turns = [turn_square(view, labels, quarters, False) for quarters in range(4)]
        assert any(np.array_equal(sample.image[:nadir.side, :nadir.side], image)
                   and np.allclose(sample.labels_xyxy - EDGE_TO_CENTRE_PX, turned) for image, turned in turns)
    with pytest.raises(ValueError, match="nadir_view"):
        StripAugment(nadir_view=1.5)


def test_rand_conv_redraws_surfaces_and_keeps_each_colours_level() -> None:
    rng = np.random.default_rng(0)
    image = np.zeros((64, 96, 3), np.uint8)
    image[16:48, 30:60] = (200, 40, 90)  # a figure on a plain ground
    image = (image + rng.integers(0, 30, image.shape)).astype(np.uint8)
    redrawn = [rand_conv(image, np.random.default_rng(seed)) for seed in range(8)]
    np.testing.assert_array_equal(redrawn[0], rand_conv(image, np.random.default_rng(0)))  # reproducible
    assert all(r.shape == image.shape and r.dtype == np.uint8 for r in redrawn)
    assert sum(not np.array_equal(r, image) for r in redrawn) >= 7
    # each channel keeps the image's mean (clipping aside) and the figure still stands out of its ground
    for r in redrawn:
        np.testing.assert_allclose(r.reshape(-1, 3).mean(axis=0), image.reshape(-1, 3).mean(axis=0), atol=12)
        inside, outside = r[20:44, 34:56].astype(float), r[:, :20].astype(float)
        assert np.abs(inside.mean(axis=(0, 1)) - outside.mean(axis=(0, 1))).max() > 10


def test_a_rand_conv_sample_keeps_its_labels_and_redraws_its_image(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=1, size=128, people=16, seed=2))
    plain = PolarStripDataset(frames, CONFIG, StripAugment.none(), seed=3)[0]
    redrawing = dataclasses.replace(StripAugment.none(), rand_conv=1.0)
    redrawn = PolarStripDataset(frames, CONFIG, redrawing, seed=3)[0]
    assert len(plain.labels_xyxy) and np.array_equal(plain.labels_xyxy, redrawn.labels_xyxy)
    np.testing.assert_array_equal(plain.feet, redrawn.feet)
    assert plain.image.shape == redrawn.image.shape and not np.array_equal(plain.image, redrawn.image)
    with pytest.raises(ValueError, match="rand_conv"):
        StripAugment(rand_conv=-0.1)


def test_the_strip_cache_stops_at_its_bound_with_the_same_samples(toy_dataset: Callable[..., Path]) -> None:
    # strips at the second look's scales are large: past `cache_bytes` a strip is unwrapped each
    # time it is drawn, the same samples either way, and its labels are counted once
    frames = read_dataset(toy_dataset(count=3, size=128, people=4))
    augment = StripAugment(band_scales=(1.0, 2.0), flip=0.0)
    unbounded = PolarStripDataset(frames, CONFIG, augment, seed=2)
    one_strip = frame_strip(frames[0], training_info(CONFIG))[0].nbytes
    bounded = PolarStripDataset(frames, CONFIG, augment, seed=2, cache_bytes=one_strip)
    for epoch in range(3):
        for dataset in (unbounded, bounded):
            dataset.set_epoch(epoch)
        for index in range(len(frames)):
            a, b = unbounded[index], bounded[index]
            np.testing.assert_array_equal(a.image, b.image)
            np.testing.assert_array_equal(a.labels_xyxy, b.labels_xyxy)
            np.testing.assert_array_equal(a.feet, b.feet)
    assert len(unbounded._strips) > 1 and unbounded.cached_bytes > one_strip
    assert len(bounded._strips) == 1 and bounded.cached_bytes == one_strip
    assert bounded.full_turns_left_out == unbounded.full_turns_left_out


def test_an_averaged_strip_is_the_view_of_as_many_samples(toy_dataset: Callable[..., Path]) -> None:
    # `StripAugment.unwrap_samples`: the same strip and labels, each px the mean of its 2 x 2
    # samples, as the service's view of `ViewPlanConfig.unwrap_samples` 2 makes it
    frame = read_dataset(toy_dataset(count=1, size=128, people=4))[0]
    info = training_info(CONFIG)
    strip, xyxy, feet, _ = frame_strip(frame, info)
    averaged, averaged_xyxy, averaged_feet, _ = frame_strip(frame, info, samples=2)
    assert averaged.shape == strip.shape and not np.array_equal(averaged, strip)
    np.testing.assert_array_equal(averaged_xyxy, xyxy)
    np.testing.assert_array_equal(averaged_feet, feet)
    turn = dataclasses.replace(info, polar=dataclasses.replace(info.polar, overlap=0))
    grid = polar_grid(turn, frame.camera)
    rgb = load_rgb(frame)
    scale = (rgb.shape[1] / frame.camera.image_size[0], rgb.shape[0] / frame.camera.image_size[1])
    assert np.array_equal(averaged, grid.unwrap(rgb, scale, info.pad_value, samples=2))
    dataset = PolarStripDataset([frame], CONFIG, StripAugment(unwrap_samples=2, roll=False, flip=0.0), seed=1)
    dataset.set_epoch(0)
    np.testing.assert_array_equal(dataset.base(0)[0], averaged)
    with pytest.raises(ValueError, match="unwrap_samples"):
        StripAugment(unwrap_samples=0)


# ----- loss


def test_every_label_gets_a_positive_and_cells_go_to_the_smallest_box() -> None:
    maps = [torch.zeros(1, 6, 64 // s, 288 // s) for s in (8, 16, 32)]
    anchors = anchors_of(maps)
    labels = torch.tensor([[10.0, 10, 14, 13], [0, 0, 60, 60], [20, 20, 44, 44]])
    owner = assign(anchors, labels, 2.5)
    assert set(owner[owner >= 0].tolist()) == {0, 1, 2}
    small_cells = anchors.centres_xy[owner == 2]
    assert torch.all((small_cells > 20) & (small_cells < 44))
    assert (assign(anchors, torch.zeros(0, 4), 2.5) == -1).all()


def test_distillation_is_zero_against_itself_and_the_loss_learns(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128, people=3))
    dataset = PolarStripDataset(frames, CONFIG, StripAugment.none())
    images, labels = collate_strips([dataset[0], dataset[1]])
    student = init_from_pretrained(str(ONNX_PATH), CONFIG).train()
    teacher = init_from_pretrained(str(ONNX_PATH), CONFIG).eval().requires_grad_(False)
    loss = PolarDetectionLoss()
    with torch.no_grad():
        teacher_maps = teacher(images)
    start = loss(student(images), labels, teacher_maps)
    assert abs(start["distill"].item()) < 1e-6
    assert set(start) == {"iou", "objectness", "class", "distill", "foot", "total"}
    bias = student.get_parameter("head.obj_preds.0.bias")
    with torch.no_grad():  # a different student: the term must see it
        bias.add_(4.0)
    assert loss(student(images), labels, teacher_maps)["distill"].item() > 1e-2
    with torch.no_grad():
        bias.sub_(4.0)
    optimizer = torch.optim.AdamW(student.parameters(), lr=1e-3)
    for _ in range(12):
        terms = loss(student(images), labels, teacher_maps)
        optimizer.zero_grad()
        terms["total"].backward()  # type: ignore[no-untyped-call]
        optimizer.step()
    end = loss(student(images), labels, teacher_maps)
    assert end["total"].item() < 0.75 * start["total"].item()
    assert end["objectness"].item() < start["objectness"].item()
    assert end["distill"].item() > 0  # it moved away from the teacher, and the term says so
    assert all(p.grad is None for p in teacher.parameters())


def test_feature_distillation_is_zero_at_the_teacher_and_blind_to_a_levels_scale() -> None:
    generator = torch.Generator().manual_seed(2)
    teacher = [torch.randn(2, 8, 8 // s, 32 // s, generator=generator) * scale
               for s, scale in ((1, 1.0), (2, 30.0), (4, 0.01))]
    assert feature_distillation(teacher, teacher).item() == 0.0
    zeros = [torch.zeros_like(t) for t in teacher]
    assert feature_distillation(zeros, teacher).item() == pytest.approx(1.0, rel=1e-3)
    noisy = [t + 0.1 * t.std() * torch.randn(t.shape, generator=generator) for t in teacher]
    term = feature_distillation(noisy, teacher).item()
    assert 0.005 < term < 0.02  # (0.1 σ)² / σ² on every level, whatever its scale
    scaled = feature_distillation([n * 7 for n in noisy], [t * 7 for t in teacher]).item()
    assert scaled == pytest.approx(term, rel=1e-3)
    with pytest.raises(ValueError, match="same levels"):
        feature_distillation(noisy[:2], teacher)


# ----- the loop


def _finetuner(pretrained: YoloxNano, frames: list[FrameAnnotations], out: Path) -> Finetuner:
    config = FinetuneConfig(epochs=2, batch_size=2, lr=1e-3, warmup_steps=2, seed=4, device="cpu",
                            checkpoint_every_s=0.0)
    return Finetuner(CONFIG, config, out, pretrained, frames, None, "toy", progress=False)


def test_resume_mid_epoch_equals_training_straight(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    frames = read_dataset(toy_dataset(count=4, size=128, people=2))
    straight = _finetuner(pretrained, frames, tmp_path / "straight")
    straight.fit()  # 2 epochs x 2 batches
    first = _finetuner(pretrained, frames, tmp_path / "cut")
    first.fit(stop_after_steps=1)  # stops inside epoch 1, leaving last.pt
    resumed = _finetuner(pretrained, frames, tmp_path / "cut")
    resumed.resume(tmp_path / "cut" / "last.pt")
    assert (resumed.epoch, resumed.batch, resumed.step) == (0, 1, 1)
    resumed.fit()
    assert straight.step == resumed.step == 4
    for key, value in straight.model.state_dict().items():
        torch.testing.assert_close(resumed.model.state_dict()[key], value, atol=1e-6, rtol=0, msg=key)
    trained, initial = straight.model.state_dict(), pretrained.state_dict()
    assert any(not torch.equal(v, initial[k]) for k, v in trained.items())
    frozen = [k for k in initial if k.startswith(("backbone.stem", "backbone.dark2", "backbone.dark3"))]
    assert frozen and all(torch.equal(trained[k], initial[k]) for k in frozen)
    last = [json.loads(line) for line in (tmp_path / "cut" / "log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in last] == [1, 2]


def test_the_boxes_alone_refit_and_every_score_stays(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    """All but `head.reg_preds` frozen: the boxes learn, and the objectness and class maps (read
    from features `reg_preds` does not feed) come out bit for bit as before."""
    frames = read_dataset(toy_dataset(count=4, size=128, people=2))
    everything_else = ("stem", "dark2", "dark3", "dark4", "dark5", "neck", "head.stems", "head.cls_convs",
                       "head.cls_preds", "head.reg_convs", "head.obj_preds")
    config = FinetuneConfig(epochs=2, batch_size=2, lr=1e-2, warmup_steps=1, seed=4, device="cpu",
                            freeze=everything_else, distill=1.0, augment=StripAugment.none())
    tuner = Finetuner(CONFIG, config, tmp_path / "boxes", pretrained, frames, None, "toy", progress=False)
    first = tuner.train_step([0, 1])
    tuner.fit()
    last = tuner.train_step([0, 1])
    trained, initial = tuner.model.state_dict(), pretrained.state_dict()
    changed = {k for k in initial if not torch.equal(trained[k], initial[k])}
    assert changed and all(k.startswith("head.reg_preds.") for k in changed)
    assert last["iou"] < first["iou"]
    dataset = PolarStripDataset(frames, CONFIG, StripAugment.none())
    images, _ = collate_strips([dataset[0], dataset[1]])
    with torch.no_grad():
        before, after = copy.deepcopy(pretrained).eval()(images), tuner.model.eval()(images)
    for old, new in zip(before, after, strict=True):  # (B, 4 + 1 + classes, h, w) per level
        assert torch.equal(new[:, 4:], old[:, 4:]) and not torch.equal(new[:, :4], old[:, :4])


def test_feature_distillation_holds_a_trained_backbones_features_to_the_teacher(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    """The whole network below the stem trains: with its pyramids held, they end much nearer
    COCO's than without (a dozen free steps at 3e-5 already move them by ~2/3 of their own size),
    and the run still learns the renders."""
    frames = read_dataset(toy_dataset(count=4, size=128, people=3))
    dataset = PolarStripDataset(frames, CONFIG, StripAugment.none())
    images, _ = collate_strips([dataset[i] for i in range(4)])
    with torch.no_grad():
        backbone = pretrained.backbone(images)
        teacher_levels = [*backbone, *pretrained.neck(backbone)]
    drift, first, last = {}, {}, {}
    for weight in (0.0, 20.0):
        config = FinetuneConfig(epochs=6, batch_size=2, lr=3e-5, warmup_steps=1, seed=4, device="cpu",
                                freeze=("stem",), feature_distill=weight, augment=StripAugment.none())
        tuner = Finetuner(CONFIG, config, tmp_path / f"held-{weight}", pretrained, frames, None, "toy",
                          progress=False)
        first[weight] = tuner.train_step([0, 1, 2, 3])
        tuner.fit()
        last[weight] = tuner.train_step([0, 1, 2, 3])
        model = tuner.model.eval()
        with torch.no_grad():
            backbone = model.backbone(images)
            drift[weight] = feature_distillation([*backbone, *model.neck(backbone)], teacher_levels).item()
    assert "features" not in first[0.0] and first[20.0]["features"] < 1e-6  # it starts at the teacher
    assert last[20.0]["features"] > 0
    assert drift[20.0] < 0.2 * drift[0.0]
    def detection(terms: dict[str, float]) -> float:
        return terms["objectness"] + terms["iou"]
    assert all(detection(last[weight]) < detection(first[weight]) for weight in (0.0, 20.0))


def _cli(out: Path, data: Path, *extra: str) -> int:
    return main(["train", "--init-from", str(ONNX_PATH), "--data", str(data), "--out", str(out),
                 "--quiet", "--threads", "1", *STRIP, *extra])


def test_cli_zero_epochs_validation_and_release(
        pretrained: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    data = toy_dataset(count=2, size=128, people=2)
    out = tmp_path / "zero"
    assert _cli(out, data, "--epochs", "0") == 0
    zero_shot = load_checkpoint(out / "last.pt")
    for key, value in pretrained.state_dict().items():
        assert torch.equal(zero_shot.model_state[key], value), key
    release = save_release(out / "last.pt", tmp_path / "release.pt")
    assert release.training_state == {} and load_checkpoint(tmp_path / "release.pt").config == CONFIG
    run = tmp_path / "one"
    assert _cli(run, data, "--epochs", "1", "--batch-size", "2", "--val", str(data)) == 0
    record = json.loads((run / "log.jsonl").read_text().splitlines()[0])
    assert {"mAP", "AP50", "AP_near", "AP_mid", "AP_far", "recall"} <= set(record["val"])
    assert set(record["train"]) == {"iou", "objectness", "class", "distill", "foot", "total"}
    assert (run / "best.pt").exists() and load_checkpoint(run / "best.pt").config == CONFIG


def test_cli_feature_distillation_is_logged_and_a_negative_weight_refused(
        toy_dataset: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = toy_dataset(count=2, size=128, people=2)
    refused = tmp_path / "refused"
    assert _cli(refused, data, "--epochs", "1", "--distill-features", "-1") == 2
    assert "feature distillation" in capsys.readouterr().err and not refused.exists()
    run = tmp_path / "held"
    assert _cli(run, data, "--epochs", "1", "--batch-size", "2", "--freeze", "stem",
                "--distill-features", "2") == 0
    record = json.loads((run / "log.jsonl").read_text().splitlines()[0])
    assert set(record["train"]) == {"iou", "objectness", "class", "distill", "foot", "features", "total"}
    assert json.loads((run / "config.json").read_text())["finetune"]["feature_distill"] == 2.0


def _not_yolox(path: Path) -> Path:
    weight = helper.make_tensor("w", TensorProto.FLOAT, [1, 3, 1, 1], [1.0, 1.0, 1.0])
    graph = helper.make_graph([helper.make_node("Conv", ["x", "w"], ["y"])], "g",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 4, 4])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 1, 4, 4])], [weight])
    onnx.save(helper.make_model(graph), str(path))
    return path


@pytest.mark.parametrize("kind", ["missing", "truncated", "not-yolox"])
def test_bad_init_from_files(kind: str, toy_dataset: Callable[..., Path], tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    data = toy_dataset(count=1, size=128, people=1)
    bad = tmp_path / f"{kind}.onnx"
    if kind == "truncated":
        bad.write_bytes(ONNX_PATH.read_bytes()[:5000])
    elif kind == "not-yolox":
        _not_yolox(bad)
    out = tmp_path / "run"
    out.mkdir()
    (out / "last.pt").write_bytes(b"previous")
    code = main(["train", "--init-from", str(bad), "--data", str(data), "--out", str(out), *STRIP])
    assert code == 2
    assert str(bad) in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["last.pt"]
    assert (out / "last.pt").read_bytes() == b"previous"


@pytest.mark.parametrize("other", ["strip", "centernet"])
def test_resuming_another_configuration_fails_and_writes_nothing(
        other: str, toy_dataset: Callable[..., Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    data = toy_dataset(count=1, size=128, people=1)
    out = tmp_path / "run"
    if other == "strip":
        wider = PolarDetectorConfig(input_size=64, polar_width=288, polar_overlap=32)
        weights = init_from_pretrained(str(ONNX_PATH), CONFIG).state_dict()
        save_checkpoint(out / "last.pt", Checkpoint(wider, weights))
    else:
        from detector.model import build_model
        centernet = build_model(tiny_config(64)).state_dict()
        save_checkpoint(out / "last.pt", Checkpoint(tiny_config(64), centernet))
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert _cli(out, data, "--resume") == 2
    assert str(out / "last.pt") in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
