"""`fishloc export`: a checkpoint -> an ONNX model of the FishLoc contract, verified on every run.

The graph takes `image` uint8 (N, S, S, 3) RGB (dynamic N) and returns `boxes` float32 (N, K, 4)
radius-aligned `cxcywh` in input pixels, aligned about the input centre ((S - 1) / 2, (S - 1) / 2),
and `scores` float32 (N, K) sorted descending, with the `fishloc.*` metadata of DESIGN.md. Each
export is checked with `onnx.checker` and for parity with torch; `--int8` adds static QDQ
quantisation calibrated on frames from `--calibration-data`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import sys
import tempfile
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import onnx
import torch
from numpy.typing import NDArray
from torch import nn

from contract import ModelInfo, OnnxModel, SessionThreads, metadata_props
from detector.checkpoint import Checkpoint, CheckpointError, load_checkpoint, parse_view_point_args
from detector.graph import contract_info, contract_module
from detector.yolox.polar import PolarDetectorConfig
from exporter.parity import ParityReport, check_parity, synthetic_parity_frames
from exporter.quantize import check_integer_convolutions, quantize_int8
from fisheye import FisheyeCamera

DEFAULT_OPSET = 18
_IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}


@dataclass(frozen=True)
class ExportReport:
    output: str
    input_size: int
    opset: int
    max_detections: int
    parity: ParityReport
    int8: bool
    integer_ops: dict[str, int] | None = None


@dataclass(frozen=True)
class GraphOptions:
    """How the graph is built beyond what the checkpoint says: `planned`, a polar graph of any
    height and width (multiples of 32) whose view the service plans per camera
    (`fishloc.view_planned`); `peaks`, its top K taken among peak cells only
    (`detector.yolox.decode.peak_cells`). Either turns on what the checkpoint's config leaves off."""

    planned: bool = False
    peaks: bool = False


def contract_model(checkpoint: Checkpoint, input_size: int | None = None, source: str = "<memory>",
                   options: GraphOptions = GraphOptions()) -> tuple[nn.Module, ModelInfo]:
    """`checkpoint`'s network wrapped to the ONNX contract, at `input_size` (default: trained; a
    letterbox side or a strip height), and the metadata its export carries."""
    if input_size is not None and input_size % 32 != 0:
        raise ValueError(f"--input-size must be a multiple of 32, got {input_size}")
    config = checkpoint.config
    if input_size is not None and input_size != config.input_size:
        config = replace(config, input_size=input_size)
    if options.planned or options.peaks:
        if not isinstance(config, PolarDetectorConfig):
            raise ValueError("--planned and --peaks need a polar network")
        config = replace(config, planned=config.planned or options.planned,
                         peaks=config.peaks or options.peaks)
    checkpoint = replace(checkpoint, config=config)
    return contract_module(checkpoint, source), contract_info(checkpoint)


def _torch_to_onnx(model: nn.Module, info: ModelInfo, path: Path, opset: int) -> None:
    width, height = info.input_wh
    example = torch.zeros((2, height, width, 3), dtype=torch.uint8)
    with torch.no_grad():
        outputs = ["boxes", "scores", "foot"][:len(model(example))]
    batch = torch.export.Dim("batch", min=1, max=1024)
    shapes: dict[int, object] = {0: batch}
    if info.planned:  # any height and width, multiples of the largest stride
        shapes[1] = 32 * torch.export.Dim("rows32", min=2, max=256)
        shapes[2] = 32 * torch.export.Dim("columns32", min=2, max=256)
    # The exporter prints progress and torch-internal deprecation notices; keep the command's output ours.
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        logging.getLogger("torch.onnx").setLevel(logging.ERROR)
        torch.onnx.export(model, (example,), str(path), input_names=["image"],
                          output_names=outputs, opset_version=opset, dynamo=True,
                          dynamic_shapes={"image": shapes}, external_data=False, verbose=False)


# Each node's Python stack at export: 2 KB a node, the exporting machine's paths in every one, and
# nothing onnxruntime reads (the nodes keep their module scopes, `namespace`, for profiles).
_NODE_KEYS_DROPPED = ("pkg.torch.onnx.stack_trace",)


def _write_metadata(path: Path, metadata: dict[str, str]) -> None:
    proto = onnx.load(str(path))
    del proto.metadata_props[:]
    for key, value in metadata.items():
        proto.metadata_props.add(key=key, value=value)
    for node in proto.graph.node:
        kept = [(entry.key, entry.value) for entry in node.metadata_props
                if entry.key not in _NODE_KEYS_DROPPED]
        del node.metadata_props[:]
        for key, value in kept:
            node.metadata_props.add(key=key, value=value)
    onnx.checker.check_model(proto, full_check=True)
    onnx.save(proto, str(path))


def load_calibration_frames(folder: str | Path, info: ModelInfo, limit: int = 64) -> NDArray[np.uint8]:
    """(N, H, W, 3) model inputs made from the frames of a folder as the service makes them (the
    model's view: letterbox or polar unwrap). A `fishloc synth` folder's frames use their own
    cameras (its annotations.json); other images the assumed camera of DESIGN.md."""
    import cv2

    from contract import prepare_input, reduce_like_decode
    from contract.views import min_decoded_side
    from detector.data.dataset import load_rgb
    from detector.data.readers import read_dataset
    from fisheye import assumed_camera

    root = Path(folder)
    pairs: list[tuple[NDArray[np.uint8], FisheyeCamera]] = []
    if (root / "annotations.json").is_file():
        for frame in read_dataset(root)[:limit]:
            camera = frame.camera or assumed_camera(frame.width, frame.height)
            pairs.append((load_rgb(frame), camera))
    else:
        files = sorted(p for p in root.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)[:limit]
        for file in files:
            bgr = cv2.imread(str(file), cv2.IMREAD_COLOR)
            if bgr is None:
                raise ValueError(f"cannot decode calibration image {file}")
            rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
            pairs.append((rgb, assumed_camera(rgb.shape[1], rgb.shape[0])))
    if not pairs:
        raise ValueError(f"no images (.jpg, .png, .bmp) in calibration folder {folder}")
    inputs = [prepare_input(info, reduce_like_decode(rgb, min_decoded_side(info, camera)), camera)[0]
              for rgb, camera in pairs]
    return np.stack(inputs)


def export_onnx(checkpoint: Checkpoint, output: str | Path, input_size: int | None = None,
                opset: int = DEFAULT_OPSET, int8: bool = False,
                calibration_frames: NDArray[np.uint8] | None = None,
                parity_frames: NDArray[np.uint8] | None = None,
                options: GraphOptions = GraphOptions()) -> ExportReport:
    """Export, write metadata, check the graph and its parity with torch; return what was verified.

    With `int8`, the verified float graph is quantised and written to `output` instead; the float
    parity report still describes the graph before quantisation.
    """
    model, info = contract_model(checkpoint, input_size, options=options)
    width, size = info.input_wh
    target = Path(output)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder:
        float_path = Path(folder) / "float.onnx" if int8 else target
        _torch_to_onnx(model, info, float_path, opset)
        _write_metadata(float_path, metadata_props(info))
        frames = (parity_frames if parity_frames is not None
                  else synthetic_parity_frames(size, width=width))
        session = OnnxModel(float_path, SessionThreads(intra_op=1))
        parity = check_parity(model, session, frames, info.default_min_score)
        if info.planned:  # a planned graph must agree at a canvas unlike the trained strip, too
            check_parity(model, session, synthetic_parity_frames(size + 64, width=width // 2 + 32)[:1],
                         info.default_min_score)
        integer_ops = None
        if int8:
            if calibration_frames is None:
                raise ValueError("INT8 export needs calibration frames (--calibration-data DIR)")
            quantize_int8(float_path, target, calibration_frames)
            onnx.checker.check_model(onnx.load(str(target)), full_check=True)
            integer_ops = check_integer_convolutions(target)
    return ExportReport(str(target), size, opset, int(getattr(model, "max_detections", 0)), parity, int8,
                        integer_ops)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--checkpoint", required=True, help="training checkpoint (.pt) to export")
    parser.add_argument("--output", required=True, help="ONNX file to write")
    parser.add_argument("--input-size", type=int, default=None,
                        help="input side S in pixels (multiple of 32; default: the trained size)")
    parser.add_argument("--opset", type=int, default=DEFAULT_OPSET, help="ONNX opset (default 18)")
    parser.add_argument("--int8", action="store_true", help="static INT8 QDQ quantisation")
    parser.add_argument("--calibration-data", default=None,
                        help="folder of frames (e.g. a `fishloc synth` output) for INT8 calibration")
    parser.add_argument("--model-version", default=None, help="override fishloc.model_version")
    parser.add_argument("--trained-on", default=None, help="override fishloc.trained_on")
    parser.add_argument("--min-score", type=float, default=None,
                        help="override fishloc.default_min_score")
    parser.add_argument("--nms-iou", type=float, default=None, help="override fishloc.nms_iou")
    parser.add_argument("--view-point", action="append", default=[], metavar="LAYOUT=SCORE,IOU",
                        help="a planned view layout's own operating point, e.g. 2band+nadir=0.346,0.3 "
                             "(fishloc.view_operating_points); repeatable")
    parser.add_argument("--planned", action="store_true",
                        help="polar graph of any height and width: the service plans each camera's view")
    parser.add_argument("--peaks", action="store_true",
                        help="take the top K among peak cells only (every person reaches NMS in a crowd)")


def run(args: argparse.Namespace) -> int:
    if args.int8 and not args.calibration_data:
        print("fishloc export: --int8 needs --calibration-data DIR", file=sys.stderr)
        return 2
    try:
        checkpoint = load_checkpoint(args.checkpoint)
    except CheckpointError as error:
        print(f"fishloc export: {error}", file=sys.stderr)
        return 2
    info = checkpoint.info
    if args.model_version is not None:
        info.model_version = args.model_version
    if args.trained_on is not None:
        info.trained_on = args.trained_on
    if args.min_score is not None:
        info.default_min_score = args.min_score
    if args.nms_iou is not None:
        info.nms_iou = args.nms_iou
    try:
        info.view_points = {**info.view_points, **parse_view_point_args(args.view_point)}
        checkpoint.build(args.checkpoint)  # a mismatched checkpoint fails here, with its own message
        calibration = None
        options = GraphOptions(planned=args.planned, peaks=args.peaks)
        if args.int8:
            model_info = contract_model(checkpoint, args.input_size, args.checkpoint, options)[1]
            calibration = load_calibration_frames(args.calibration_data, model_info)
        report = export_onnx(checkpoint, args.output, args.input_size, args.opset, args.int8, calibration,
                             options=options)
    except (CheckpointError, ValueError) as error:
        print(f"fishloc export: {error}", file=sys.stderr)
        return 2
    print(json.dumps(asdict(report), indent=2))
    return 0
