"""Checkpoint files: the network's config and weights, plus the training state that resumes exactly.

A checkpoint is a `torch.save`d dict with `format == "fishloc-checkpoint"`. Anything else (a file
that is not a checkpoint, a truncated file, weights that do not fit the stored config) raises
`CheckpointError` with a message that says what is wrong.
"""

from __future__ import annotations

import dataclasses
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch
from torch import nn

from contract.metadata import LAYOUT_PATTERN, LEGACY_NMS_IOU, OperatingPoint
from detector.model import DetectorConfig, build_model
from detector.yolox.fisheye import ARCH as FISHEYE_ARCH
from detector.yolox.fisheye import FisheyeDetectorConfig, build_fisheye_network
from detector.yolox.polar import ARCH as POLAR_ARCH
from detector.yolox.polar import PolarDetectorConfig, build_polar_network

NetworkConfig = DetectorConfig | PolarDetectorConfig | FisheyeDetectorConfig

CHECKPOINT_FORMAT = "fishloc-checkpoint"
CHECKPOINT_VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint that cannot be used; the message names the file and the problem."""


@dataclass
class ModelInfo:
    """What a model says about itself (carried into the ONNX metadata)."""

    model_version: str = "0.0.0"
    trained_on: str = "untrained"
    default_min_score: float = 0.3
    nms_iou: float = LEGACY_NMS_IOU  # chosen with the threshold (`detector.operating_point`)
    # a planned model's own points for some view layouts: layout -> [min_score, nms_iou]
    # (`contract.metadata.ModelInfo.view_points`)
    view_points: dict[str, list[float]] = field(default_factory=dict)


def build_network(config: NetworkConfig) -> nn.Module:
    """The (untrained) network a config describes: the 0.1 CenterNet or a YOLOX (polar or fisheye)."""
    if isinstance(config, PolarDetectorConfig):
        return build_polar_network(config)
    if isinstance(config, FisheyeDetectorConfig):
        return build_fisheye_network(config)
    return build_model(config)


def config_from_dict(record: dict[str, Any]) -> NetworkConfig:
    if record.get("arch") == POLAR_ARCH:
        return PolarDetectorConfig.from_dict(record)
    if record.get("arch") == FISHEYE_ARCH:
        return FisheyeDetectorConfig.from_dict(record)
    return DetectorConfig.from_dict(record)


@dataclass
class Checkpoint:
    config: NetworkConfig
    model_state: dict[str, Any]
    info: ModelInfo = field(default_factory=ModelInfo)
    training_state: dict[str, Any] = field(default_factory=dict)

    def build(self, path: str | Path = "<memory>") -> nn.Module:
        """The network with these weights, in eval mode."""
        model = build_network(self.config)
        try:
            model.load_state_dict(self.model_state, strict=True)
        except RuntimeError as error:
            first_lines = "; ".join(str(error).splitlines()[:3])
            raise CheckpointError(
                f"checkpoint {path}: weights do not fit its network config ({first_lines})"
            ) from None
        return model.eval()


def save_checkpoint(path: str | Path, checkpoint: Checkpoint) -> None:
    """Write atomically (a crash mid-write leaves the previous file intact)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    record = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "config": checkpoint.config.to_dict(),
        "model": checkpoint.model_state,
        "info": vars(checkpoint.info),
        "training": checkpoint.training_state,
    }
    temporary = target.with_name(target.name + ".tmp")
    torch.save(record, temporary)
    os.replace(temporary, target)


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read a checkpoint; CheckpointError for anything that is not a usable FishLoc checkpoint."""
    file = Path(path)
    if not file.is_file():
        raise CheckpointError(f"checkpoint {file} does not exist")
    try:
        # Our own files also hold optimizer and RNG states (numpy arrays), hence weights_only=False.
        record = torch.load(file, map_location="cpu", weights_only=False)
    except Exception as error:  # torch raises many types for damaged files
        raise CheckpointError(
            f"checkpoint {file} cannot be read ({type(error).__name__}: {error}); "
            "is it a FishLoc checkpoint written by `fishloc train`?"
        ) from None
    if not isinstance(record, dict) or record.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{file} is not a FishLoc checkpoint (no '{CHECKPOINT_FORMAT}' marker)")
    if record.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"{file} has checkpoint version {record.get('version')}, "
                              f"this FishLoc reads version {CHECKPOINT_VERSION}")
    try:
        config = config_from_dict(dict(record["config"]))
        state = dict(record["model"])
    except (KeyError, TypeError, ValueError) as error:
        raise CheckpointError(f"checkpoint {file} has a damaged config or weights: {error}") from None
    info_record = record.get("info") or {}
    info = ModelInfo(**{k: v for k, v in info_record.items() if k in ModelInfo.__dataclass_fields__})
    return Checkpoint(config, state, info, dict(record.get("training") or {}))


def load_model(path: str | Path) -> tuple[nn.Module, Checkpoint]:
    """The network of a checkpoint file (eval mode) and the checkpoint itself."""
    checkpoint = load_checkpoint(path)
    return checkpoint.build(path), checkpoint


def release_of(checkpoint: Checkpoint, info: ModelInfo | None = None,
               graph: dict[str, bool] | None = None, source: str | Path = "the checkpoint") -> Checkpoint:
    """A training checkpoint without its training state (optimizer, schedule, RNG), in memory:
    the file to ship and to fine-tune from with `fishloc train --init`, a third of the size.
    `info`, when given, replaces what the model says about itself (version, data, threshold);
    `graph` sets fields of a polar config that shape only the exported graph (`peaks`, `planned`);
    `source` names the checkpoint in errors."""
    config = checkpoint.config
    if graph:
        if not hasattr(config, "planned"):
            raise CheckpointError(f"{source}: --peaks and --planned need a polar network")
        config = dataclasses.replace(config, **graph)  # type: ignore[arg-type]
    return Checkpoint(config, checkpoint.model_state, info or checkpoint.info, {})


def save_release(source: str | Path, target: str | Path, info: ModelInfo | None = None,
                 graph: dict[str, bool] | None = None) -> Checkpoint:
    """The release of the training checkpoint at `source` (`release_of`) written to `target`."""
    release = release_of(load_checkpoint(source), info, graph, source)
    save_checkpoint(target, release)
    return release


def parse_view_point_args(values: list[str]) -> dict[str, list[float]]:
    """`LAYOUT=SCORE,IOU` arguments -> layout -> [min_score, nms_iou]; CheckpointError naming the
    argument when one is malformed, names no layout a plan has, or lies out of range."""
    points: dict[str, list[float]] = {}
    for value in values:
        layout, _, numbers = value.partition("=")
        try:
            score, iou = (float(x) for x in numbers.split(","))
            OperatingPoint(score, iou)
        except ValueError as error:
            raise CheckpointError(f"--view-point {value!r}: expected LAYOUT=SCORE,IOU with SCORE in [0, 1] "
                                  f"and IOU in (0, 1], e.g. 2band+nadir=0.346,0.3 ({error})") from None
        if not LAYOUT_PATTERN.fullmatch(layout):
            raise CheckpointError(f"--view-point {value!r}: unknown layout {layout!r} "
                                  "(1band, 2band, each with +nadir, then +look)")
        points[layout] = [score, iou]
    return points


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="a release copy of a training checkpoint")
    parser.add_argument("source", help="training checkpoint (e.g. runs/NAME/last.pt)")
    parser.add_argument("target", help="release checkpoint to write")
    parser.add_argument("--model-version", default=None)
    parser.add_argument("--trained-on", default=None)
    parser.add_argument("--min-score", type=float, default=None, help="the default score threshold")
    parser.add_argument("--nms-iou", type=float, default=None, help="the rotated NMS IoU")
    parser.add_argument("--view-point", action="append", default=[], metavar="LAYOUT=SCORE,IOU",
                        help="the operating point of a planned view layout, e.g. 2band+nadir=0.346,0.3 "
                             "(chosen with `fishloc eval --operating-point --max-view-pixels N`); repeatable")
    parser.add_argument("--peaks", action="store_true", help="its graph takes the top K among peak cells")
    parser.add_argument("--planned", action="store_true", help="its graph takes planned views (any size)")
    parser.add_argument("--wise-ft", metavar="PRETRAINED_ONNX", default=None,
                        help="interpolate the fine-tuned head towards the COCO head of this ONNX, the one "
                             "it started from (YOLOX-Nano or NanoDet-Plus-m; WiSE-FT)")
    parser.add_argument("--wise-from", metavar="START.pt", default=None,
                        help="interpolate every weight towards this checkpoint, the one a run that "
                             "trained the whole network started from (WiSE-FT of the whole network)")
    parser.add_argument("--wise-alpha", type=float, default=0.9,
                        help="weight of the fine-tuned network in that interpolation (default 0.9)")
    args = parser.parse_args(argv)
    if args.wise_ft is not None and args.wise_from is not None:
        parser.error("--wise-ft and --wise-from are two interpolations: choose one")
    from detector.yolox.wise import wise_checkpoint, wise_from_checkpoint  # which imports this module

    try:
        source = load_checkpoint(args.source)
        info = source.info
        info = ModelInfo(model_version=args.model_version or info.model_version,
                         trained_on=args.trained_on or info.trained_on,
                         default_min_score=info.default_min_score if args.min_score is None
                         else args.min_score,
                         nms_iou=info.nms_iou if args.nms_iou is None else args.nms_iou,
                         view_points={**info.view_points, **parse_view_point_args(args.view_point)})
        graph = {name: True for name in ("peaks", "planned") if getattr(args, name)}
        shipped = release_of(source, info, graph, args.source)
        # Either interpolation is made in memory and refused before anything is written.
        if args.wise_ft is not None:
            shipped = wise_checkpoint(shipped, args.wise_ft, args.wise_alpha)
        if args.wise_from is not None:
            shipped = wise_from_checkpoint(shipped, args.wise_from, args.wise_alpha)
        save_checkpoint(args.target, shipped)
    except CheckpointError as error:
        print(f"detector.checkpoint: {error}", file=sys.stderr)
        return 2
    print(f"wrote {args.target}: {shipped.info.model_version}, trained on {shipped.info.trained_on}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
