"""`fishloc train`: train the detector on an annotation file (FishLoc/LOAF or CEPDOF format).

    fishloc train --data train/annotations.json --val val/annotations.json --out runs/NAME
    fishloc train ... --out runs/NAME --resume          # continue exactly where it stopped
    fishloc train --data mine.json --out runs/ft --init models/default.pt   # fine-tune
    fishloc train --init-from models/pretrained/yolox_nano.onnx --data A.json --val V.json \
        --out runs/polar [--strip 416 1664 128] [--distill 1.0] [--resume]   # the polar YOLOX
    fishloc train --init-from models/pretrained/yolox_nano.onnx --view fisheye --data A.json \
        --val V.json --out runs/fisheye [--input-size 640] [--no-rotation-aug]  # YOLOX on the frame
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
from detector.nanodet.network import NanoDetPlus
from detector.trainer import LAST, TrainConfig, Trainer
from detector.yolox.finetune import NANODET_STAGES, STAGES, FinetuneConfig, Finetuner, YoloxDetectorConfig
from detector.yolox.fisheye import FisheyeDetectorConfig
from detector.yolox.frames import FrameAugment
from detector.yolox.network import YoloxNano
from detector.yolox.polar import (
    NETWORKS,
    YOLOX_NANO,
    PolarDetectorConfig,
    init_from_pretrained,
    init_network_from_pretrained,
)
from detector.yolox.strips import StripAugment

MODEL_SIZES = {"default": DetectorConfig, "tiny": tiny_config}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", required=True, nargs="+",
                        help="training annotations.json (several files are concatenated)")
    parser.add_argument("--val", default=None, help="validation annotations.json (metrics each epoch)")
    parser.add_argument("--out", required=True, help="run folder: checkpoints, log.jsonl, training.png")
    parser.add_argument("--init", default=None, help="start from this checkpoint's weights (fine-tune)")
    parser.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    parser.add_argument("--epochs", type=int, default=None, help="default 30 (polar: 20)")
    parser.add_argument("--batch-size", type=int, default=None, help="default 16 (polar: 8)")
    parser.add_argument("--lr", type=float, default=None, help="default 2e-3 (polar: 5e-4)")
    parser.add_argument("--input-size", type=int, default=None, help="model input side (multiple of 32)")
    parser.add_argument("--model-size", choices=sorted(MODEL_SIZES), default="default")
    parser.add_argument("--equivariance", action=argparse.BooleanOptionalAction, default=True,
                        help="LOAF's rotation-equivariant loss term (λ = 0.5)")
    parser.add_argument("--rotation-aug", action=argparse.BooleanOptionalAction, default=None,
                        help="rotate input frames at random (default: off for the CenterNet, on for "
                             "--view fisheye)")
    parser.add_argument("--no-flip", action="store_true", help="no left-right flips")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--val-limit", type=int, default=200, help="validate on the first N frames")
    parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu, cuda, ...")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch intra-op threads (on a busy CPU, 1 is often fastest)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    polar = parser.add_argument_group("YOLOX, polar or fisheye view (fine-tuned from COCO YOLOX-Nano)")
    polar.add_argument("--init-from", default=None, metavar="PATH.onnx|PATH.pt",
                       help="YOLOX-Nano's COCO ONNX: fine-tune a person detector from it; or a polar "
                            "YOLOX checkpoint (e.g. models/fishloc-default.pt): go on from its network "
                            "and strip")
    polar.add_argument("--foot", action="store_true",
                       help="add the foot output (each box's floor-contact point, learnt from the "
                            "renders' location_m); train it alone with --freeze stem dark2 dark3 dark4 "
                            "dark5 neck head --distill 0")
    polar.add_argument("--foot-refine", action="store_true",
                       help="add the foot output's second stage (stride-8 features read about each "
                            "coarse foot point; detector.yolox.foot.FootRefiner); implies --foot")
    polar.add_argument("--foot-neck", action="store_true",
                       help="give the foot output its own copy of the neck, started from the "
                            "detector's and trained on the foot loss alone (detector.yolox.foot.FootNeck); "
                            "implies --foot")
    polar.add_argument("--foot-neck-top-down", action="store_true",
                       help="keep the top-down path of the foot's own neck alone (neck.TopDownFPN: the "
                            "foot branch at a fraction of its cost); implies --foot-neck")
    polar.add_argument("--foot-refine-steps", type=int, default=None, metavar="N",
                       help="passes of the foot refiner (default: the checkpoint's, else 1)")
    polar.add_argument("--view", choices=("polar", "fisheye"), default=None,
                       help="what the YOLOX reads: the polar unwrap (default) or the letterboxed frame "
                            "with a radius-aligned head (--input-size, default 640)")
    polar.add_argument("--strip", type=int, nargs=3, default=None, metavar=("HEIGHT", "WIDTH", "OVERLAP"),
                       help="strip rows, columns per turn and overlap columns (default 416 1664 128)")
    polar.add_argument("--network", choices=NETWORKS, default=YOLOX_NANO,
                       help="the network of the polar view, started from its COCO ONNX (default yolox-nano; "
                            "nanodet-plus-m: ../shared/pretrained/nanodet-plus-m_416.onnx, no foot)")
    polar.add_argument("--freeze", nargs="*", default=None, choices=(*STAGES, *NANODET_STAGES[:1]),
                       help="network stages kept frozen (default: stem dark2 dark3, NanoDet's backbone; "
                            "none: no stage); head.stems ... head.obj_preds freeze the head's parts")
    polar.add_argument("--inner-head", type=float, default=0.0, metavar="FRACTION",
                       help="design (c): a second head for the disc within FRACTION of the strip's "
                            "radius (e.g. 0.3); train it alone with --freeze stem dark2 dark3 dark4 dark5 "
                            "neck head")
    polar.add_argument("--zoom", type=float, nargs="+", default=[1.0], metavar="SCALE",
                       help="strip radii (multiples of the served one) drawn per sample, e.g. 0.8 1 1.25 "
                            "(each scale caches its own strips: memory grows with the count)")
    polar.add_argument("--band-scale", type=float, nargs="+", default=[1.0], metavar="SCALE",
                       help="strips at these multiples of the served rows and columns per turn (a planned "
                            "view's bands, e.g. 1 1.5), one drawn per sample, in windows of the served rows")
    polar.add_argument("--unwrap-samples", type=int, default=1, metavar="N",
                       help="each strip px the mean of N x N samples of the frame, as a view of "
                            "ViewPlanConfig.unwrap_samples N serves it (default 1: one bilinear sample)")
    polar.add_argument("--nadir-view", type=float, default=0.0, metavar="P",
                       help="the probability that a sample is the frame's nadir view (the upright crop "
                            "below the lens the default view runs beside the strip) rather than a strip "
                            "(default 0: strips alone)")
    polar.add_argument("--rand-conv", type=float, default=0.0, metavar="P",
                       help="the probability that a sample's colours and textures are redrawn by a random "
                            "convolution, its shapes kept (RandConv; default 0: never): people found by "
                            "their shape rather than by the renders' surfaces")
    polar.add_argument("--crop", type=int, default=0, metavar="COLUMNS",
                       help="train on strip windows of this many columns (a multiple of 32) around "
                            "the people, a fraction of the strip's cost per sample (default: whole strips)")
    polar.add_argument("--foot-metres-cap", type=float, default=None, metavar="M_PER_PX",
                       help="where a person's weight in the foot loss stops, in metres per strip px "
                            "(default 0.1: detector.yolox.foot.MAX_METRES_PER_PX); higher weighs the far "
                            "people, whose px span more floor, nearer their share of the floor error")
    polar.add_argument("--foot-coarse-weight", type=float, default=None, metavar="W",
                       help="the coarse foot point's weight in the foot loss against each pass of the "
                            "refiner, whose point the graph serves (default 1: their plain mean)")
    polar.add_argument("--distill", type=float, default=None, help="λ of the COCO distillation (default 1.0)")
    polar.add_argument("--distill-features", type=float, default=0.0, metavar="λ",
                       help="hold the backbone's and the neck's features on every level to the "
                            "teacher's (0: off); for runs that train the backbone")
    polar.add_argument("--teacher", default=None, metavar="PATH.onnx|PATH.pt",
                       help="distil from this network (a COCO ONNX or a polar checkpoint of the same "
                            "network) instead of the one --init-from starts from, e.g. the COCO "
                            "YOLOX-Nano for a head that goes on from a fine-tuned checkpoint")
    polar.add_argument("--checkpoint-every", type=float, default=None,
                       help="seconds between checkpoints to OUT/last.pt (default 180)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    if args.init_from is not None:
        return run_polar(args)
    if args.view is not None:
        print("fishloc train: --view needs --init-from (the COCO YOLOX-Nano to fine-tune)", file=sys.stderr)
        return 2
    args.epochs = 30 if args.epochs is None else args.epochs
    args.batch_size = 16 if args.batch_size is None else args.batch_size
    args.lr = 2e-3 if args.lr is None else args.lr
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
        augment=AugmentConfig(rotation=bool(args.rotation_aug), flip=not args.no_flip),
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


def yolox_view(args: argparse.Namespace) -> tuple[YoloxDetectorConfig, StripAugment | FrameAugment]:
    """The network config and augmentation of `--view`; ValueError for flags of the other view."""
    if args.view == "fisheye":
        if (args.strip is not None or args.zoom != [1.0] or args.band_scale != [1.0] or args.inner_head
                or args.unwrap_samples != 1 or args.nadir_view or args.rand_conv):
            raise ValueError("--strip, --zoom, --band-scale, --unwrap-samples, --nadir-view, --rand-conv and "
                             "--inner-head are options of the polar view, not of --view fisheye")
        size = {} if args.input_size is None else {"input_size": args.input_size}
        rotation = True if args.rotation_aug is None else args.rotation_aug
        flip = 0.0 if args.no_flip else FrameAugment().flip
        return FisheyeDetectorConfig(**size), FrameAugment(rotation=rotation, flip=flip)
    strip = {} if args.strip is None else dict(zip(("input_size", "polar_width", "polar_overlap"),
                                                   args.strip, strict=True))
    if args.network != YOLOX_NANO:
        if args.view == "fisheye" or args.inner_head or _wants_foot(args):
            raise ValueError(f"--network {args.network} reads the polar view, with no foot or inner head")
        name = f"fishloc-{args.network}-polar"
        return (PolarDetectorConfig(**strip, network=args.network, model_name=name),
                strip_augment(args))
    return (PolarDetectorConfig(**strip, inner_fraction=args.inner_head),
            strip_augment(args))


def strip_augment(args: argparse.Namespace) -> StripAugment:
    """The strips' augmentation the polar view's flags ask for."""
    return StripAugment(radius_scales=tuple(args.zoom), band_scales=tuple(args.band_scale),
                        crop_width=args.crop, unwrap_samples=args.unwrap_samples, nadir_view=args.nadir_view,
                        rand_conv=args.rand_conv)


def default_freeze(network: str) -> tuple[str, ...]:
    """The stages `--freeze` keeps frozen when not given: YOLOX's first three, NanoDet's backbone."""
    return FinetuneConfig().freeze if network == YOLOX_NANO else NANODET_STAGES[:1]


def _wants_foot(args: argparse.Namespace) -> bool:
    """Whether the command line asks for the foot output or a part of it."""
    return bool(args.foot or args.foot_refine or args.foot_neck or args.foot_neck_top_down)


def initial_network(args: argparse.Namespace, model_config: YoloxDetectorConfig
                    ) -> tuple[YoloxDetectorConfig, YoloxNano | NanoDetPlus]:
    """The network `--init-from` starts from and its config: the COCO ONNX's person network in
    `model_config`, or a polar checkpoint's own network and strip; `--foot` adds the foot branch."""
    if Path(args.init_from).suffix.lower() != ".pt":
        if _wants_foot(args):
            if not isinstance(model_config, PolarDetectorConfig):
                raise ValueError("--foot is an option of the polar view")
            model_config = replace(model_config, foot=True, foot_refine=bool(args.foot_refine),
                                   foot_refine_steps=args.foot_refine_steps or 1,
                                   foot_neck=bool(args.foot_neck or args.foot_neck_top_down),
                                   foot_neck_top_down=bool(args.foot_neck_top_down))
        if isinstance(model_config, PolarDetectorConfig) and model_config.network != YOLOX_NANO:
            return model_config, init_network_from_pretrained(args.init_from, model_config)
        return model_config, init_from_pretrained(args.init_from, model_config)
    checkpoint = load_checkpoint(args.init_from)
    if not isinstance(checkpoint.config, PolarDetectorConfig):
        raise ValueError(f"{args.init_from} is no polar YOLOX checkpoint; --init-from takes the COCO "
                         "ONNX or a polar YOLOX checkpoint")
    if args.view == "fisheye" or args.strip is not None or args.inner_head:
        raise ValueError(f"{args.init_from} fixes the view and strip; --view, --strip and --inner-head "
                         "are options of a start from the COCO ONNX")
    network = checkpoint.build(args.init_from)
    if isinstance(network, NanoDetPlus):
        if _wants_foot(args):
            raise ValueError(f"{args.init_from} holds a NanoDet-Plus, which has no foot branch")
        return checkpoint.config, network
    if not isinstance(network, YoloxNano):
        raise ValueError(f"{args.init_from} holds no YOLOX network")
    model_config = checkpoint.config
    if _wants_foot(args) and not model_config.foot:
        model_config, network = replace(model_config, foot=True), network.with_foot()
    if args.foot_refine and not model_config.foot_refine:
        model_config, network = replace(model_config, foot_refine=True), network.with_foot_refiner()
    if args.foot_refine_steps is not None and args.foot_refine_steps != model_config.foot_refine_steps:
        if not model_config.foot_refine:
            raise ValueError("--foot-refine-steps needs a foot refiner (--foot-refine)")
        model_config = replace(model_config, foot_refine_steps=args.foot_refine_steps)
        network = network.with_foot_refine_steps(args.foot_refine_steps)
    if (args.foot_neck or args.foot_neck_top_down) and not model_config.foot_neck:
        model_config, network = replace(model_config, foot_neck=True), network.with_foot_neck()
    if args.foot_neck_top_down and not model_config.foot_neck_top_down:
        model_config = replace(model_config, foot_neck_top_down=True)
        network = network.with_foot_neck_top_down()
    return model_config, network


def teacher_network(path: str, model_config: YoloxDetectorConfig, student: YoloxNano | NanoDetPlus
                    ) -> YoloxNano | NanoDetPlus:
    """`--teacher`: the network of a COCO ONNX (read as `--init-from` reads it, without the foot
    branch or inner head, which the distillation does not read) or of a polar checkpoint. ValueError
    naming the file when it is not the student's network or its maps differ in shape."""
    if Path(path).suffix.lower() != ".pt":
        if not isinstance(model_config, PolarDetectorConfig):
            raise ValueError("--teacher is an option of the polar view")
        plain = replace(model_config, foot=False, foot_refine=False, foot_neck=False,
                        foot_neck_top_down=False, inner_fraction=0.0)
        teacher = init_network_from_pretrained(path, plain)
    else:
        checkpoint = load_checkpoint(path)
        if not isinstance(checkpoint.config, PolarDetectorConfig):
            raise ValueError(f"--teacher {path} is no polar YOLOX or NanoDet checkpoint")
        built = checkpoint.build(path)
        if not isinstance(built, YoloxNano | NanoDetPlus):
            raise ValueError(f"--teacher {path} holds a {type(built).__name__}, no YOLOX or NanoDet")
        teacher = built
    if isinstance(teacher, NanoDetPlus) != isinstance(student, NanoDetPlus):
        raise ValueError(f"--teacher {path} holds a {type(teacher).__name__}, the student is a "
                         f"{type(student).__name__}")
    probe = torch.zeros(1, 3, 64, 128)
    with torch.no_grad():
        theirs, mine = teacher.eval()(probe), student.eval()(probe)
    if [tuple(t.shape) for t in theirs] != [tuple(m.shape) for m in mine]:
        raise ValueError(f"--teacher {path}: its maps {[tuple(t.shape) for t in theirs]} differ from the "
                         f"student's {[tuple(m.shape) for m in mine]}")
    return teacher


def run_polar(args: argparse.Namespace) -> int:
    """`--init-from`: fine-tune the YOLOX of `--view` (polar by default). Every input is checked
    before OUT is touched."""
    out = Path(args.out)
    defaults = FinetuneConfig()
    try:
        model_config, augment = yolox_view(args)
        config = FinetuneConfig(
            epochs=defaults.epochs if args.epochs is None else args.epochs,
            batch_size=args.batch_size or defaults.batch_size, lr=args.lr or defaults.lr,
            freeze=default_freeze(args.network) if args.freeze is None else tuple(args.freeze),
            distill=defaults.distill if args.distill is None else args.distill,
            feature_distill=args.distill_features,
            foot_max_metres_per_px=(defaults.foot_max_metres_per_px if args.foot_metres_cap is None
                                    else args.foot_metres_cap),
            foot_coarse_weight=(defaults.foot_coarse_weight if args.foot_coarse_weight is None
                                else args.foot_coarse_weight),
            checkpoint_every_s=args.checkpoint_every or defaults.checkpoint_every_s,
            seed=args.seed, val_limit=args.val_limit, device=args.device,
            augment=augment)
        model_config, initial = initial_network(args, model_config)
        teacher = None if args.teacher is None else teacher_network(args.teacher, model_config, initial)
        train_frames = [frame for path in args.data for frame in read_dataset(path)]
        val_frames = read_dataset(args.val) if args.val else None
        names = ", ".join(Path(path).parent.name or str(path) for path in args.data)
        finetuner = Finetuner(model_config, config, out, initial, train_frames, val_frames,
                              f"{names} ({len(train_frames)} frames)", progress=not args.quiet,
                              teacher=teacher)
        if args.resume:
            if not (out / LAST).exists():
                raise ValueError(f"nothing to resume, {out / LAST} does not exist")
            finetuner.resume(out / LAST)
    except (DatasetFormatError, CheckpointError, ValueError) as error:  # PretrainedWeightsError too
        print(f"fishloc train: {error}", file=sys.stderr)
        return 2
    if not args.resume:
        out.mkdir(parents=True, exist_ok=True)
        (out / "log.jsonl").unlink(missing_ok=True)
        (out / "config.json").write_text(json.dumps(
            {"model": model_config.to_dict(), "finetune": asdict(config), "init_from": args.init_from,
             "teacher": args.teacher, "data": args.data, "val": args.val}, indent=2, default=str) + "\n",
            encoding="utf-8")
    finetuner.fit()
    return 0
