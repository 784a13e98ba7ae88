"""The training loop: epochs over a DetectionDataset, validation, logs, plots and exact resumption.

Everything random is seeded and checkpointed: the data order of epoch e comes from a generator
seeded with (seed, e), augmentation from (seed, e, index), the equivariance angles from a generator
whose state is saved, and the global torch/numpy/python RNG states are saved too. Resuming from
`last.pt` therefore continues exactly as if training had never stopped.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from detector.checkpoint import Checkpoint, ModelInfo, load_checkpoint, save_checkpoint
from detector.data.dataset import AugmentConfig, DetectionDataset, collate
from detector.data.readers import FrameAnnotations
from detector.evaluate import TorchContract, choose_operating_point, json_safe
from detector.graph import ContractModel, centernet_info
from detector.losses import DetectionLoss, LossConfig
from detector.model import DetectorConfig, FishLocNet, build_model
from detector.plots import plot_training
from detector.schedule import restore_rng, rng_state, seed_everything, warmup_cosine

LOG_FILE = "log.jsonl"
LAST = "last.pt"
BEST = "best.pt"


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 30
    batch_size: int = 16
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 100
    final_lr_fraction: float = 0.05
    grad_clip: float = 10.0
    seed: int = 0
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    val_limit: int = 200
    device: str = "auto"


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


class Trainer:
    """Trains one model into `out/`: `last.pt` each epoch, `best.pt` at the best validation mAP."""

    def __init__(self, model_config: DetectorConfig, config: TrainConfig, out: Path,
                 train_frames: list[FrameAnnotations], val_frames: list[FrameAnnotations] | None = None,
                 trained_on: str = "", init: Path | None = None, progress: bool = True) -> None:
        self.config = config
        self.out = out
        self.progress = progress
        self.device = resolve_device(config.device)
        seed_everything(config.seed)
        self.model: FishLocNet = build_model(model_config)
        if init is not None:
            source = load_checkpoint(init)
            self.model.load_state_dict(source.build(init).state_dict())
        self.model.to(self.device)
        self.train_set = DetectionDataset(train_frames, model_config.input_size, config.augment, config.seed)
        self.val_frames = (val_frames or [])[:config.val_limit]
        self.loss = DetectionLoss(config.loss)
        self.optimizer = torch.optim.AdamW(self.model.parameters(), lr=config.lr,
                                           weight_decay=config.weight_decay)
        self.steps_per_epoch = max(1, math.ceil(len(train_frames) / config.batch_size))
        total = self.steps_per_epoch * config.epochs
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer,
            lambda step: warmup_cosine(step, total, config.warmup_steps, config.final_lr_fraction))
        self.angle_generator = torch.Generator().manual_seed(config.seed + 1)
        self.epoch = 0  # epochs completed
        self.best_score = -math.inf
        self.info = ModelInfo(model_version=f"{out.name}-e0", trained_on=trained_on or "unspecified",
                              default_min_score=0.3)

    # ----- checkpoints

    def _checkpoint(self) -> Checkpoint:
        state = {
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "epoch": self.epoch,
            "best_score": self.best_score,
            "rng": rng_state({"angles": self.angle_generator}),
            "train_config": asdict(self.config),
        }
        model_state = {k: v.detach().cpu() for k, v in self.model.state_dict().items()}
        return Checkpoint(self.model.config, model_state, ModelInfo(**vars(self.info)), state)

    def resume(self, path: Path) -> None:
        """Continue from a checkpoint written by this trainer (model, optimizer, schedule, RNG)."""
        checkpoint = load_checkpoint(path)
        state = checkpoint.training_state
        if "optimizer" not in state:
            raise ValueError(f"{path} holds no training state to resume from; use --init to fine-tune")
        self.model.load_state_dict(checkpoint.build(path).state_dict())
        self.model.to(self.device)
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        self.epoch = int(state["epoch"])
        self.best_score = float(state["best_score"])
        self.info = checkpoint.info
        restore_rng(state["rng"], {"angles": self.angle_generator})

    # ----- loop

    def _train_epoch(self) -> dict[str, float]:
        self.model.train()
        self.train_set.set_epoch(self.epoch)
        epoch_generator = torch.Generator().manual_seed(self.config.seed * 100003 + self.epoch)
        order = torch.randperm(len(self.train_set), generator=epoch_generator)
        sums: dict[str, float] = {}
        batches = [order[i:i + self.config.batch_size].tolist()
                   for i in range(0, len(order), self.config.batch_size)]
        bar = tqdm(batches, desc=f"epoch {self.epoch + 1}/{self.config.epochs}", unit="batch",
                   disable=not self.progress, leave=False)
        for indices in bar:
            batch = collate([self.train_set[i] for i in indices])
            images = self.model.normalise(batch.images.to(self.device))
            terms = self.loss(self.model, images, batch.boxes, self.angle_generator)
            self.optimizer.zero_grad(set_to_none=True)
            terms["total"].backward()
            torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.config.grad_clip)
            self.optimizer.step()
            self.scheduler.step()
            for key, value in terms.items():
                sums[key] = sums.get(key, 0.0) + float(value.detach())
            bar.set_postfix(loss=f"{float(terms['total'].detach()):.3f}")
        return {k: v / len(batches) for k, v in sums.items()}

    def _validate(self) -> dict[str, Any]:
        if not self.val_frames:
            return {}
        self.model.eval()
        model = TorchContract(ContractModel(self.model), centernet_info(self.model.config, self.info))
        _, evaluation, _ = choose_operating_point(model, self.val_frames)
        self.model.train()
        return {k: v for k, v in evaluation.metrics.items() if isinstance(v, float)}

    def fit(self) -> list[dict[str, Any]]:
        """Train until `config.epochs` epochs are complete; returns this run's log records."""
        self.out.mkdir(parents=True, exist_ok=True)
        records = []
        while self.epoch < self.config.epochs:
            started = time.time()
            train_terms = self._train_epoch()
            val = self._validate()
            self.epoch += 1
            self.info.model_version = f"{self.out.name}-e{self.epoch}"
            if "min_score" in val:
                self.info.default_min_score = round(float(val["min_score"]), 3)
                self.info.nms_iou = float(val["nms_iou"])
            score = val.get("mAP", -train_terms["total"])
            score = -math.inf if not math.isfinite(score) else score
            record = {"epoch": self.epoch, "train": train_terms, "val": val,
                      "lr": self.scheduler.get_last_lr()[0], "seconds": round(time.time() - started, 1)}
            records.append(record)
            checkpoint = self._checkpoint()
            if score > self.best_score:
                self.best_score = score
                checkpoint.training_state["best_score"] = score
                save_checkpoint(self.out / BEST, checkpoint)
            save_checkpoint(self.out / LAST, checkpoint)
            with open(self.out / LOG_FILE, "a", encoding="utf-8") as log:
                log.write(json.dumps(json_safe(record), default=float) + "\n")
            self._plot()
            if self.progress:
                summary = {k: round(v, 4) for k, v in {**train_terms, **val}.items()
                           if k in ("total", "equivariance", "AP50", "mAP", "mPE", "recall")}
                print(f"epoch {self.epoch}: {json.dumps(summary)} ({record['seconds']} s)", flush=True)
        return records

    def _plot(self) -> None:
        lines = (self.out / LOG_FILE).read_text(encoding="utf-8").splitlines()
        plot_training([json.loads(line) for line in lines if line.strip()], self.out / "training.png")
