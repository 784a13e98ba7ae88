from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from detector.checkpoint import ModelInfo, load_checkpoint, save_release
from detector.data.dataset import AugmentConfig, DetectionDataset, collate
from detector.data.readers import read_dataset
from detector.evaluate import evaluate, torch_predictor
from detector.graph import ContractModel, centernet_info
from detector.losses import DetectionLoss, LossConfig
from detector.model import build_model, tiny_config
from detector.operating_point import NMS_GRID
from detector.trainer import TrainConfig, Trainer
from service.cli import main

SIZE = 64


def test_tiny_model_overfits_a_handful_of_frames(toy_dataset: Callable[..., Path]) -> None:
    frames = read_dataset(toy_dataset(count=4, size=96, people=2))
    torch.manual_seed(0)
    model = build_model(replace(tiny_config(96), widths=(8, 12, 16, 24, 24), neck_width=16, head_width=16))
    batch = collate([DetectionDataset(frames, 96)[i] for i in range(4)])
    images = model.normalise(batch.images)
    loss = DetectionLoss(LossConfig(equivariance=True))
    optimizer = torch.optim.Adam(model.parameters(), lr=5e-3)
    generator = torch.Generator().manual_seed(0)
    model.train()
    for _ in range(250):
        terms = loss(model, images, batch.boxes, generator)
        optimizer.zero_grad()
        terms["total"].backward()
        optimizer.step()
    assert float(terms["heatmap"].detach()) < 0.5
    info = centernet_info(model.config, ModelInfo(default_min_score=0.3))
    metrics = evaluate(torch_predictor(ContractModel(model.eval()), info), frames).metrics
    assert metrics["AP50"] >= 0.9
    assert metrics["recall"] >= 0.85
    # One pixel of this 96 px toy lens is ~0.4 m five metres out; the foot point must beat the centre.
    assert metrics["mPE"] < 1.0
    assert metrics["mPE"] < metrics["mPE_center"]


def _trainer(frames: list, out: Path, epochs: int) -> Trainer:
    config = TrainConfig(epochs=epochs, batch_size=2, lr=3e-3, warmup_steps=2, seed=5,
                         augment=AugmentConfig(rotation=True), device="cpu")
    return Trainer(tiny_config(64), config, out, frames, frames[:2], "toy", progress=False)


def _read_log(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]


def test_training_resumes_to_exactly_the_same_state(toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    frames = read_dataset(toy_dataset(count=4, size=64, people=2))
    straight = _trainer(frames, tmp_path / "straight", epochs=3)
    straight.fit()
    interrupted = _trainer(frames, tmp_path / "interrupted", epochs=3)
    interrupted.config = replace(interrupted.config, epochs=1)
    interrupted.fit()  # stops after epoch 1; a new process would now resume from last.pt
    resumed = _trainer(frames, tmp_path / "interrupted", epochs=3)
    resumed.resume(tmp_path / "interrupted" / "last.pt")
    assert resumed.epoch == 1
    resumed.fit()
    for key, value in straight.model.state_dict().items():
        assert torch.equal(value, resumed.model.state_dict()[key]), key
    steps = [t.optimizer.state_dict()["state"][0]["step"] for t in (straight, resumed)]
    assert steps[0] == steps[1]
    log = _read_log(tmp_path / "interrupted")
    assert [r["epoch"] for r in log] == [1, 2, 3]
    straight_log = _read_log(tmp_path / "straight")
    assert log[-1]["train"] == straight_log[-1]["train"]
    assert (tmp_path / "straight" / "training.png").stat().st_size > 0
    checkpoint = load_checkpoint(tmp_path / "straight" / "last.pt")
    assert checkpoint.info.model_version == "straight-e3" and checkpoint.info.trained_on == "toy"


def test_train_eval_and_export_commands(toy_dataset: Callable[..., Path], tmp_path: Path) -> None:
    data = toy_dataset(count=4, size=64, name="train")
    val = toy_dataset(count=2, size=64, seed=1, split="unseen", name="val")
    out = tmp_path / "run"
    assert main(["train", "--data", str(data), "--val", str(val), "--out", str(out), "--epochs", "1",
                 "--model-size", "tiny", "--input-size", "64", "--batch-size", "2", "--quiet",
                 "--no-equivariance", "--rotation-aug"]) == 0
    assert (out / "last.pt").exists() and (out / "best.pt").exists()
    assert main(["train", "--data", str(data), "--out", str(out), "--epochs", "2", "--resume",
                 "--model-size", "tiny", "--input-size", "64", "--batch-size", "2", "--quiet"]) == 0
    assert load_checkpoint(out / "last.pt").training_state["epoch"] == 2
    release = tmp_path / "release.pt"
    save_release(out / "last.pt", release)
    assert load_checkpoint(release).training_state == {}
    assert release.stat().st_size < (out / "last.pt").stat().st_size
    assert main(["train", "--data", str(data), "--out", str(tmp_path / "ft"), "--epochs", "1", "--init",
                 str(release), "--batch-size", "2", "--quiet"]) == 0
    assert load_checkpoint(tmp_path / "ft" / "last.pt").config == load_checkpoint(release).config
    onnx_path = tmp_path / "model.onnx"
    assert main(["export", "--checkpoint", str(out / "last.pt"), "--output", str(onnx_path)]) == 0
    both = toy_dataset(count=2, size=64, seed=2, split="unseen", name="mixed")
    results = {}
    for model in (out / "last.pt", onnx_path):
        target = tmp_path / f"{model.suffix[1:]}.json"
        assert main(["eval", "--model", str(model), "--data", str(both), "--json", str(target),
                     "--plots", str(tmp_path / "plots")]) == 0
        results[model.suffix] = json.loads(target.read_text())
    for key in ("mAP", "AP50", "AP75", "AP_near", "AP_mid", "AP_far", "mPE", "PE_near", "PE_mid", "PE_far",
                "mPE_center", "precision", "recall"):
        assert key in results[".onnx"]
    assert results[".pt"]["AP50"] == pytest.approx(results[".onnx"]["AP50"], abs=1e-6)
    trained = load_checkpoint(out / "last.pt").info  # its operating point, chosen on --val
    assert results[".onnx"]["nms_iou"] == trained.nms_iou and trained.nms_iou in NMS_GRID
    assert results[".onnx"]["min_score"] == pytest.approx(trained.default_min_score)
    chosen = tmp_path / "chosen.json"
    assert main(["eval", "--model", str(onnx_path), "--data", str(both), "--json", str(chosen),
                 "--operating-point"]) == 0
    swept = json.loads(chosen.read_text())
    assert [p["nms_iou"] for p in swept["operating_points"]] == list(NMS_GRID)
    best = max(swept["operating_points"], key=lambda p: p["f1"])
    assert (swept["nms_iou"], swept["min_score"]) == (best["nms_iou"], best["min_score"])
    assert swept["layouts"] == ["fixed"]  # a model of a fixed view: no layout to store a point under
    assert main(["eval", "--model", str(onnx_path), "--data", str(both), "--json", str(chosen),
                 "--nms-iou", "1.5"]) == 2
    for plot in ("pr_curve.png", "pe_by_distance.png"):
        assert (tmp_path / "plots" / plot).exists()
