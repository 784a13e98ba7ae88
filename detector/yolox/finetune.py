"""Fine-tuning of a YOLOX person detector on renders, without forgetting COCO: the polar view
(design (a), `PolarStripDataset`) or the letterboxed fisheye frame (design (b),
`FisheyeFrameDataset`), chosen by the network config's arch (`training_set`).

The student starts as the COCO person network (`init_from_pretrained`); a frozen copy of it, the
teacher, scores every strip too, and the loss's `distill` term keeps the student's scores where no
label says otherwise (`detector.yolox.loss`); with `feature_distill` the backbone's and the neck's
pyramids are held to the teacher's too, on every level and cell (`feature_distillation`), so that a
run training the backbone keeps what the teacher sees. A run that goes on from a fine-tuned checkpoint may
name another teacher (`teacher`: e.g. the COCO network itself, so that what the checkpoint's head
already traded away is held to COCO and not to the checkpoint). The first backbone stages stay
frozen (`freeze`; `foot` freezes the foot branch, so a head trained on its own leaves the feet as
they were; the head's parts can be frozen one by one, `head.reg_preds` ... of HEAD_PARTS: with all
but `head.reg_preds` frozen a run refits the boxes alone and every score stays as it was, since
YOLOX reads objectness and class from features that `reg_preds` does not feed).

Checkpoints go to `OUT/last.pt` every `checkpoint_every_s` seconds and at each epoch's end, with
weights, teacher, optimizer, schedule, RNG states, the epoch and the batch within it; the epoch's
order comes from (seed, epoch) and augmentation from (seed, epoch, index), so `resume` continues the
run exactly. Validation runs each epoch through the ONNX contract's module and the service's pre-
and post-processing; `OUT/best.pt` keeps the best validation mAP (renders only).
"""

from __future__ import annotations

import copy
import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Protocol

import torch
from torch import Tensor, nn

from detector.checkpoint import (
    Checkpoint,
    CheckpointError,
    ModelInfo,
    build_network,
    load_checkpoint,
    save_checkpoint,
)
from detector.data.readers import FrameAnnotations
from detector.evaluate import TorchContract, choose_operating_point, json_safe
from detector.graph import contract_info, contract_module
from detector.nanodet.loss import NanoDetDetectionLoss, NanoDetLossConfig
from detector.nanodet.network import NanoDetPlus
from detector.schedule import restore_rng, rng_state, seed_everything, warmup_cosine
from detector.trainer import resolve_device
from detector.yolox.fisheye import ARCH as FISHEYE_ARCH
from detector.yolox.fisheye import FisheyeDetectorConfig
from detector.yolox.foot import MAX_METRES_PER_PX
from detector.yolox.frames import FisheyeFrameDataset, FrameAugment
from detector.yolox.loss import PolarDetectionLoss, PolarLossConfig, feature_distillation
from detector.yolox.network import YoloxNano
from detector.yolox.polar import ARCH as POLAR_ARCH
from detector.yolox.polar import PolarDetectorConfig
from detector.yolox.strips import (
    PolarStripDataset,
    StripAugment,
    YoloxSample,
    collate_feet,
    collate_strips,
)

LOG_FILE = "log.jsonl"
LAST = "last.pt"
BEST = "best.pt"
TRAINER_KINDS = {POLAR_ARCH: "polar-finetune", FISHEYE_ARCH: "fisheye-finetune"}
VIEWS = {POLAR_ARCH: "polar", FISHEYE_ARCH: "fisheye"}  # `fishloc train --view`
# the head's parts (`detector.yolox.head`): its stems, then the class and the box branch, whose
# features feed both the boxes (reg_preds) and the objectness (obj_preds)
HEAD_PARTS = ("head.stems", "head.cls_convs", "head.cls_preds", "head.reg_convs", "head.reg_preds",
              "head.obj_preds")
STAGES = ("stem", "dark2", "dark3", "dark4", "dark5", "neck", "head", *HEAD_PARTS, "inner_head", "foot")
OPTIONAL_STAGES = ("inner_head", "foot")  # frozen where the network has them, ignored where not
NANODET_STAGES = ("backbone", "neck", "head")  # what --freeze names of a NanoDet-Plus


@dataclass(frozen=True)
class FinetuneConfig:
    epochs: int = 20
    batch_size: int = 8
    lr: float = 5e-4
    weight_decay: float = 0.05  # on convolution weights only, not on biases (BatchNorm folded in)
    warmup_steps: int = 100
    final_lr_fraction: float = 0.05
    grad_clip: float = 10.0
    freeze: tuple[str, ...] = ("stem", "dark2", "dark3")  # of STAGES
    distill: float = 1.0  # λ
    # λ of the backbone's and the neck's features held to the teacher's on every level and cell (0:
    # off); a run that trains the backbone keeps what the teacher sees, the head free to read it anew
    feature_distill: float = 0.0
    iou_weight: float = 5.0
    foot_max_metres_per_px: float = MAX_METRES_PER_PX  # cap of a person's foot-loss weight
    foot_coarse_weight: float = 1.0  # the coarse foot point's weight against each refiner pass
    augment: StripAugment | FrameAugment = field(default_factory=StripAugment)  # of the view trained
    checkpoint_every_s: float = 180.0
    seed: int = 0
    val_limit: int = 200
    device: str = "auto"

    def __post_init__(self) -> None:
        unknown = set(self.freeze) - set(STAGES) - set(NANODET_STAGES)
        if unknown:
            raise ValueError(f"freeze: unknown stages {sorted(unknown)}; choose from "
                             f"{', '.join(STAGES)} (YOLOX) or {', '.join(NANODET_STAGES)} (NanoDet)")
        if not self.foot_max_metres_per_px > 0:  # NaN too
            cap = self.foot_max_metres_per_px
            raise ValueError(f"the foot loss's metres cap must be positive, got {cap}")
        if not self.foot_coarse_weight >= 0:  # NaN too
            weight = self.foot_coarse_weight
            raise ValueError(f"the coarse foot point's weight must be 0 or more, got {weight}")
        if not self.feature_distill >= 0:  # NaN too
            raise ValueError(f"the feature distillation's λ must be 0 or more, got {self.feature_distill}")


YoloxDetectorConfig = PolarDetectorConfig | FisheyeDetectorConfig


class TrainingSet(Protocol):
    """What the loop reads of a view's dataset (PolarStripDataset, FisheyeFrameDataset)."""

    def set_epoch(self, epoch: int) -> None: ...

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> YoloxSample: ...

    def left_out(self) -> dict[str, int]: ...


def training_set(model_config: YoloxDetectorConfig, frames: list[FrameAnnotations],
                 augment: StripAugment | FrameAugment, seed: int) -> TrainingSet:
    """The dataset of `model_config`'s view; ValueError for the other view's augmentation."""
    if isinstance(model_config, FisheyeDetectorConfig):
        if not isinstance(augment, FrameAugment):
            raise ValueError(f"the fisheye view is augmented by a FrameAugment, not {type(augment).__name__}")
        return FisheyeFrameDataset(frames, model_config, augment, seed)
    if not isinstance(augment, StripAugment):
        raise ValueError(f"the polar view is augmented by a StripAugment, not {type(augment).__name__}")
    return PolarStripDataset(frames, model_config, augment, seed)


def stage_parameters(model: YoloxNano | NanoDetPlus, stage: str) -> list[nn.Parameter]:
    """The parameters of one of `model`'s stages (STAGES of YOLOX, NANODET_STAGES of NanoDet);
    none for an optional stage (OPTIONAL_STAGES) it lacks; ValueError for any other stage the
    network does not have."""
    if stage in OPTIONAL_STAGES and getattr(model, stage, None) is None:
        return []
    stages = NANODET_STAGES if isinstance(model, NanoDetPlus) else STAGES
    if stage not in stages:
        raise ValueError(f"freeze: {type(model).__name__} has no stage {stage!r}; "
                         f"choose from {', '.join(stages)}")
    owner: nn.Module = model.backbone if stage.startswith(("stem", "dark")) else model
    module = owner.get_submodule(stage)
    return list(module.parameters())


class PyramidTap:
    """The last feature pyramids of a network, kept by forward hooks for `feature_distillation`:
    the backbone's three levels (which a foot branch's own neck reads) and the neck's three (which
    the head reads)."""

    def __init__(self, network: YoloxNano | NanoDetPlus) -> None:
        self.levels: dict[str, list[Tensor]] = {}
        for part in ("backbone", "neck"):
            network.get_submodule(part).register_forward_hook(self._keeper(part))

    def _keeper(self, part: str) -> Any:
        def keep(module: nn.Module, inputs: Any, output: Sequence[Tensor]) -> None:
            self.levels[part] = list(output)
        return keep

    @property
    def features(self) -> list[Tensor]:
        return [level for part in ("backbone", "neck") for level in self.levels[part]]


class Finetuner:
    """Fine-tunes `initial` (a person-only YoloxNano of `model_config`, either view, or a polar
    NanoDetPlus) into `out/`."""

    def __init__(self, model_config: YoloxDetectorConfig, config: FinetuneConfig, out: Path,
                 initial: YoloxNano | NanoDetPlus, train_frames: list[FrameAnnotations],
                 val_frames: list[FrameAnnotations] | None = None, trained_on: str = "",
                 progress: bool = True, teacher: YoloxNano | NanoDetPlus | None = None) -> None:
        self.model_config = model_config
        self.config = config
        self.out = out
        self.progress = progress
        self.device = resolve_device(config.device)
        seed_everything(config.seed)
        model = build_network(model_config)  # a YoloxNano (inner head where asked) or a NanoDetPlus
        if not isinstance(model, YoloxNano | NanoDetPlus):
            raise TypeError(f"{model_config.arch} builds a {type(model).__name__}, not a YOLOX network")
        self.model = model
        self.model.load_state_dict(initial.state_dict(), strict=True)
        self.model.to(self.device)
        start = self.model if teacher is None else teacher
        self.teacher = copy.deepcopy(start).to(self.device).eval().requires_grad_(False)
        self.taps = (PyramidTap(self.model), PyramidTap(self.teacher)) if config.feature_distill > 0 else None
        frozen = {id(p) for stage in config.freeze for p in stage_parameters(self.model, stage)}
        for parameter in self.model.parameters():
            parameter.requires_grad_(id(parameter) not in frozen)
        trainable = [p for p in self.model.parameters() if p.requires_grad]
        self.optimizer = torch.optim.AdamW(
            [{"params": [p for p in trainable if p.ndim > 1], "weight_decay": config.weight_decay},
             {"params": [p for p in trainable if p.ndim <= 1], "weight_decay": 0.0}], lr=config.lr)
        self.train_set = training_set(model_config, train_frames, config.augment, config.seed)
        self.kind = TRAINER_KINDS[model_config.arch]
        self.val_frames = (val_frames or [])[:config.val_limit]
        self.loss: PolarDetectionLoss | NanoDetDetectionLoss = (
            NanoDetDetectionLoss(NanoDetLossConfig(distill_weight=config.distill))
            if isinstance(self.model, NanoDetPlus) else
            PolarDetectionLoss(PolarLossConfig(iou_weight=config.iou_weight, distill_weight=config.distill,
                                               foot_max_metres_per_px=config.foot_max_metres_per_px,
                                               foot_coarse_weight=config.foot_coarse_weight)))
        self.steps_per_epoch = max(1, math.ceil(len(train_frames) / config.batch_size))
        total = self.steps_per_epoch * config.epochs
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(
            self.optimizer,
            lambda step: warmup_cosine(step, total, config.warmup_steps, config.final_lr_fraction))
        self.epoch = 0  # epochs completed
        self.batch = 0  # batches of the current epoch completed
        self.step = 0
        self.best_score = -math.inf
        self.epoch_sums: dict[str, float] = {}
        self.info = ModelInfo(model_version=f"{out.name}-e0", trained_on=trained_on or "unspecified",
                              default_min_score=0.3)
        self._saved_at = time.monotonic()

    # ----- checkpoints

    def checkpoint(self) -> Checkpoint:
        state = {
            "kind": self.kind,
            "optimizer": self.optimizer.state_dict(),
            "scheduler": self.scheduler.state_dict(),
            "teacher": {k: v.detach().cpu() for k, v in self.teacher.state_dict().items()},
            "epoch": self.epoch, "batch": self.batch, "step": self.step,
            "epoch_sums": dict(self.epoch_sums),
            "best_score": self.best_score,
            "rng": rng_state(),
            "finetune_config": json_safe(asdict(self.config)),
        }
        weights = {k: v.detach().cpu().clone() for k, v in self.model.state_dict().items()}
        return Checkpoint(self.model_config, weights, ModelInfo(**vars(self.info)), state)

    def save_last(self) -> None:
        save_checkpoint(self.out / LAST, self.checkpoint())
        self._saved_at = time.monotonic()

    def resume(self, path: Path) -> None:
        """Continue a run of this configuration from its checkpoint; CheckpointError naming the
        file for a checkpoint of another network, strip or trainer (nothing is written)."""
        checkpoint = load_checkpoint(path)
        state = checkpoint.training_state
        mine = self.model_config
        if not isinstance(checkpoint.config, PolarDetectorConfig | FisheyeDetectorConfig):
            raise CheckpointError(f"{path} is a CenterNet (fisheye view) checkpoint, not the {mine.arch} "
                                  "this run trains; resume it without --init-from")
        if checkpoint.config.arch != mine.arch:
            theirs = checkpoint.config.arch
            raise CheckpointError(f"{path} is a {theirs} checkpoint (--view {VIEWS[theirs]}), not the "
                                  f"{mine.arch} this run trains; resume it with --view {VIEWS[theirs]}")
        if checkpoint.config != mine:
            flag = "--strip" if isinstance(mine, PolarDetectorConfig) else "--input-size"
            raise CheckpointError(f"{path} was trained with {checkpoint.config.to_dict()}, this run asks "
                                  f"for {mine.to_dict()}; resume with the same {flag}")
        if state.get("kind") != self.kind:
            raise CheckpointError(f"{path} holds no fine-tuning state to resume from")
        teacher = state["teacher"]
        if set(teacher) != set(self.teacher.state_dict()):
            raise CheckpointError(f"{path} was distilled from another teacher network than this run's; "
                                  "resume it with the same --teacher")
        self.model.load_state_dict(checkpoint.build(path).state_dict())
        self.teacher.load_state_dict(teacher)
        self.optimizer.load_state_dict(state["optimizer"])
        self.scheduler.load_state_dict(state["scheduler"])
        self.epoch, self.batch, self.step = int(state["epoch"]), int(state["batch"]), int(state["step"])
        self.epoch_sums = dict(state["epoch_sums"])
        self.best_score = float(state["best_score"])
        self.info = checkpoint.info
        restore_rng(state["rng"])

    # ----- loop

    def batches(self, epoch: int) -> list[list[int]]:
        """The batches of `epoch`: a permutation derived from (seed, epoch)."""
        generator = torch.Generator().manual_seed(self.config.seed * 100003 + epoch)
        order = torch.randperm(len(self.train_set), generator=generator).tolist()
        size = self.config.batch_size
        return [order[i:i + size] for i in range(0, len(order), size)]

    def train_step(self, indices: list[int]) -> dict[str, float]:
        samples = [self.train_set[i] for i in indices]
        images, labels = collate_strips(samples)
        images = images.to(self.device)
        teacher_maps = None
        if self.config.distill > 0 or self.taps is not None:
            with torch.no_grad():
                teacher_maps = self.teacher(images)
            if self.config.distill <= 0:
                teacher_maps = None  # the teacher ran for its features alone
        model, loss = self.model, self.loss
        if isinstance(model, YoloxNano) and model.foot is not None and isinstance(loss, PolarDetectionLoss):
            feet = collate_feet(samples)
            maps, offsets, fine = model.forward_with_foot(images)
            foot = model.foot
            refine = (fine, foot) if foot.refiner is not None else None
            terms = loss(maps, labels, teacher_maps, offsets, feet, refine)
        else:
            terms = loss(model(images), labels, teacher_maps)
        if self.taps is not None:
            student, teacher = self.taps
            terms["features"] = feature_distillation(student.features, teacher.features)
            terms["total"] = terms["total"] + self.config.feature_distill * terms["features"]
        self.optimizer.zero_grad(set_to_none=True)
        if terms["total"].requires_grad:  # not when only the foot trains and no label has a floor point
            terms["total"].backward()
            torch.nn.utils.clip_grad_norm_([p for p in self.model.parameters() if p.requires_grad],
                                           self.config.grad_clip)
            self.optimizer.step()
        self.scheduler.step()
        self.step += 1
        return {k: v.item() for k, v in terms.items()}

    def validate(self) -> dict[str, Any]:
        if not self.val_frames:
            return {}
        checkpoint = self.checkpoint()
        model = TorchContract(contract_module(checkpoint).to(self.device), contract_info(checkpoint))
        _, evaluation, _ = choose_operating_point(model, self.val_frames)
        return {k: v for k, v in evaluation.metrics.items() if isinstance(v, float)}

    def fit(self, stop_after_steps: int | None = None) -> list[dict[str, Any]]:
        """Train until `config.epochs` are complete (or `stop_after_steps` optimizer steps in all,
        leaving `last.pt` to resume from); returns this call's log records. With 0 epochs it writes
        the unchanged initial network (the zero-shot model)."""
        self.out.mkdir(parents=True, exist_ok=True)
        if self.config.epochs == 0:
            self.save_last()
            return []
        records: list[dict[str, Any]] = []
        self.model.train()
        while self.epoch < self.config.epochs:
            self.train_set.set_epoch(self.epoch)
            started = time.time()
            batches = self.batches(self.epoch)
            while self.batch < len(batches):
                if stop_after_steps is not None and self.step >= stop_after_steps:
                    self.save_last()
                    return records
                terms = self.train_step(batches[self.batch])
                self.batch += 1
                for key, value in terms.items():
                    self.epoch_sums[key] = self.epoch_sums.get(key, 0.0) + value
                if self.progress and self.step % 10 == 0:
                    print(f"epoch {self.epoch + 1} batch {self.batch}/{len(batches)}: "
                          f"{json.dumps({k: round(v, 4) for k, v in terms.items()})}", flush=True)
                if time.monotonic() - self._saved_at >= self.config.checkpoint_every_s:
                    self.save_last()
            records.append(self._end_epoch(len(batches), time.time() - started))
        return records

    def _end_epoch(self, batch_count: int, seconds: float) -> dict[str, Any]:
        train_terms = {k: v / batch_count for k, v in self.epoch_sums.items()}
        val = self.validate()
        self.epoch += 1
        self.batch = 0
        self.epoch_sums = {}
        self.info.model_version = f"{self.out.name}-e{self.epoch}"
        if "min_score" in val:
            self.info.default_min_score = round(float(val["min_score"]), 3)
            self.info.nms_iou = float(val["nms_iou"])
        record = {"epoch": self.epoch, "step": self.step, "train": train_terms, "val": val,
                  "lr": self.scheduler.get_last_lr()[0], "seconds": round(seconds, 1),
                  **self.train_set.left_out()}
        score = val.get("mAP", math.nan)
        if math.isfinite(score) and score > self.best_score:
            self.best_score = score
            save_checkpoint(self.out / BEST, self.checkpoint())
        self.save_last()
        with open(self.out / LOG_FILE, "a", encoding="utf-8") as log:
            log.write(json.dumps(json_safe(record), default=float) + "\n")
        if self.progress:
            summary = {k: round(v, 4) for k, v in {**train_terms, **val}.items()
                       if k in ("total", "distill", "features", "AP50", "mAP", "AP_near", "AP_mid", "AP_far",
                                "recall")}
            print(f"epoch {self.epoch}: {json.dumps(summary)} ({record['seconds']} s)", flush=True)
        return record
