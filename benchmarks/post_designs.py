"""`python -m benchmarks.post_designs`: one model and view, several ways to post-process its outputs.

The network runs once per frame of every set; each design then selects the detections from the same
raw outputs, and is scored with `fishloc eval`'s metrics on every set given (the real check frames
and the renders together). A design's free parameter (its threshold, or one per part of the view)
is chosen on the `--choose` set alone, the validation renders: the real frames only judge.

- `hard`: the service's own selection (`contract.select_detections`) at the view's operating point.
- `soft-gauss:S`, `soft-linear:T`: Soft-NMS (Bodla et al., 2017) in place of the rotated NMS: each
  kept box lowers the scores of the boxes it overlaps (by exp(−IoU²/S), or by 1 − IoU above IoU T)
  instead of removing them, after an NMS in input px at IoU 0.7 that merges a cell's near copies;
  the threshold of best F1 on `--choose`.
- `parts`: each part of a planned view (the nadir view, each band) its own threshold, chosen by
  coordinate ascent on F1 over `PART_GRID` on `--choose`, at the view's NMS IoU: a part's raw scores
  are mapped piecewise-linearly so that its threshold lands on the view's (a monotone rescale, so
  the view's one threshold and AP's ranking then see every part alike).

The figures of docs/DETECTOR.md's "Post-processing designs" come from:

    python -m benchmarks.post_designs --model runs/v072.onnx --choose data/val1024/annotations.json \\
        --data lunch3=../shared/real-frames/cepdof_lunch3.json \\
        --data scenes4=../shared/real-frames/scenes4.json \\
        --data unseen=data/unseen1024/annotations.json [--max-view-pixels 4000000] --json post.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.view_designs import FIGURES, cell
from contract import (
    FrameDetections,
    InputMapping,
    ModelError,
    ModelRunner,
    OnnxModel,
    OperatingPoint,
    RawOutputs,
    SessionThreads,
)
from contract.detect import FrameOutputs, frame_candidates, select_detections
from contract.views import DEFAULT_VIEW, PlannedInput, mapping_layout
from fisheye.rotated import rotated_iou

FloatArray = NDArray[np.float64]
FLOOR = 0.05  # every detection from this score is kept for AP, as `fishloc eval` keeps them
PRE_NMS_IOU = 0.7  # Soft-NMS's first, hard step in input px: a person's cells' near copies
PART_GRID = tuple(np.round(np.arange(0.10, 0.80, 0.02), 2))
Selector = Callable[[FrameOutputs], FrameDetections]
PointOf = Callable[[InputMapping], OperatingPoint]  # the operating point of a frame's view


@dataclasses.dataclass(frozen=True)
class Scored:
    """Frames of one set with the raw outputs of their view."""

    frames: list[Any]
    outputs: list[FrameOutputs]


def soft_nms(boxes: FloatArray, scores: FloatArray, principal_point: tuple[float, float], kind: str,
             parameter: float, floor: float) -> tuple[NDArray[np.int64], FloatArray]:
    """Indices of the radius-aligned `boxes` (N, 4) kept by Soft-NMS, best first, and their decayed
    scores: the best box left is kept and every box left loses score by its rotated IoU with it
    (`kind` "gauss": × exp(−IoU²/`parameter`); "linear": × (1 − IoU) above IoU `parameter`), until
    no box left scores `floor`."""
    iou = rotated_iou(boxes, boxes, principal_point) if len(boxes) else np.zeros((0, 0))
    left, decayed = np.ones(len(scores), dtype=bool), np.asarray(scores, dtype=np.float64).copy()
    keep: list[int] = []
    while left.any():
        best = int(np.argmax(np.where(left, decayed, -np.inf)))
        if decayed[best] < floor:
            break
        keep.append(best)
        left[best] = False
        overlap = iou[best]
        factor = (np.exp(-overlap ** 2 / parameter) if kind == "gauss"
                  else np.where(overlap > parameter, 1.0 - overlap, 1.0))
        decayed = np.where(left, decayed * factor, decayed)
    kept = np.asarray(keep, dtype=np.int64)
    return kept, decayed[kept]


def soft_selector(kind: str, parameter: float) -> Selector:
    """Detections by Soft-NMS (`soft_nms`) from score `FLOOR`: the candidates of the view, their
    feet fused as the service fuses them, at most 300."""

    def select(out: FrameOutputs) -> FrameDetections:
        found = frame_candidates(out.raw, out.mapping, out.principal_point, FLOOR, PRE_NMS_IOU)
        pp = out.principal_point
        chosen, decayed = soft_nms(found.boxes_cxcywh, found.scores, pp, kind, parameter, FLOOR)
        chosen, decayed = chosen[:300], decayed[:300]
        return FrameDetections(found.boxes_cxcywh[chosen], decayed, pp,
                               None if found.foot_px is None else found.foot_px[chosen])

    return select


def part_of(raw: RawOutputs, mapping: InputMapping) -> NDArray[np.int64]:
    """(N,) each output's part of its view: 0 the nadir view, 1 + k band k (a fixed view: all 1)."""
    if not isinstance(mapping, PlannedInput):
        return np.ones(len(raw.scores), dtype=np.int64)
    return mapping.parts(raw.boxes)


def rescaled(scores: NDArray[np.floating], own: FloatArray, threshold: float) -> FloatArray:
    """Scores (N,) mapped piecewise-linearly through (0, 0), (`own`, `threshold`), (1, 1), where
    `own` (N,) is each score's part's threshold."""
    s = np.asarray(scores, dtype=np.float64)
    return np.where(s < own, s * threshold / own, threshold + (s - own) * (1 - threshold) / (1 - own))


def parts_selector(thresholds: Sequence[float], point: PointOf) -> Selector:
    """Detections with each part's threshold (`thresholds[part]`, `part_of`) mapped onto the view's
    (`point(mapping)`), by the service's own selection at the view's NMS IoU."""

    def select(out: FrameOutputs) -> FrameDetections:
        view = point(out.mapping)
        own = np.asarray(thresholds, dtype=np.float64)[part_of(out.raw, out.mapping)]
        scores = rescaled(out.raw.scores, own, view.min_score).astype(np.float32)
        raw = dataclasses.replace(out.raw, scores=scores)
        return select_detections(raw, out.mapping, out.principal_point, FLOOR, view.nms_iou)

    return select


def hard_selector(point: PointOf) -> Selector:
    def select(out: FrameOutputs) -> FrameDetections:
        view = point(out.mapping)
        return select_detections(out.raw, out.mapping, out.principal_point, FLOOR, view.nms_iou)

    return select


def scored(selector: Selector, data: Scored, threshold: float) -> dict[str, Any]:
    """`fishloc eval`'s metrics of a selection on one set, precision and recall at `threshold`."""
    from detector.evaluate import eval_frame
    from detector.metrics import compute_metrics

    frames = [eval_frame(frame, selector(out), threshold) for frame, out in zip(data.frames, data.outputs,
                                                                                 strict=True)]
    return dict(compute_metrics(frames, threshold))


def f1(metrics: dict[str, Any]) -> float:
    precision, recall = metrics["precision"], metrics["recall"]
    return float(2 * precision * recall / max(precision + recall, 1e-9))


def best_threshold(selector: Selector, data: Scored) -> float:
    """The threshold of best F1 at IoU 0.5 on `data` (`detector.operating_point`)."""
    from detector.evaluate import eval_frame
    from detector.operating_point import best_f1_threshold

    return best_f1_threshold([eval_frame(frame, selector(out), None) for frame, out in zip(
        data.frames, data.outputs, strict=True)])


def choose_parts(data: Scored, point: PointOf, threshold: float, rounds: int = 2
                 ) -> tuple[list[float], float]:
    """Per-part thresholds of best F1 on `data` at the view's `threshold`, by coordinate ascent
    over `PART_GRID` from the view's threshold everywhere; and that F1."""
    parts = 1 + max(len(o.mapping.plan.bands) if isinstance(o.mapping, PlannedInput) else 1
                    for o in data.outputs)
    chosen = [threshold] * parts
    best = f1(scored(parts_selector(chosen, point), data, threshold))
    for _ in range(rounds):
        for part in range(parts):
            for value in PART_GRID:
                trial = [*chosen[:part], float(value), *chosen[part + 1:]]
                score = f1(scored(parts_selector(trial, point), data, threshold))
                if score > best + 1e-9:
                    best, chosen = score, trial
    return chosen, best


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.post_designs", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", required=True, help="an ONNX model of the contract")
    parser.add_argument("--choose", required=True, metavar="ANNOTATIONS",
                        help="the set each design's threshold is chosen on (validation renders)")
    parser.add_argument("--data", action="append", required=True, metavar="NAME=ANNOTATIONS",
                        help="an evaluation set (repeat): name=annotations.json")
    parser.add_argument("--design", action="append", default=None,
                        help="hard, soft-gauss:S, soft-linear:T or parts (repeat; default: hard, "
                             "soft-gauss:0.1, soft-gauss:0.3, soft-linear:0.35, parts)")
    parser.add_argument("--max-view-pixels", type=int, default=None, help="a planned model's view budget")
    parser.add_argument("--limit", type=int, default=None, help="the first N frames of each set")
    parser.add_argument("--threads", type=int, default=2, help="inference threads (default 2)")
    parser.add_argument("--json", type=Path, default=None, help="where to write every figure")
    args = parser.parse_args(argv)
    from detector.data.dataset import load_rgb
    from detector.data.readers import DatasetFormatError, read_dataset
    from detector.evaluate import frame_camera

    designs = args.design or ["hard", "soft-gauss:0.1", "soft-gauss:0.3", "soft-linear:0.35", "parts"]
    try:
        for design in designs:
            kind, _, value = design.partition(":")
            if kind in ("soft-gauss", "soft-linear"):
                if not 0 < float(value) <= 1:
                    raise ValueError(f"{design}: the parameter must lie in (0, 1]")
            elif kind not in ("hard", "parts") or value:
                raise ValueError(f"unknown design {design!r} (hard, soft-gauss:S, soft-linear:T, parts)")
        model = OnnxModel(args.model, SessionThreads(intra_op=args.threads))
        paths = {"choose": args.choose}
        for item in args.data:
            name, _, path = item.partition("=")
            if not path or name == "choose":
                raise ValueError(f"--data wants NAME=ANNOTATIONS (NAME not 'choose'), got {item!r}")
            paths[name] = path
        sets = {name: read_dataset(path)[:args.limit] for name, path in paths.items()}
    except (ModelError, DatasetFormatError, ValueError) as error:
        print(f"post_designs: {error}", file=sys.stderr)
        return 2
    view = DEFAULT_VIEW if args.max_view_pixels is None else dataclasses.replace(
        DEFAULT_VIEW, max_pixels=args.max_view_pixels)
    runner = ModelRunner(model, view=view)
    data = {name: Scored(frames, runner.outputs((load_rgb(f) for f in frames),
                                                [frame_camera(f) for f in frames]))
            for name, frames in sets.items()}

    def point(mapping: InputMapping) -> OperatingPoint:
        return model.info.point_for(mapping_layout(mapping))

    results: dict[str, dict[str, Any]] = {}
    for design in designs:
        kind, _, value = design.partition(":")
        view_threshold = point(data["choose"].outputs[0].mapping).min_score
        if kind == "hard":
            selector, threshold, extra = hard_selector(point), view_threshold, {}
        elif kind == "parts":
            chosen, _ = choose_parts(data["choose"], point, view_threshold)
            selector, threshold, extra = parts_selector(chosen, point), view_threshold, {"parts": chosen}
        else:
            selector = soft_selector(kind.removeprefix("soft-"), float(value))
            threshold, extra = best_threshold(selector, data["choose"]), {}
        by_set = {name: {k: scored(selector, d, threshold).get(k) for k in FIGURES}
                  for name, d in data.items()}
        results[design] = {"threshold": round(threshold, 3), **extra, **by_set}
        print(json.dumps({design: results[design]}), file=sys.stderr, flush=True)
    print(markdown_table(results, [name for name in data if name != "choose"]))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


def markdown_table(results: dict[str, dict[str, Any]], sets: Sequence[str]) -> str:
    """Designs as rows: the threshold, per set AP50 / precision, and AP_far / recall_nadir / mPE of
    the last set with floor positions."""
    header = ["design", "threshold", *[f"{s} AP50 / P" for s in sets], "renders AP_far / recall_nadir / mPE"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for design, row in results.items():
        cells = [design, f"{row['threshold']:.3f}", *[f"{cell(row[s]['AP50'])} / {cell(row[s]['precision'])}"
                                                      for s in sets]]
        rendered = [s for s in sets if row[s].get("mPE") is not None]
        extra = row[rendered[-1]] if rendered else {}
        cells.append(" / ".join(cell(extra.get(k)) for k in ("AP_far", "recall_nadir", "mPE")))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
