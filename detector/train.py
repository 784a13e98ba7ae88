"""`fishloc train`: train the detector on an annotation file (FishLoc/LOAF or CEPDOF format).

    fishloc train --data train/annotations.json --val val/annotations.json --out runs/NAME
    fishloc train ... --out runs/NAME --resume          # continue exactly where it stopped
    fishloc train --data mine.json --out runs/ft --init models/default.pt   # fine-tune
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, replace
from pathlib import Path

import torch

from detector.checkpoint import CheckpointError, load_checkpoint
from detector.data.dataset import AugmentConfig
from detector.data.readers import DatasetFormatError, read_dataset
from detector.losses import LossConfig
from detector.model import DetectorConfig, tiny_config
from detector.trainer import LAST, TrainConfig, Trainer

MODEL_SIZES = {"default": DetectorConfig, "tiny": tiny_config}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", required=True, nargs="+",
                        help="training annotations.json (several files are concatenated)")
    parser.add_argument("--val", default=None, help="validation annotations.json (metrics each epoch)")
    parser.add_argument("--out", required=True, help="run folder: checkpoints, log.jsonl, training.png")
    parser.add_argument("--init", default=None, help="start from this checkpoint's weights (fine-tune)")
    parser.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--lr", type=float, default=2e-3)
    parser.add_argument("--input-size", type=int, default=None, help="model input side (multiple of 32)")
    parser.add_argument("--model-size", choices=sorted(MODEL_SIZES), default="default")
    parser.add_argument("--equivariance", action=argparse.BooleanOptionalAction, default=True,
                        help="LOAF's rotation-equivariant loss term (λ = 0.5)")
    parser.add_argument("--rotation-aug", action="store_true", help="rotate input frames at random")
    parser.add_argument("--no-flip", action="store_true", help="no left-right flips")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--val-limit", type=int, default=200, help="validate on the first N frames")
    parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda, ...")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch intra-op threads (on a busy CPU, 1 is often fastest)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    try:
        train_frames = [frame for path in args.data for frame in read_dataset(path)]
        val_frames = read_dataset(args.val) if args.val else None
        model_config = load_checkpoint(args.init).config if args.init else MODEL_SIZES[args.model_size]()
        if args.input_size is not None:
            model_config = replace(model_config, input_size=args.input_size)
        if not isinstance(model_config, DetectorConfig):
            raise ValueError(f"{args.init} is a {model_config.arch} checkpoint; train it with --init-from")
    except (DatasetFormatError, CheckpointError, ValueError) as error:
        print(f"fishloc train: {error}", file=sys.stderr)
        return 2
    config = TrainConfig(
        epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, seed=args.seed,
        augment=AugmentConfig(rotation=args.rotation_aug, flip=not args.no_flip),
        loss=LossConfig(equivariance=args.equivariance), val_limit=args.val_limit, device=args.device,
    )
    names = ", ".join(Path(path).parent.name or str(path) for path in args.data)
    trained_on = f"{names} ({len(train_frames)} frames)"
    trainer = Trainer(model_config, config, out, train_frames, val_frames, trained_on,
                      init=Path(args.init) if args.init else None, progress=not args.quiet)
    if args.resume:
        if not (out / LAST).exists():
            print(f"fishloc train: nothing to resume, {out / LAST} does not exist", file=sys.stderr)
            return 2
        trainer.resume(out / LAST)
    else:
        out.mkdir(parents=True, exist_ok=True)
        (out / "log.jsonl").unlink(missing_ok=True)  # a fresh run starts a fresh log
        (out / "config.json").write_text(json.dumps(
            {"model": model_config.to_dict(), "train": asdict(config), "data": args.data, "val": args.val},
            indent=2, default=str) + "\n", encoding="utf-8")
    trainer.fit()
    return 0
