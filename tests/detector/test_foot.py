"""The foot output: targets from `location_m`, the branch, its loss and training, export, the CLI."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from contract import OnnxModel, SessionThreads
from contract.views import polar_grid
from detector.checkpoint import Checkpoint, ModelInfo, load_checkpoint, save_checkpoint
from detector.data.readers import read_dataset
from detector.metrics import EvalFrame, compute_metrics
from detector.yolox.decode import top_people
from detector.yolox.finetune import FinetuneConfig, Finetuner
from detector.yolox.foot import (
    MAX_METRES_PER_PX,
    REFINE_MIN_SCORE,
    REFINE_SIDE,
    REFINE_STEP_PX,
    REFINE_STRIDE,
    FootHead,
    FootRefiner,
    foot_from_offsets,
    foot_loss,
    strip_feet,
)
from detector.yolox.loss import PolarDetectionLoss, PolarLossConfig
from detector.yolox.network import YoloxNano
from detector.yolox.polar import EDGE_TO_CENTRE_PX, PolarContract, PolarDetectorConfig, init_from_pretrained
from detector.yolox.strips import PolarStripDataset, StripAugment, collate_feet, frame_strip, training_info
from exporter.export import export_onnx
from exporter.parity import synthetic_parity_frames
from fisheye import foot_points
from models import ASSETS_DIR
from service.cli import main

ONNX_PATH = ASSETS_DIR / "pretrained" / "yolox_nano.onnx"
CONFIG = PolarDetectorConfig(input_size=64, polar_width=256, polar_overlap=32, foot=True)
FROZEN = ("stem", "dark2", "dark3", "dark4", "dark5", "neck", "head")


@pytest.fixture(scope="module")
def footed() -> YoloxNano:
    return init_from_pretrained(str(ONNX_PATH), CONFIG)


def test_an_untrained_branch_answers_the_box_side_and_leaves_the_boxes(footed: YoloxNano) -> None:
    plain = init_from_pretrained(str(ONNX_PATH), dataclasses.replace(CONFIG, foot=False))
    strips = torch.from_numpy(synthetic_parity_frames(64, count=2, width=288))
    with torch.no_grad():
        boxes, scores, foot = PolarContract(footed, 50)(strips)
        plain_boxes, plain_scores = PolarContract(plain, 50)(strips)
    torch.testing.assert_close(boxes, plain_boxes)
    torch.testing.assert_close(scores, plain_scores)
    # The bottom side of a strip box is the side nearest the principal point.
    bottom_middle = torch.stack([(boxes[..., 0] + boxes[..., 2]) / 2, boxes[..., 3]], dim=-1)
    torch.testing.assert_close(foot, bottom_middle, atol=1e-4, rtol=0)
    assert footed.foot is not None  # the branch starts as a copy of the box branch
    for foot_convs, box_convs in zip(footed.foot.convs, footed.head.reg_convs, strict=True):
        for (name, value), (_, box_value) in zip(foot_convs.state_dict().items(),
                                                 box_convs.state_dict().items(), strict=True):
            assert torch.equal(value, box_value), name


def test_foot_targets_lead_back_to_the_floor_points(toy_dataset: Callable[..., Path]) -> None:
    frame = read_dataset(toy_dataset(count=1, size=128, people=4))[0]
    assert frame.camera is not None
    info = training_info(CONFIG)
    _, xyxy, feet, _ = frame_strip(frame, info)
    turn = dataclasses.replace(info, polar=dataclasses.replace(info.polar, overlap=0))
    grid = polar_grid(turn, frame.camera)
    assert feet.shape == (len(xyxy), 3) and np.all(feet[:, 2] > 0)
    back = frame.camera.pixels_to_floor(grid.strip_to_frame(feet[:, :2]))
    np.testing.assert_allclose(back, frame.locations_m[:len(xyxy)], atol=1e-6)
    # each foot lies in the turn of its box, below its middle (nearer the centre than the head)
    centre_x = (xyxy[:, 0] + xyxy[:, 2]) / 2
    assert np.all(np.abs(feet[:, 0] - centre_x) < grid.width / 4)
    unknown = strip_feet(grid, frame.camera, np.full((1, 2), np.nan), xyxy[:1])
    assert np.all(np.isnan(unknown))


def test_rolled_and_flipped_samples_keep_each_foot_with_its_box(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128, people=4))
    dataset = PolarStripDataset(frames, CONFIG, StripAugment(flip=1.0, brightness=0.0, contrast=0.0,
                                                              saturation=0.0, hue_deg=0.0), seed=3)
    plain = PolarStripDataset(frames, CONFIG, StripAugment.none(), seed=3)
    def relative(sample_feet: np.ndarray, labels: np.ndarray, mirror: float) -> set[tuple[float, float]]:
        """Each foot's offset from its box's bottom middle, rounded (seam copies repeat a label),
        of the boxes that the strip's ends do not clip."""
        inside = (labels[:, 0] > 1.0) & (labels[:, 2] < CONFIG.strip_wh[0] - 1.0)
        sample_feet, labels = sample_feet[inside], labels[inside]
        bottom_middle = np.stack([(labels[:, 0] + labels[:, 2]) / 2, labels[:, 3]], axis=1)
        offset = (sample_feet[:, :2] - bottom_middle) * np.array([mirror, 1.0])
        return {(round(float(x), 6), round(float(y), 6)) for x, y in offset}

    for index in range(2):
        sample, reference = dataset[index], plain[index]
        assert sample.feet.shape == (len(sample.labels_xyxy), 3)
        # rolling moves a foot with its box; flipping mirrors its offset from the box's middle
        assert relative(sample.feet, sample.labels_xyxy, -1.0) == relative(reference.feet,
                                                                          reference.labels_xyxy, 1.0)
        assert np.all(np.abs(sample.feet[:, 0] - (sample.labels_xyxy[:, 0] + sample.labels_xyxy[:, 2]) / 2)
                      <= sample.labels_xyxy[:, 2] - sample.labels_xyxy[:, 0])
    feet = collate_feet([dataset[0], dataset[1]])
    assert feet is not None and feet[0].shape == (len(dataset[0].labels_xyxy), 3)


@pytest.mark.parametrize(("offsets", "metres_per_px", "expected"), [
    ([[0.0, 0.0]], 0.05, 2.0 * 0.05),  # box side: 2 px short of the target
    ([[0.0, 0.2]], 0.05, 0.0),  # 0.2 of the 10 px height below the bottom side: on target
    ([[0.1, 0.2]], 0.05, 0.4 * 0.05),  # 0.4 px to the side
    ([[0.0, 0.0]], 0.5, 2.0 * MAX_METRES_PER_PX),  # near the horizon the weight stops at the cap
])
def test_foot_loss_counts_metres(offsets: list[list[float]], metres_per_px: float, expected: float) -> None:
    box = torch.tensor([[10.0, 0.0, 14.0, 10.0]])  # xyxy, bottom side at y = 10
    target = torch.tensor([[12.0, 12.0, metres_per_px]])  # foot x, y px, metres per px
    total, count = foot_loss(torch.tensor(offsets), box, target)
    assert count == 1 and total.item() == pytest.approx(expected, abs=1e-6)
    assert foot_loss(torch.tensor(offsets), box, torch.full((1, 3), float("nan")))[1] == 0
    torch.testing.assert_close(foot_from_offsets(torch.zeros(1, 2), torch.tensor([[12.0, 5.0, 4.0, 10.0]])),
                               torch.tensor([[12.0, 10.0]]))


def test_foot_loss_cap_is_a_setting() -> None:
    box = torch.tensor([[10.0, 0.0, 14.0, 10.0]])  # the box side is 2 px short of the target
    far = torch.tensor([[12.0, 12.0, 0.5]])  # 0.5 m per px, beyond the default cap
    near = torch.tensor([[12.0, 12.0, 0.05]])
    assert foot_loss(torch.zeros(1, 2), box, far, max_metres_per_px=0.3)[0].item() == pytest.approx(0.6)
    assert foot_loss(torch.zeros(1, 2), box, far, max_metres_per_px=1.0)[0].item() == pytest.approx(1.0)
    assert foot_loss(torch.zeros(1, 2), box, near, max_metres_per_px=0.3)[0].item() == pytest.approx(0.1)
    with pytest.raises(ValueError, match="metres cap must be positive"):
        FinetuneConfig(foot_max_metres_per_px=0.0)
    # the detection loss passes its cap on: one far person (0.5 m per px, beyond both caps), each
    # positive cell's foot read off its own box, so the term scales with the cap alone
    maps = [torch.zeros(1, 6, 64 // stride, 256 // stride) for stride in (8, 16, 32)]
    offsets = [torch.zeros(1, 2, 64 // stride, 256 // stride) for stride in (8, 16, 32)]
    label = torch.tensor([[100.0, 10.0, 140.0, 50.0]])  # xyxy strip px
    feet = torch.tensor([[120.0, 52.0, 0.5]])  # foot x, y px, metres per px
    terms = {cap: PolarDetectionLoss(PolarLossConfig(foot_max_metres_per_px=cap))(
        maps, [label], foot_offsets=offsets, feet=[feet])["foot"].item() for cap in (0.1, 0.3)}
    assert terms[0.3] == pytest.approx(3 * terms[0.1]) and terms[0.1] > 0


def test_crop_windows_keep_their_people_and_feet(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=2, size=128, people=4))
    whole = PolarStripDataset(frames, CONFIG, StripAugment.none(), seed=2)
    windows = dataclasses.replace(StripAugment.none(), crop_width=96)
    cropped = PolarStripDataset(frames, CONFIG, windows, seed=2)
    for index in range(2):
        full, window = whole[index], cropped[index]
        assert window.image.shape == (64, 96, 3) and len(window.labels_xyxy) >= 1
        # every kept label is a label of the whole strip moved by the window's start, with its foot
        starts = {round(float(x0), 6) for x0 in full.labels_xyxy[:, 0] - window.labels_xyxy[0, 0]}
        x0 = next(x for x in starts if np.any(np.all(np.isclose(full.labels_xyxy - [x, 0, x, 0],
                                                                  window.labels_xyxy[0]), axis=1)))
        for label, foot in zip(window.labels_xyxy, window.feet, strict=True):
            match = np.all(np.isclose(full.labels_xyxy - [x0, 0, x0, 0], label), axis=1)
            if match.any():  # labels the window's edge clips differ from their whole-strip box
                np.testing.assert_allclose(foot, full.feet[match][0] - [x0, 0, 0])
        start = round(x0)
        np.testing.assert_array_equal(window.image, full.image[:, start:start + 96])


def test_training_the_branch_alone_moves_the_feet_not_the_boxes(
        footed: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    frames = read_dataset(toy_dataset(count=4, size=128, people=3))
    config = FinetuneConfig(epochs=3, batch_size=2, lr=1e-2, warmup_steps=1, seed=1, device="cpu",
                            freeze=FROZEN, distill=0.0, augment=StripAugment.none())
    tuner = Finetuner(CONFIG, config, tmp_path / "run", footed, frames, None, "toy", progress=False)
    first = tuner.train_step([0, 1])
    tuner.fit()
    trained = tuner.model.state_dict()
    for key, value in footed.state_dict().items():
        if not key.startswith("foot."):
            assert torch.equal(trained[key], value), key
    branch = {k: v for k, v in footed.state_dict().items() if k.startswith("foot.")}
    assert any(not torch.equal(trained[k], v) for k, v in branch.items())
    last = tuner.train_step([0, 1])
    assert first["foot"] > 0 and last["foot"] < first["foot"]


def test_export_carries_the_foot_and_matches_torch(footed: YoloxNano, tmp_path: Path) -> None:
    network = copy.deepcopy(footed)
    with torch.no_grad():  # a branch that answers something else than the box side
        for pred in network.foot.preds:  # type: ignore[union-attr]
            pred.bias.copy_(torch.tensor([0.1, -0.2]))  # type: ignore[union-attr]
    checkpoint = Checkpoint(CONFIG, network.state_dict(), ModelInfo("foot-test", "toy", 0.3), {})
    path = tmp_path / "foot.onnx"
    export_onnx(checkpoint, path)  # runs the parity check, foot included
    model = OnnxModel(path, SessionThreads(1))
    assert model.has_foot
    strips = synthetic_parity_frames(64, count=1, width=288)
    raw = model.run(strips[0])
    assert raw.foot is not None
    boxes, foot = raw.boxes.astype(np.float64), raw.foot.astype(np.float64)
    width, height = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    centre_x = (boxes[:, 0] + boxes[:, 2]) / 2
    np.testing.assert_allclose(foot[:, 0], centre_x + 0.1 * width, atol=1e-3)
    np.testing.assert_allclose(foot[:, 1], boxes[:, 3] - 0.2 * height, atol=1e-3)


def test_foot_loss_with_a_refiner_averages_the_coarse_and_every_pass() -> None:
    from detector.yolox.foot import FootHead

    head = FootHead(width=2, levels=3, depthwise=True, refine=True, refine_steps=2)
    assert head.refiner is not None
    box = torch.tensor([[10.0, 0.0, 14.0, 10.0]])  # box side at (12, 10): 2 px short of the target
    target = torch.tensor([[12.0, 12.0, 0.05]])
    fine = torch.zeros(1, 2, 4, 4)
    coarse, _ = foot_loss(torch.zeros(1, 2), box, target)
    torch.testing.assert_close(foot_loss(torch.zeros(1, 2), box, target, (fine, head))[0], coarse)  # identity
    last = head.refiner.mlp[-1]
    assert isinstance(last, torch.nn.Linear)
    with torch.no_grad():
        last.bias.copy_(torch.tensor([0.0, 0.125]))  # each pass moves the point 1 px (scale 8 px) down
    total, count = foot_loss(torch.zeros(1, 2), box, target, (fine, head))
    assert count == 1 and total.item() == pytest.approx((2.0 + 1.0 + 0.0) / 3 * 0.05, abs=1e-6)
    weighted, _ = foot_loss(torch.zeros(1, 2), box, target, (fine, head), coarse_weight=0.5)
    assert weighted.item() == pytest.approx((0.5 * 2.0 + 1.0 + 0.0) / 2.5 * 0.05, abs=1e-6)
    refined_only, _ = foot_loss(torch.zeros(1, 2), box, target, (fine, head), coarse_weight=0.0)
    assert refined_only.item() == pytest.approx((1.0 + 0.0) / 2 * 0.05, abs=1e-6)
    with pytest.raises(ValueError, match="coarse foot point's weight"):
        FinetuneConfig(foot_coarse_weight=float("nan"))


def _coordinate_maps(height: int, width: int) -> torch.Tensor:
    """(1, 2, h, w) stride-8 maps whose channels are each cell's centre x and y in input px."""
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float32),
                                torch.arange(width, dtype=torch.float32), indexing="ij")
    return torch.stack([cols, rows])[None] * REFINE_STRIDE + REFINE_STRIDE / 2


def test_the_refiner_reads_the_fine_features_about_each_point_and_starts_as_the_identity() -> None:
    refiner = FootRefiner(width=2)
    points = torch.tensor([[[40.0, 30.0], [101.5, 66.25]]])  # (1, K, 2) px, inside a 16 x 24 map
    maps = _coordinate_maps(16, 24)
    torch.testing.assert_close(refiner(maps, points), points)  # zero last layer: the coarse point
    patches = refiner.patches(maps, points)  # (1, K, 2, S²): the cells' coordinates, interpolated
    centre, half = (REFINE_SIDE ** 2) // 2, REFINE_STEP_PX * (REFINE_SIDE - 1) / 2
    torch.testing.assert_close(patches[0, :, :, centre], points[0])  # the point itself
    torch.testing.assert_close(patches[0, :, :, 0], points[0] - half)  # the patch's first corner
    torch.testing.assert_close(patches[0, :, :, -1], points[0] + half)


def _moving_head(refine_steps: int = 1) -> FootHead:
    """A foot head whose refiner moves each point by what it reads."""
    head = FootHead(width=2, levels=3, depthwise=True, refine=True, refine_steps=refine_steps)
    assert head.refiner is not None
    with torch.no_grad():
        torch.manual_seed(1)
        for layer in head.refiner.mlp:
            if isinstance(layer, torch.nn.Linear):
                layer.weight.normal_(0.0, 0.05)
    return head


def test_refiner_passes_each_read_the_patch_about_the_previous_answer() -> None:
    head = _moving_head(refine_steps=2)
    assert head.refiner is not None
    maps, points = _coordinate_maps(16, 24), torch.tensor([[[40.0, 30.0], [101.5, 66.25]]])
    once = head.refiner(maps, points)
    assert not torch.allclose(once, points)
    torch.testing.assert_close(head.refine(maps, points), head.refiner(maps, once))
    with pytest.raises(ValueError, match="foot_refine_steps"):
        dataclasses.replace(CONFIG, foot_refine=True, foot_refine_steps=0)


def test_only_the_candidates_scored_from_the_floor_are_refined() -> None:
    head = _moving_head()
    maps = _coordinate_maps(16, 24).expand(2, -1, -1, -1)
    points = torch.tensor([[40.0, 30.0], [101.5, 66.25], [60.0, 20.0], [80.0, 50.0]]).expand(2, -1, -1)
    scores = torch.tensor([[0.9, 0.3, 0.04, 0.01], [0.8, 0.06, REFINE_MIN_SCORE, 0.0]])  # descending
    everything = head.refine(maps, points)
    assert not torch.allclose(everything, points)
    refined = head.refine_scored(maps, points, scores)  # the longest scored prefix: 3 of the 4
    torch.testing.assert_close(refined[:, :3], everything[:, :3])
    torch.testing.assert_close(refined[:, 3:], points[:, 3:])  # coarse beneath the floor
    torch.testing.assert_close(head.refine_scored(maps, points, torch.zeros(2, 4)), points)  # none
    torch.testing.assert_close(head.refine_scored(maps, points, scores, min_score=0.0), everything)


def test_export_carries_the_refined_foot_and_matches_torch(footed: YoloxNano, tmp_path: Path) -> None:
    raised = copy.deepcopy(footed)
    with torch.no_grad():  # a person score over the refiner's floor for some of the toy's candidates
        for pred in raised.head.obj_preds:
            pred.bias.add_(4.0)
    network = raised.with_foot_refiner().with_foot_neck()
    assert network.foot is not None and network.foot.refiner is not None and network.foot.features
    with torch.no_grad():  # a refiner that moves the points by what it reads, a neck of its own
        torch.manual_seed(0)
        last = network.foot.refiner.mlp[-1]
        assert isinstance(last, torch.nn.Linear)
        last.weight.normal_(0.0, 0.05)
        for parameter in network.foot.features.parameters():
            parameter.mul_(1.1)
    config = dataclasses.replace(CONFIG, foot_refine=True, foot_neck=True)
    checkpoint = Checkpoint(config, network.state_dict(), ModelInfo("refine-test", "toy", 0.3), {})
    report = export_onnx(checkpoint, tmp_path / "refined.onnx")  # the parity check covers the foot
    assert report.parity.frames > 0
    plain = export_onnx(Checkpoint(CONFIG, raised.state_dict(), ModelInfo("plain", "toy", 0.3), {}),
                        tmp_path / "plain.onnx")
    strips = synthetic_parity_frames(64, count=1, width=288)
    refined_raw = OnnxModel(tmp_path / "refined.onnx", SessionThreads(1)).run(strips[0])
    plain_raw = OnnxModel(plain.output, SessionThreads(1)).run(strips[0])
    np.testing.assert_allclose(refined_raw.boxes, plain_raw.boxes, atol=1e-4)  # boxes untouched
    assert refined_raw.foot is not None and plain_raw.foot is not None
    assert np.abs(refined_raw.foot - plain_raw.foot).max() > 0.01  # the refiner moved the feet
    # the graph refines the candidates from the floor (a length it counts) and leaves the rest coarse
    image = torch.from_numpy(strips[0])[None]
    with torch.no_grad():
        _, scores, every = top_people(network.eval(), image, CONFIG.max_detections, refine_min_score=0.0)
        _, _, coarse = top_people(network, image, CONFIG.max_detections, refine_min_score=2.0)
    assert every is not None and coarse is not None
    scored = scores[0].numpy() >= REFINE_MIN_SCORE
    assert 0 < scored.sum() < len(scored)
    np.testing.assert_allclose(refined_raw.scores, scores[0].numpy(), atol=1e-5)
    every_px, coarse_px = (feet[0].numpy() - EDGE_TO_CENTRE_PX for feet in (every, coarse))
    np.testing.assert_allclose(refined_raw.foot[scored], every_px[scored], atol=1e-3)
    np.testing.assert_allclose(refined_raw.foot[~scored], coarse_px[~scored], atol=1e-3)


def test_cli_adds_the_foot_to_a_polar_checkpoint(
        footed: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    plain = dataclasses.replace(CONFIG, foot=False)
    start = tmp_path / "start.pt"
    network = init_from_pretrained(str(ONNX_PATH), plain)
    save_checkpoint(start, Checkpoint(plain, network.state_dict(), ModelInfo("s", "toy", 0.4), {}))
    data = toy_dataset(count=2, size=128, people=2)
    out = tmp_path / "foot"
    # --zoom draws each sample's strip radius: an augmentation, which a checkpoint's strip allows;
    # --nadir-view mixes in nadir views, whose people have no foot labels
    args = ["train", "--init-from", str(start), "--foot", "--data", str(data), "--out", str(out), "--quiet",
            "--threads", "1", "--epochs", "1", "--batch-size", "2", "--distill", "0", "--zoom", "1", "1.5",
            "--nadir-view", "0.5", "--freeze", *FROZEN]
    assert main(args) == 0
    trained = load_checkpoint(out / "last.pt")
    assert trained.config == CONFIG
    for key, value in network.state_dict().items():
        assert torch.equal(trained.model_state[key], value), key
    assert main([*args[:1], "--init-from", str(start), "--strip", "64", "256", "32", *args[4:]]) == 2
    assert "fixes the view and strip" in capsys.readouterr().err


def test_a_foot_neck_starts_as_the_detectors_and_trains_alone(
        footed: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    network = footed.with_foot_refiner().with_foot_neck()
    assert network.foot is not None and network.foot.features is not None
    strips = torch.from_numpy(synthetic_parity_frames(64, count=2, width=288))
    with torch.no_grad():  # a copy of the neck and stems: the same foot points as without it
        before = PolarContract(footed.with_foot_refiner(), 50)(strips)
        after = PolarContract(network, 50)(strips)
    for old, new in zip(before, after, strict=True):
        torch.testing.assert_close(new, old)
    start = tmp_path / "start.pt"
    save_checkpoint(start, Checkpoint(CONFIG, footed.state_dict(), ModelInfo("s", "toy", 0.4), {}))
    out = tmp_path / "neck"
    data = toy_dataset(count=2, size=128, people=2)
    assert main(["train", "--init-from", str(start), "--foot-neck", "--data", str(data), "--out", str(out),
                 "--quiet", "--threads", "1", "--epochs", "1", "--batch-size", "2", "--distill", "0",
                 "--lr", "0.01", "--freeze", *FROZEN]) == 0
    trained = load_checkpoint(out / "last.pt")
    assert trained.config == dataclasses.replace(CONFIG, foot_neck=True)
    neck_keys = [key for key in trained.model_state if key.startswith("foot.features.neck.")]
    assert neck_keys and any(not torch.equal(trained.model_state[key],  # the copy learnt
                                             footed.state_dict()[key.removeprefix("foot.features.")])
                             for key in neck_keys)
    for key, value in footed.state_dict().items():  # the detector's own neck did not
        if not key.startswith("foot."):
            assert torch.equal(trained.model_state[key], value), key
    with pytest.raises(ValueError, match="refiner or neck needs"):
        dataclasses.replace(CONFIG, foot=False, foot_neck=True)


def test_metrics_place_people_by_the_predicted_foot() -> None:
    from fisheye import camera_from_dict

    camera = camera_from_dict({"id": "m", "altitude_m": 3.0, "image_size": [401, 401],
                               "principal_point": [200.0, 200.0], "focal_px": [120.0, 120.0], "kb": [1.0]})
    truth = np.array([[2.0, 0.0]])
    foot_px = camera.floor_to_pixels(truth)
    box = np.array([[foot_px[0, 0] + 20.0, foot_px[0, 1], 14.0, 30.0]])  # its near side 5 px beyond the feet
    frame = EvalFrame(gt_boxes=box, gt_locations_m=truth, gt_distances_m=np.array([2.0]), det_boxes=box,
                      det_scores=np.array([0.9]), principal_point=camera.principal_point, camera=camera,
                      det_foot_px=foot_px)
    metrics = compute_metrics([frame], 0.5)
    box_side = camera.pixels_to_floor(foot_points(box, camera.principal_point))
    assert metrics["mPE"] == pytest.approx(0.0, abs=1e-9)
    assert metrics["mPE_box_side"] == pytest.approx(float(np.linalg.norm(box_side - truth)))
    assert metrics["mPE_box_side"] > 0.1 and metrics["mPE_center"] > metrics["mPE_box_side"]
    without = compute_metrics([dataclasses.replace(frame, det_foot_px=None)], 0.5)
    assert without["mPE"] == without["mPE_box_side"]


@pytest.mark.parametrize("batch", [1, 3])
def test_bilinear_samples_are_grid_samples_border_padding(batch: int) -> None:
    from torch.nn import functional

    from detector.yolox.foot import sample_bilinear

    torch.manual_seed(4)
    features = torch.randn(batch, 5, 7, 11)
    points = torch.rand(batch, 6, 9, 2) * torch.tensor([11.0, 7.0]) * 8 * 1.4 - 12  # inside, past every edge
    points[0, 0, 0] = torch.tensor([4.0, 4.0])  # the first cell's centre
    points[0, 0, 1] = torch.tensor([88.0, 56.0])  # the far corner
    grid = points / torch.tensor([11.0 * 8, 7.0 * 8]) * 2 - 1
    expected = functional.grid_sample(features, grid, mode="bilinear", padding_mode="border",
                                      align_corners=False).permute(0, 2, 3, 1)  # (B, K, S, C)
    torch.testing.assert_close(sample_bilinear(features, points, 8), expected, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(sample_bilinear(features, points, 8)[0, 0, 0], features[0, :, 0, 0])
    # the gradient reaches the features and the points, as grid_sample's does
    points.requires_grad_(True)
    features.requires_grad_(True)
    sample_bilinear(features, points, 8).sum().backward()
    assert features.grad is not None and points.grad is not None and points.grad.abs().sum() > 0


def test_a_top_down_foot_neck_keeps_the_stride_8_features_and_drops_the_bottom_up_path(
        footed: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    from detector.yolox.neck import TopDownFPN

    necked = footed.with_foot_refiner().with_foot_neck()
    with torch.no_grad():  # a foot neck that differs from the detector's, so that a mix-up shows
        assert necked.foot is not None and necked.foot.features is not None
        for parameter in necked.foot.features.parameters():
            parameter.mul_(1.1)
    cut = necked.with_foot_neck_top_down()
    assert cut.foot is not None and cut.foot.features is not None
    assert type(cut.foot.features.neck) is TopDownFPN and cut.config.foot_neck_top_down
    foot_keys = [key for key in cut.state_dict() if key.startswith("foot.features.neck.")]
    assert foot_keys and not any(".c3_n3." in key or ".bu_conv1." in key for key in foot_keys)
    images = torch.from_numpy(synthetic_parity_frames(64, count=2, width=288)).permute(0, 3, 1, 2).float()
    with torch.no_grad():
        maps, offsets, fine = necked.forward_with_foot(images)
        cut_maps, cut_offsets, cut_fine = cut.forward_with_foot(images)
        levels = cut.backbone(images)
        _, f_out0, _, _ = cut.foot.features.neck.top_down(levels)
        stride_16 = cut.foot.convs[1](cut.foot.features.stems[1](f_out0))
    for before, after in zip(maps, cut_maps, strict=True):
        torch.testing.assert_close(after, before)  # the detector is untouched
    torch.testing.assert_close(cut_fine, fine)  # the refiner reads the same stride-8 features
    torch.testing.assert_close(cut_offsets[0], offsets[0])  # and the stride-8 level the same offsets
    torch.testing.assert_close(cut.foot.preds[1](stride_16), cut_offsets[1])  # stride 16: the top-down output
    start = tmp_path / "start.pt"
    config = dataclasses.replace(CONFIG, foot_refine=True, foot_neck=True)
    save_checkpoint(start, Checkpoint(config, necked.state_dict(), ModelInfo("s", "toy", 0.4), {}))
    out = tmp_path / "top-down"
    data = toy_dataset(count=2, size=128, people=2)
    assert main(["train", "--init-from", str(start), "--foot-neck-top-down", "--data", str(data),
                 "--out", str(out), "--quiet", "--threads", "1", "--epochs", "1", "--batch-size", "2",
                 "--distill", "0", "--freeze", *FROZEN]) == 0
    trained = load_checkpoint(out / "last.pt")
    assert trained.config == dataclasses.replace(config, foot_neck_top_down=True)
    export = export_onnx(trained, tmp_path / "top-down.onnx")  # the parity check covers the foot
    assert export.parity.frames > 0
    with pytest.raises(ValueError, match="cuts the foot's own neck"):
        dataclasses.replace(CONFIG, foot_neck_top_down=True)
    with pytest.raises(ValueError, match="cuts the foot's own neck"):
        footed.with_foot_neck_top_down()


def test_a_head_trained_on_from_a_checkpoint_is_held_to_another_teacher(
        footed: YoloxNano, toy_dataset: Callable[..., Path], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """`--teacher`: the COCO network distils a head that goes on from a fine-tuned checkpoint, and
    `--freeze ... foot` leaves the feet as they were."""
    network = copy.deepcopy(footed)
    with torch.no_grad():  # a head that has moved away from COCO's, as a fine-tuned one has
        for name, parameter in network.named_parameters():
            if name.startswith("head."):
                parameter.add_(0.05 * torch.randn_like(parameter))
    start = tmp_path / "start.pt"
    save_checkpoint(start, Checkpoint(CONFIG, network.state_dict(), ModelInfo("s", "toy", 0.4), {}))
    data = toy_dataset(count=2, size=128, people=2)
    out = tmp_path / "head"
    args = ["train", "--init-from", str(start), "--data", str(data), "--out", str(out), "--quiet",
            "--threads", "1", "--epochs", "1", "--batch-size", "2", "--distill", "4", "--lr", "0.01",
            "--freeze", "stem", "dark2", "dark3", "dark4", "dark5", "neck", "foot"]
    assert main([*args, "--teacher", str(ONNX_PATH)]) == 0
    trained = load_checkpoint(out / "last.pt")
    moved = {k for k, v in network.state_dict().items() if not torch.equal(trained.model_state[k], v)}
    assert moved and all(k.startswith("head.") for k in moved)  # the foot branch frozen with the rest
    coco = init_from_pretrained(str(ONNX_PATH), dataclasses.replace(CONFIG, foot=False)).state_dict()
    teacher = trained.training_state["teacher"]
    assert set(teacher) == set(coco) and all(torch.equal(teacher[k], v) for k, v in coco.items())
    # resuming it without the teacher it was distilled from is refused, naming the checkpoint
    assert main([*args, "--resume"]) == 2
    assert f"{out / 'last.pt'} was distilled from another teacher" in capsys.readouterr().err
    # without --teacher the start itself teaches, as before
    assert main([*args[:6], str(tmp_path / "self"), *args[7:]]) == 0
    own = load_checkpoint(tmp_path / "self" / "last.pt").training_state["teacher"]
    assert torch.equal(own["head.cls_preds.0.weight"], network.state_dict()["head.cls_preds.0.weight"])
    # a teacher that cannot be read is refused before anything is written
    missing = tmp_path / "missing.onnx"
    assert main([*args[:6], str(tmp_path / "bad"), *args[7:], "--teacher", str(missing)]) == 2
    assert str(missing) in capsys.readouterr().err and not (tmp_path / "bad").exists()
