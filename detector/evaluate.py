"""`fishloc eval`: a checkpoint or ONNX model on an annotated dataset -> metrics JSON and plots.

Both kinds of model go through the service's own pre- and post-processing (`contract`): the frame
reduced as the service's JPEG decode would, the model's view of it (letterbox or polar unwrap),
boxes back to frame pixels, rotated NMS. Frames without a calibration (CEPDOF, WEPDTOF) are run with
the assumed camera of DESIGN.md. Metrics are those of `detector.metrics`, overall and per split
(seen/unseen) when the data has more than one.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn
from tqdm import tqdm

from contract import (
    FrameDetections,
    ModelError,
    ModelInfo,
    ModelRunner,
    OnnxModel,
    OperatingPoint,
    RawOutputs,
    SessionThreads,
)
from contract.detect import ContractModel
from contract.views import DEFAULT_VIEW, mapping_layout
from detector.checkpoint import CheckpointError, load_checkpoint
from detector.data.dataset import load_rgb
from detector.data.readers import ASSUMED_LENSES, DatasetFormatError, FrameAnnotations, read_dataset
from detector.drawing import draw_evaluated
from detector.graph import contract_info, contract_module
from detector.metrics import (
    BOX_SIDE,
    CENTRE,
    FOOT,
    EvalFrame,
    compute_metrics,
    localisation_points,
    pr_curve,
)
from detector.operating_point import (
    NMS_GRID,
    SweptPoint,
    choose,
    describe,
    sweep,
)
from detector.people import FalsePositive, PersonOutcome, breakdown, summarise_outcomes, write_rows_csv
from detector.plots import plot_pe_by_distance, plot_pr_curve
from fisheye import FisheyeCamera, assumed_camera
from fisheye.boxes import cepdof_to_corners
from fisheye.view_plan import ViewPlanConfig

EVAL_MIN_SCORE = 0.05  # detections kept for AP (DESIGN.md, "Datasets"; the PR curve runs down to here)


class Predictor(Protocol):
    default_min_score: float

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        ...


class TorchContract:
    """A torch module of the ONNX contract with the ModelInfo its export would carry: runs like an
    `OnnxModel` (`info`, `run`), so `contract.ModelRunner` pre- and post-processes it alike."""

    def __init__(self, module: nn.Module, info: ModelInfo) -> None:
        self.module = module.eval()
        self.info = info

    def run(self, image: NDArray[np.uint8]) -> RawOutputs:
        device = next(self.module.parameters()).device
        with torch.no_grad():
            outputs = self.module(torch.from_numpy(np.ascontiguousarray(image[None])).to(device))
        arrays = [o[0].float().cpu().numpy() for o in outputs]
        return RawOutputs(arrays[0], arrays[1], arrays[2] if len(arrays) > 2 else None)

    def run_boxes(self, image: NDArray[np.uint8]) -> RawOutputs:
        """Boxes and scores alone (the module runs whole; `OnnxModel` skips its foot branch)."""
        return dataclasses.replace(self.run(image), foot=None)


class RunnerPredictor:
    """Any contract model (ONNX session or torch module) behind `contract.ModelRunner`."""

    def __init__(self, runner: ModelRunner) -> None:
        self.runner = runner
        self.default_min_score = runner.default_min_score
        self.points_used: set[OperatingPoint] = set()  # the operating points of the views it ran

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        found = self.runner.detect(frames_rgb, cameras, min_score)
        self.points_used.update(d.view_point for d in found if d.view_point is not None)
        return found


def torch_predictor(module: nn.Module, info: ModelInfo) -> RunnerPredictor:
    return RunnerPredictor(ModelRunner(TorchContract(module, info)))


def load_contract_model(path: str | Path, threads: int | None = None, device: str = "cpu") -> ContractModel:
    """An ONNX file (by its .onnx suffix) or a training checkpoint as a model of the contract."""
    if Path(path).suffix.lower() == ".onnx":
        return OnnxModel(path, SessionThreads(intra_op=threads or torch.get_num_threads()))
    checkpoint = load_checkpoint(path)
    return TorchContract(contract_module(checkpoint, str(path)).to(device), contract_info(checkpoint))


def load_predictor(path: str | Path, device: str = "cpu", threads: int | None = None) -> Predictor:
    """An ONNX file (by its .onnx suffix) or a training checkpoint."""
    return RunnerPredictor(ModelRunner(load_contract_model(path, threads, device)))


def frame_camera(frame: FrameAnnotations) -> FisheyeCamera:
    return frame.camera if frame.camera is not None else assumed_camera(frame.width, frame.height)


@dataclass
class Evaluation:
    frames: list[EvalFrame]
    metrics: dict[str, Any]


def _corners_or_none(cxcywha: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    return None if cxcywha is None else cepdof_to_corners(cxcywha)


def eval_frame(frame: FrameAnnotations, detections: FrameDetections, min_score: float | None = None
               ) -> EvalFrame:
    """An annotated frame and its detections -> what the metrics score; its threshold is that of
    the operating point its view ran at, else `min_score`."""
    if detections.view_point is not None:
        min_score = detections.view_point.min_score
    return EvalFrame(
        gt_boxes=frame.boxes_cxcywh, gt_locations_m=frame.locations_m,
        gt_distances_m=frame.distances_m, det_boxes=detections.boxes_cxcywh,
        det_scores=detections.scores, principal_point=frame.principal_point,
        camera=frame.camera, split=frame.split, crowd_boxes=frame.crowd_cxcywh,
        # CEPDOF/WEPDTOF frames are scored against the file's own boxes (DESIGN.md).
        gt_corners=_corners_or_none(frame.file_boxes_cxcywha),
        crowd_corners=_corners_or_none(frame.file_crowd_cxcywha),
        camera_assumed=frame.camera_assumed, det_foot_px=detections.foot_px, min_score=min_score)


def eval_frames(predictor: Predictor, frames: Sequence[FrameAnnotations], batch_size: int = 8,
                progress: bool = False) -> list[EvalFrame]:
    """Run the predictor over annotated frames -> EvalFrames (detections with score ≥ 0.05)."""
    result: list[EvalFrame] = []
    batches = range(0, len(frames), batch_size)
    for start in tqdm(batches, desc="eval", unit="batch", disable=not progress):
        chunk = frames[start:start + batch_size]
        found = predictor.detect([load_rgb(f) for f in chunk], [frame_camera(f) for f in chunk],
                                 EVAL_MIN_SCORE)
        result.extend(eval_frame(frame, detections, predictor.default_min_score)
                      for frame, detections in zip(chunk, found, strict=True))
    return result


def choose_operating_point(model: ContractModel, frames: Sequence[FrameAnnotations],
                           grid: Sequence[float] = NMS_GRID, view: ViewPlanConfig = DEFAULT_VIEW
                           ) -> tuple[SweptPoint, Evaluation, list[SweptPoint]]:
    """The best-F1 (NMS IoU, threshold) of `model` on validation `frames` (`detector.operating_point`)
    in the views `view` plans, the evaluation there (its metrics with `min_score`, `nms_iou` and
    the `layouts` of the frames' views: the key a view's own point is stored under), and every
    IoU's point."""
    runner = ModelRunner(model, view=view)
    outputs = runner.outputs((load_rgb(f) for f in frames), [frame_camera(f) for f in frames])

    def frames_at(nms_iou: float) -> list[EvalFrame]:
        found = runner.select(outputs, EVAL_MIN_SCORE, nms_iou)
        return [eval_frame(frame, detections) for frame, detections in zip(frames, found, strict=True)]

    swept = sweep(frames_at, grid)
    points = [point for point, _ in swept]
    best, evaluated = swept[choose(points)]
    layouts = sorted({mapping_layout(o.mapping) or "fixed" for o in outputs})
    metrics = {**summarise(evaluated, best.min_score), "nms_iou": best.nms_iou, "layouts": layouts}
    return best, Evaluation(evaluated, metrics), points


def summarise(frames: Sequence[EvalFrame], min_score: float | None) -> dict[str, Any]:
    """Overall metrics plus a `splits` entry per split when there are several; precision and recall
    at `min_score`, or where it is None at each frame's own (`min_score` then lists them, where
    they differ)."""
    metrics: dict[str, Any] = dict(compute_metrics(frames, min_score))
    own = sorted({f.min_score for f in frames if f.min_score is not None})
    metrics["min_score"] = min_score if min_score is not None else own[0] if len(own) == 1 else own
    splits = sorted({f.split for f in frames})
    if len(splits) > 1:
        metrics["splits"] = {name: compute_metrics([f for f in frames if f.split == name], min_score)
                             for name in splits}
    return metrics


def evaluate(predictor: Predictor, frames: Sequence[FrameAnnotations], progress: bool = False,
             min_score: float | None = None) -> Evaluation:
    """Metrics of `predictor` on `frames`: precision and recall at `min_score`, or (None) at the
    operating point of each frame's view (`contract.metadata.ModelInfo.point_for`)."""
    evaluated = eval_frames(predictor, frames, progress=progress)
    return Evaluation(evaluated, summarise(evaluated, min_score))


def write_plots(evaluation: Evaluation, folder: Path, title: str) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    precision, recall, _ = pr_curve(evaluation.frames)
    pr_path, pe_path = folder / "pr_curve.png", folder / "pe_by_distance.png"
    plot_pr_curve(precision, recall, pr_path, f"{title}: PR at IoU 0.5")
    distances, errors = localisation_points(evaluation.frames)
    has_foot = any(frame.det_foot_px is not None for frame in evaluation.frames)
    labels = {FOOT: "predicted foot", BOX_SIDE: "box-side foot point", CENTRE: "box centre"}
    shown = {labels[p]: e for p, e in errors.items() if has_foot or p != FOOT}
    plot_pe_by_distance(distances, shown, pe_path, f"{title}: localisation error")
    return [pr_path, pe_path]


def write_drawings(frames: Sequence[FrameAnnotations], evaluated: Sequence[EvalFrame],
                   outcomes: Sequence[PersonOutcome], errors: Sequence[FalsePositive], folder: Path
                   ) -> list[Path]:
    """Each frame drawn as the evaluation saw it (`detector.drawing.draw_evaluated`) into
    `folder`/<image id>.png; the paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for frame, seen in zip(frames, evaluated, strict=True):
        name = str(frame.image_id)
        image = draw_evaluated(load_rgb(frame), seen, [o for o in outcomes if o.frame == name],
                               [e for e in errors if e.frame == name])
        path = folder / f"{Path(name).name}.png"
        cv2.imwrite(str(path), image)
        paths.append(path)
    return paths


def json_safe(value: Any) -> Any:
    """NaN and infinities -> None, recursively (strict JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = "Site sequences: fishloc eval --tracks --help (tracks, zone counts, line counts)."
    parser.add_argument("--model", required=True, help="checkpoint (.pt) or ONNX model (.onnx)")
    parser.add_argument("--data", required=True, help="annotations.json (FishLoc/LOAF or CEPDOF format)")
    parser.add_argument("--json", required=True, help="where to write the metrics")
    parser.add_argument("--plots", default=None, help="folder for pr_curve.png and pe_by_distance.png")
    parser.add_argument("--min-score", type=float, default=None,
                        help="threshold of precision/recall (default: the model's own)")
    parser.add_argument("--nms-iou", type=float, default=None,
                        help="rotated NMS IoU (default: the model's own, fishloc.nms_iou)")
    parser.add_argument("--operating-point", action="store_true",
                        help="choose the NMS IoU and threshold of best F1 on this data (validation "
                             "renders only) and report there; each IoU's point goes into the JSON")
    parser.add_argument("--limit", type=int, default=None, help="evaluate the first N frames only")
    parser.add_argument("--max-view-pixels", type=int, default=None,
                        help="a planned model's view budget, as fishloc serve --max-view-pixels")
    parser.add_argument("--second-look", type=int, default=None, metavar="PIXELS",
                        help="a planned model's second look, as fishloc serve --second-look (px of its "
                             "patches in all; default 0: none)")
    parser.add_argument("--longest-person-ratio", type=float, default=None, metavar="RATIO",
                        help="a planned model's candidates longer along the ray than RATIO standing adults "
                             "where their feet stand are dropped before NMS "
                             "(ViewPlanConfig.longest_person_ratio; default: no bound)")
    parser.add_argument("--assumed-camera", choices=ASSUMED_LENSES, default="short-side",
                        help="camera of frames without a calibration (CEPDOF/WEPDTOF files): the 180° "
                             "circle that fills the frame's shorter side (default, DESIGN.md), or the "
                             "one fitted to each frame's image circle (for circles wider than the frame)")
    parser.add_argument("--people", default=None, metavar="CSV",
                        help="write each annotated person's outcome here (found, low_score, loose_box, "
                             "missed; where they stand, the best detection's IoU, score and box), and "
                             "the counts by ring, size and frame into the JSON's 'people'")
    parser.add_argument("--draw", default=None, metavar="FOLDER",
                        help="write each frame here as a PNG with its people in the colour of their "
                             "outcome (as --people) and the detections from score 0.1, the false "
                             "positives marked (detector/drawing.py)")
    parser.add_argument("--false-positives", default=None, metavar="CSV",
                        help="write each false positive at the threshold here (duplicate, loose, "
                             "background; where, score, box, best IoU), and the counts into 'people'")


def run(args: argparse.Namespace) -> int:
    if args.nms_iou is not None and not 0.0 < args.nms_iou <= 1.0:
        print(f"fishloc eval: --nms-iou must lie in (0, 1], got {args.nms_iou}", file=sys.stderr)
        return 2
    try:
        model = load_contract_model(args.model)
        frames = read_dataset(args.data, args.assumed_camera)
    except (CheckpointError, ModelError, DatasetFormatError) as error:
        print(f"fishloc eval: {error}", file=sys.stderr)
        return 2
    if args.limit is not None:
        frames = frames[:args.limit]
    extra: dict[str, Any] = {}
    try:
        asked = (("max_pixels", args.max_view_pixels), ("second_look_pixels", args.second_look),
                 ("longest_person_ratio", args.longest_person_ratio))
        view = dataclasses.replace(DEFAULT_VIEW, **{name: v for name, v in asked if v is not None})
    except ValueError as error:
        print(f"fishloc eval: {error}", file=sys.stderr)
        return 2
    if args.operating_point:
        best, evaluation, points = choose_operating_point(model, frames, view=view)
        print(json.dumps({"operating_point": describe([best])[0], "layouts": evaluation.metrics["layouts"]}))
        extra["operating_points"] = describe(points)
    else:
        predictor = RunnerPredictor(ModelRunner(model, args.nms_iou, view=view))
        evaluation = evaluate(predictor, frames, progress=True, min_score=args.min_score)
        ious = sorted({point.nms_iou for point in predictor.points_used})
        extra["nms_iou"] = ious[0] if len(ious) == 1 else ious
    if args.people or args.false_positives or args.draw:
        outcomes, errors = breakdown(evaluation.frames, [str(f.image_id) for f in frames])
        if args.people:
            write_rows_csv(outcomes, args.people, PersonOutcome)
        if args.false_positives:
            write_rows_csv(errors, args.false_positives, FalsePositive)
        if args.draw:
            write_drawings(frames, evaluation.frames, outcomes, errors, Path(args.draw))
        extra["people"] = summarise_outcomes(outcomes, errors)
        print(json.dumps({"people": extra["people"]["all"]}))
    metrics = json_safe({**evaluation.metrics, **extra, "model": str(args.model), "data": str(args.data),
                         "assumed_camera": args.assumed_camera})
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(metrics, indent=2) + "\n", encoding="utf-8")
    if args.plots:
        write_plots(evaluation, Path(args.plots), Path(args.model).name)
    keys: tuple[str, ...] = ("mAP", "AP50", "AP75", "AP_near", "AP_mid", "AP_far", "mPE", "mPE_reported",
                             "mPE_center", "PE_far", "precision", "recall")
    keys += tuple(k for k in ("AP50_radius_aligned",) if k in metrics)  # files with their own boxes
    print(json.dumps({k: metrics.get(k) for k in keys}))
    return 0
