"""`python -m benchmarks.view_designs`: one model, several view designs, every evaluation set at once.

Each design is a way to build the model's input (the fixed strip, or a planned view with its
`ViewPlanConfig`); each is scored with `fishloc eval`'s metrics on every set given (the real check
frames and the renders together: a design that gains on one set and loses on the others is tuned
to a room), and the input's cost is reported beside it as the planned pixels against the trained
strip's. The figures of docs/DETECTOR.md's "Planned views" table come from this command:

    python -m benchmarks.view_designs --model models/fishloc-default.onnx \\
        --data lunch3=../shared/real-frames/cepdof_lunch3.json \\
        --data scenes4=../shared/real-frames/scenes4.json \\
        --data unseen=data/unseen1024/annotations.json --json view-designs.json

With `--choose VAL` each design runs at its own operating point, the best F1 on those validation
renders (`fishloc eval --operating-point`), rather than the one the model stores for its layout: a
view unlike the ones the points were chosen on gets a fair threshold.

With `--scale-jitter 0.9 0.95 1.05 1.1` each set is read again with each design's bands and nadir
view at those factors of their scales, at the same point, and AP50's mean, min and max over the
scales (1 among them) join the figures: on a few real frames AP50 at one scale is one draw of how
large their people come out in the input, and it swings by 0.1-0.2 from one scale to the next
(docs/DETECTOR.md, "Real frames read at several scales"). With `--rotate-jitter 4 8 12 16 20 24 28`
each set is read again with every band's turn started that many columns further round
(`ViewPlanConfig.start_columns`): the same strip rolled, the network's cells falling elsewhere on
every person; on the real sets that moves AP50 by up to 0.2, on the renders by 0.02. With both
and `--together`, every scale is read at every start (20 reads for 5 scales and 4 starts), and the
mean over all the reads is the figure heads are judged by (docs/DETECTOR.md, "The heads judged over
scales and starts together"). With `--fuse-turn COLUMNS` every read is two (`TurnFused`): the view
as planned and the view turned that many columns further round, their detections fused, so that
the network's cells fall twice on every person (test-time augmentation over the start, at twice
the cost; docs/DETECTOR.md, "Two starts fused").

The model must be a planned one (`fishloc export --planned`): the fixed strip is its one-band plan.
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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contract import FrameDetections, ModelError, ModelRunner, OnnxModel, SessionThreads
from contract.detect import ContractModel, FrameOutputs
from contract.metadata import ModelInfo, OperatingPoint
from contract.model import RawOutputs
from contract.views import DEFAULT_VIEW, view_plan
from fisheye import FisheyeCamera, rotated_nms
from fisheye.camera import MAX_SECOND_LOOK_PIXELS
from fisheye.view_plan import SECOND_LOOK_FULL_PIXELS, ViewPlanConfig

# The designs compared for 0.6.0: the trained strip, and two bands (the rim at 1.5x) with the inner
# band over the whole disc or reaching 0.6 of a standing adult past the split, or at 0.75x; then
# each view with the nadir view beside it (`fisheye.view_plan.NadirPiece`), showing 0.25, 0.3 or
# 0.35 of the image circle's radius at 1.25x to 1.95x the strip's radial scale; then the strip
# starting 0.1 or 0.2 of the radius out where the nadir view shows the disc within.
BANDS = dataclasses.replace(DEFAULT_VIEW, max_pixels=4_000_000, nadir_fraction=None)
LOOKING = dataclasses.replace(DEFAULT_VIEW, second_look_pixels=SECOND_LOOK_FULL_PIXELS)
DESIGNS: dict[str, ViewPlanConfig] = {
    "strip (one band, 1.0x)": dataclasses.replace(DEFAULT_VIEW, scales=(1.0,), nadir_fraction=None),
    "two bands 1.0x / 1.5x, inner = whole disc": dataclasses.replace(BANDS, band_margin=None),
    "two bands 1.0x / 1.5x, margin 0.6": dataclasses.replace(BANDS, band_margin=0.6),
    "two bands 0.75x / 1.5x, margin 0.6": dataclasses.replace(BANDS, scales=(0.75, 1.5), band_margin=0.6),
    **{f"strip + nadir view {shown:g} at {scale:g}x": dataclasses.replace(
        DEFAULT_VIEW, scales=(1.0,), max_pixels=4_000_000, nadir_view_fraction=shown, nadir_scale=scale)
       for shown, scale in ((0.25, 1.95), (0.3, 1.95), (0.35, 1.25), (0.35, 1.5), (0.35, 1.95))},
    **{f"two bands 1.0x / 1.5x, margin 0.6, + nadir view 0.35 at {scale:g}x": dataclasses.replace(
        BANDS, nadir_fraction=0.2, nadir_scale=scale) for scale in (1.5, 1.95)},
    # 0.6.2: with the nadir view the strip leaves it the disc within 0.1 or 0.2 of the radius
    **{f"strip from {start:g} + nadir view 0.35 at {scale:g}x": dataclasses.replace(
        DEFAULT_VIEW, scales=(1.0,), max_pixels=4_000_000, nadir_scale=scale, nadir_strip_from=start)
       for start, scale in ((0.1, 1.25), (0.1, 1.5), (0.2, 1.5))},
    # after 0.7.1: where two bands do not fit, the rim band kept at 1.5x and narrowed to fit (with
    # the nadir view) rather than one band; each at the two-band view's operating point
    **{f"rim band narrowed to fit {budget / 1e6:g}M + nadir view": dataclasses.replace(
        DEFAULT_VIEW, max_pixels=budget, min_outer_fraction=0.1) for budget in (1_400_000, 1_600_000)},
    # after 0.7.2: a middle step between the default budget and the two bands' 2.0 M px, the rim
    # band over the same radii at 1.25x where 1.5x does not fit (1.28-1.44 M px with the nadir view)
    "rim band at 1.25x (scales 1 / 1.25 / 1.5), 1.5M + nadir view": dataclasses.replace(
        DEFAULT_VIEW, scales=(1.0, 1.25, 1.5), max_pixels=1_500_000),
    # the rim band widened across the ray more than along it (`ViewPlanConfig.outer_row_scale`):
    # at the default budget a person at the rim is 27 px along the ray and 8 across
    "two bands 1.0x / 1.5x (the default at 4M) + nadir view": dataclasses.replace(
        DEFAULT_VIEW, max_pixels=4_000_000),
    **{f"rim band {across:g}x across, {along:g}x along + nadir view": dataclasses.replace(
        DEFAULT_VIEW, scales=tuple(sorted({1.0, along, across})), max_pixels=4_000_000, outer_row_scale=along)
       for across, along in ((1.5, 1.0), (2.0, 1.0), (1.5, 1.25))},
    # after 0.7.3: each band px the mean of 2 x 2 samples of the frame, decoded twice as large
    # (`ViewPlanConfig.unwrap_samples`), in the default view and with two bands
    "the default view, 2 x 2 samples a px (area-averaged)": dataclasses.replace(
        DEFAULT_VIEW, unwrap_samples=2),
    "two bands 1.0x / 1.5x + nadir view, 2 x 2 samples a px": dataclasses.replace(
        DEFAULT_VIEW, max_pixels=4_000_000, unwrap_samples=2),
    # 0.8.0: the second look (`contract.second_look`, off in every view above), its patches bounded
    # by their count alone (their px at most SECOND_LOOK_FULL_PIXELS), or within 300 000 px
    "the default view + second look": LOOKING,
    "the default view + second look within 300 000 px": dataclasses.replace(
        LOOKING, second_look_pixels=300_000),
    **{f"the default view + second look of {patches} patches at {zoom:g}x": dataclasses.replace(
        LOOKING, second_look_pixels=patches * 256 * 256, second_look_patches=patches, second_look_zoom=zoom)
       for patches, zoom in ((6, 2.0), (24, 2.0), (12, 1.5), (12, 2.5))},
    "two bands 1.0x / 1.5x + nadir view + second look": dataclasses.replace(
        DEFAULT_VIEW, max_pixels=4_000_000, second_look_pixels=SECOND_LOOK_FULL_PIXELS),
    # after 0.8.0: budgets under the default's 892 928 px, where the strip at the trained scale and
    # the nadir view do not both fit: the nadir view left out (the rule), or kept beside a strip
    # shrunk to leave it its px (`ViewPlanConfig.nadir_min_scale`)
    **{f"budget {budget // 1000}k, {way}": dataclasses.replace(
        DEFAULT_VIEW, max_pixels=budget, nadir_min_scale=keep)
       for budget in (800_000, 700_000, 600_000, 450_000, 350_000)
       for way, keep in (("no nadir view (the rule)", None), ("nadir view beside a smaller strip", 0.5))},
    # after 0.8.0: candidates longer along the ray than so many standing adults where their feet
    # stand dropped before NMS (`ViewPlanConfig.longest_person_ratio`), without and with the look
    **{f"the default view, longer than {ratio:g} adults dropped": dataclasses.replace(
        DEFAULT_VIEW, longest_person_ratio=ratio) for ratio in (1.6, 1.8, 2.0, 2.25)},
    "the default view + second look, longer than 1.8 adults dropped": dataclasses.replace(
        LOOKING, longest_person_ratio=1.8),
}
FIGURES = ("AP50", "precision", "recall", "AP_far", "recall_nadir", "mPE", "mPE_reported")
JITTERED = ("AP50", "precision")  # the figures kept of every read again (`read_again`)


@dataclass(frozen=True)
class Read:
    """One read of a set: `evaluate_design`'s figures and, where asked, whether each person was
    found at the point (`found`, the frames' people in order) and their sizes (`detector.people.size_px`)."""

    figures: dict[str, Any]
    found: list[bool]
    sizes_px: list[float]


@dataclass(frozen=True)
class NadirPair:
    """Two models as one: `strip` runs the canvas of bands (and the second look's patches), `nadir`
    the nadir view (`ContractModel.run_boxes`, the call the service makes for it alone). A head
    of its own for the nadir view, read before a graph picks its head per input."""

    strip: ContractModel
    nadir: ContractModel

    @property
    def info(self) -> ModelInfo:
        return self.strip.info

    def run(self, image: NDArray[np.uint8]) -> RawOutputs:
        return self.strip.run(image)

    def run_boxes(self, image: NDArray[np.uint8]) -> RawOutputs:
        return self.nadir.run_boxes(image)


class TurnFused:
    """`ModelRunner`'s reading of `view`, twice a frame: as planned, and with every band's turn
    started `columns` further round (`turned_view`; the nadir view is the same in both). The two
    reads' detections are fused: their union, then the rotated NMS again at the read's IoU. Every
    person falls on the network's cells at two places (test-time augmentation over the start);
    the bands cost twice their pixels."""

    def __init__(self, model: ContractModel, view: ViewPlanConfig, columns: float,
                 nms_iou: float | None = None) -> None:
        views = (view, turned_view(view, columns))
        self.runners = [ModelRunner(model, nms_iou=nms_iou, view=v) for v in views]
        self.default_min_score = self.runners[0].default_min_score

    def outputs(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera]
                ) -> list[list[FrameOutputs]]:
        """Each read's raw outputs of the frames (`ModelRunner.outputs`)."""
        return [runner.outputs(frames_rgb, cameras) for runner in self.runners]

    def select(self, outputs: Sequence[Sequence[FrameOutputs]], min_score: float, nms_iou: float | None = None
               ) -> list[FrameDetections]:
        """Each read's detections at `min_score` and `nms_iou` (default: the view's point's), fused."""
        reads = [runner.select(read, min_score, nms_iou)
                 for runner, read in zip(self.runners, outputs, strict=True)]
        return [fused(list(pair), nms_iou) for pair in zip(*reads, strict=True)]

    def detect(self, frames_rgb: Sequence[NDArray[np.uint8]], cameras: Sequence[FisheyeCamera],
               min_score: float) -> list[FrameDetections]:
        return self.select(self.outputs(frames_rgb, cameras), min_score)


def fused(reads: Sequence[FrameDetections], nms_iou: float | None) -> FrameDetections:
    """One frame's detections of several reads as one: their union, then the rotated NMS at
    `nms_iou` (default: the first read's view's point's), feet kept with their boxes."""
    first = reads[0]
    iou = nms_iou if nms_iou is not None else first.view_point.nms_iou if first.view_point else None
    if iou is None:
        raise ValueError("fusing reads needs an NMS IoU: give one or read through a view's point")
    boxes = np.concatenate([r.boxes_cxcywh for r in reads])
    scores = np.concatenate([r.scores for r in reads])
    feet = None if any(r.foot_px is None for r in reads) else np.concatenate([r.foot_px for r in reads])
    kept = rotated_nms(boxes, scores, first.principal_point, iou) if len(scores) else np.zeros(0, np.int64)
    return dataclasses.replace(first, boxes_cxcywh=boxes[kept], scores=scores[kept],
                               foot_px=None if feet is None else feet[kept])


def evaluate_design(model: ContractModel, view: ViewPlanConfig, frames: Sequence[Any],
                    point: OperatingPoint | None = None) -> dict[str, Any]:
    """`fishloc eval`'s metrics of `model` on `frames` with views planned by `view`, and the mean
    cost ratio of the plans (pixels against the trained strip); at `point` where given, else at
    the model's own point for each view's layout."""
    return read_design(model, view, frames, point).figures


def read_design(model: ContractModel, view: ViewPlanConfig, frames: Sequence[Any],
                point: OperatingPoint | None = None, people: bool = False,
                fuse_turn: float | None = None) -> Read:
    """`evaluate_design`'s read, with each person's outcome where `people` (empty otherwise); with
    `fuse_turn`, two reads fused (`TurnFused`), their cost counted twice."""
    from detector.evaluate import Predictor, RunnerPredictor, evaluate, frame_camera
    from detector.people import FOUND, breakdown, size_px

    min_score = None if point is None else point.min_score
    nms_iou = None if point is None else point.nms_iou
    predictor: Predictor = (TurnFused(model, view, fuse_turn, nms_iou) if fuse_turn is not None
                            else RunnerPredictor(ModelRunner(model, nms_iou=nms_iou, view=view)))
    evaluation = evaluate(predictor, frames, min_score=min_score)
    metrics = evaluation.metrics
    reads = 1 if fuse_turn is None else 2
    costs = [reads * view_plan(model.info, frame_camera(frame), view).cost_ratio for frame in frames]
    chosen = {} if point is None else {"min_score": point.min_score, "nms_iou": point.nms_iou}
    if fuse_turn is not None:
        chosen["fused_turn"] = fuse_turn
    figures = {**{k: metrics.get(k) for k in FIGURES}, "cost_ratio": sum(costs) / len(costs), **chosen}
    names = [str(frame.path) for frame in frames]
    persons = breakdown(evaluation.frames, names, min_score)[0] if people else []
    return Read(figures, [person.outcome == FOUND for person in persons],
                [size_px(person) for person in persons])


def read_sets(items: Sequence[str], limit: int | None) -> dict[str, list[Any]]:
    """`--data NAME=ANNOTATIONS` items -> each set's first `limit` frames by name; ValueError for an
    item without a name, DatasetFormatError for a file that cannot be read."""
    from detector.data.readers import read_dataset

    sets: dict[str, list[Any]] = {}
    for item in items:
        name, _, path = item.partition("=")
        if not name or not path:
            raise ValueError(f"--data wants NAME=ANNOTATIONS, got {item!r}")
        sets[name] = list(read_dataset(path))[:limit]
    return sets


def chosen_point(model: ContractModel, frames: Sequence[Any], view: ViewPlanConfig,
                 fuse_turn: float | None = None) -> OperatingPoint:
    """The best-F1 operating point of `model` on validation `frames` in the views `view` plans
    (`fishloc eval --operating-point`), of the two reads fused where `fuse_turn` (`TurnFused`)."""
    from detector.data.dataset import load_rgb
    from detector.evaluate import EVAL_MIN_SCORE, choose_operating_point, eval_frame, frame_camera
    from detector.operating_point import choose, sweep

    if fuse_turn is None:
        best = choose_operating_point(model, frames, view=view)[0]
        return OperatingPoint(best.min_score, best.nms_iou)
    reader = TurnFused(model, view, fuse_turn)
    outputs = reader.outputs([load_rgb(f) for f in frames], [frame_camera(f) for f in frames])
    swept = sweep(lambda nms_iou: [eval_frame(frame, found) for frame, found in
                                   zip(frames, reader.select(outputs, EVAL_MIN_SCORE, nms_iou), strict=True)])
    best = swept[choose([point for point, _ in swept])][0]
    return OperatingPoint(best.min_score, best.nms_iou)


def scaled_view(view: ViewPlanConfig, factor: float) -> ViewPlanConfig:
    """`view` with its bands and its nadir view read `factor` times as large (every person that
    much larger in the input), its budgets (the view's and the second look's) grown by factor² and
    a fifth more for the stride's rounding, so that the same layout is planned at the larger scales."""
    if factor == 1:
        return view
    grown = factor ** 2 * 1.2
    return dataclasses.replace(
        view, scales=tuple(scale * factor for scale in view.scales), nadir_scale=view.nadir_scale * factor,
        outer_row_scale=None if view.outer_row_scale is None else view.outer_row_scale * factor,
        max_pixels=math.ceil(view.max_pixels * grown),
        second_look_pixels=min(math.ceil(view.second_look_pixels * grown), MAX_SECOND_LOOK_PIXELS))


def turned_view(view: ViewPlanConfig, columns: float) -> ViewPlanConfig:
    """`view` with every band's turn started `columns` of its columns further round."""
    return dataclasses.replace(view, start_columns=view.start_columns + columns)


def design_figures(design: str, model: ContractModel, view: ViewPlanConfig, sets: dict[str, list[Any]],
                   choose_on: Sequence[Any] | None, jitter: Sequence[float] = (),
                   rotations: Sequence[float] = (), together: bool = False,
                   fuse_turn: float | None = None) -> dict[str, dict[str, Any]]:
    """`evaluate_design` on every set, at the point chosen on `choose_on` (None: the model's own for
    each layout); the figures also go to stderr as one JSON line as soon as they are made. With
    `jitter`, each set is read again at each of those scale factors (`scaled_view`) at the same
    point, and its figures gain `AP50_by_scale` and `precision_by_scale` (factor 1 among them) and
    their mean, min and max (`AP50_over_scales`, `precision_over_scales`); with `rotations`, read
    again with every band's turn started that many columns further round (`start_columns`), the
    same as `..._by_rotation` (0 among them) and `..._over_rotations`. With `together`, every scale
    is read at every start instead, each pair once (`..._by_read`, keyed "1.1x+8", and
    `..._over_reads`): the two draws of where a person falls in the cells, taken at once. With any
    reads again, each set's `people_over_reads` counts the people found in every read, in none and
    in some (`steadiness`). With `fuse_turn`, every read is two fused (`TurnFused`), the point
    chosen so too."""
    point = None if choose_on is None else chosen_point(model, choose_on, view, fuse_turn)
    people = bool(jitter or rotations)
    served = {name: read_design(model, view, frames, point, people, fuse_turn)
              for name, frames in sets.items()}
    figures = {name: read.figures for name, read in served.items()}
    found = {name: [read.found] for name, read in served.items()}
    if together:
        read_again(model, {f"{factor:g}x+{columns:g}": turned_view(scaled_view(view, factor), columns)
                           for factor in (1, *jitter) for columns in (0, *rotations)
                           if (factor, columns) != (1, 0)}, "read", "1x+0", figures, found, sets, point,
                   fuse_turn)
    else:
        read_again(model, {f"{factor:g}": scaled_view(view, factor) for factor in jitter}, "scale", "1",
                   figures, found, sets, point, fuse_turn)
        read_again(model, {f"{columns:g}": turned_view(view, columns) for columns in rotations},
                   "rotation", "0", figures, found, sets, point, fuse_turn)
    if people:
        for name, read in served.items():
            figures[name]["people_over_reads"] = steadiness(found[name], read.sizes_px)
    print(json.dumps({design: figures}), file=sys.stderr, flush=True)
    return figures


def steadiness(found_by_read: Sequence[Sequence[bool]], sizes_px: Sequence[float]
               ) -> dict[str, dict[str, int]]:
    """How many people were found (at IoU 0.5, at the point) in every read, in none and in some,
    of all and of each size (`detector.people.SIZES`): which people the figures over the reads
    hinge on."""
    from detector.people import SIZES

    counts = [sum(read[person] for read in found_by_read) for person in range(len(sizes_px))]
    groups = {"all": (0.0, math.inf), **SIZES}
    steady = {}
    for group, (low, high) in groups.items():
        chosen = [count for count, size in zip(counts, sizes_px, strict=True) if low <= size < high]
        every = sum(count == len(found_by_read) for count in chosen)
        never = sum(count == 0 for count in chosen)
        steady[group] = {"people": len(chosen), "every_read": every, "no_read": never,
                         "some_reads": len(chosen) - every - never}
    return steady


def read_again(model: ContractModel, variants: dict[str, ViewPlanConfig], kind: str, served: str,
               figures: dict[str, dict[str, Any]], found: dict[str, list[list[bool]]],
               sets: dict[str, list[Any]], point: OperatingPoint | None,
               fuse_turn: float | None = None) -> None:
    """Every set read with each variant of the view at `point`: the JITTERED figures of each, by
    label, beside the served read's (`served`), into `figures[set]["<figure>_by_<kind>"]`, and
    their mean, min and max into `"<figure>_over_<kind>s"`; who each read found onto `found[set]`."""
    if not variants:
        return
    for label, view in variants.items():
        for name, frames in sets.items():
            read = read_design(model, view, frames, point, people=True, fuse_turn=fuse_turn)
            for key in JITTERED:
                by_label = figures[name].setdefault(f"{key}_by_{kind}", {served: figures[name][key]})
                by_label[label] = read.figures[key]
            found[name].append(read.found)
    for by_set in figures.values():
        for key in JITTERED:
            values = list(by_set[f"{key}_by_{kind}"].values())
            by_set[f"{key}_over_{kind}s"] = {"mean": sum(values) / len(values), "min": min(values),
                                             "max": max(values)}


def report(results: dict[str, dict[str, dict[str, Any]]], json_path: Path | None) -> None:
    """The designs' table on stdout and, where asked, every figure as JSON."""
    print(markdown_table(results))
    if json_path is not None:
        json_path.write_text(json.dumps(results, indent=2) + "\n")


def cell(value: Any) -> str:
    return "–" if value is None or value != value else f"{value:.3f}"


def over_reads(summary: dict[str, float] | None) -> str:
    return "–" if summary is None else (
        f"{cell(summary['mean'])} [{cell(summary['min'])}, {cell(summary['max'])}]")


def steady_cell(steady: dict[str, dict[str, int]] | None) -> str:
    if steady is None:
        return "–"
    counts = steady["all"]
    return f"{counts['every_read']} / {counts['no_read']} / {counts['some_reads']} of {counts['people']}"


def markdown_table(results: dict[str, dict[str, dict[str, Any]]]) -> str:
    """Designs as rows (with the operating point each was chosen, where it was); per set AP50 /
    precision (and AP_far, recall_nadir, mPE where the set has floor positions), and the cost
    ratio of the first set's plans; where sets were read again, the figures over the reads and the
    people found in every read, in none and in some."""
    sets = list(next(iter(results.values())))
    header = ["design", *[f"{s} AP50 / P" for s in sets], "renders AP_far / recall_nadir / mPE", "cost"]
    kinds = [kind for kind in ("scales", "rotations", "reads")
             if any(f"AP50_over_{kind}" in by_set[s] for by_set in results.values() for s in sets)]
    header += [f"{s} AP50 over {kind}: mean [min, max] / P mean" for kind in kinds for s in sets]
    if kinds:
        header += [f"{s} people found in every / no / some read" for s in sets]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for design, by_set in results.items():
        first = by_set[sets[0]]
        name = design if "min_score" not in first else (
            f"{design} (at {first['min_score']:g} / NMS {first['nms_iou']:g})")
        cells = [name, *[f"{cell(by_set[s]['AP50'])} / {cell(by_set[s]['precision'])}" for s in sets]]
        rendered = [s for s in sets if by_set[s].get("mPE") is not None]
        extra = by_set[rendered[-1]] if rendered else {}
        cells.append(" / ".join(cell(extra.get(k)) for k in ("AP_far", "recall_nadir", "mPE")))
        cells.append(f"{by_set[sets[0]]['cost_ratio']:.2f}x")
        cells += [f"{over_reads(by_set[s].get(f'AP50_over_{kind}'))} / "
                  f"{cell((by_set[s].get(f'precision_over_{kind}') or {}).get('mean'))}"
                  for kind in kinds for s in sets]
        if kinds:
            cells += [steady_cell(by_set[s].get("people_over_reads")) for s in sets]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def planned_model(path: str, threads: int) -> OnnxModel:
    """A planned ONNX model; ModelError for any other."""
    model = OnnxModel(path, SessionThreads(intra_op=threads))
    if not model.info.planned:
        raise ModelError(f"{path} is not a planned model (fishloc export --planned)")
    return model


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.view_designs", description=__doc__)
    parser.add_argument("--model", required=True, help="a planned ONNX model")
    parser.add_argument("--data", action="append", required=True, metavar="NAME=ANNOTATIONS",
                        help="an evaluation set (repeat): name=annotations.json")
    parser.add_argument("--limit", type=int, default=None, help="the first N frames of each set")
    parser.add_argument("--design", action="append", choices=list(DESIGNS), default=None,
                        help="only this design (repeat; default: every design)")
    parser.add_argument("--choose", type=Path, default=None, metavar="ANNOTATIONS",
                        help="validation renders on which each design gets its own operating point "
                             "(best F1 over the NMS grid, `fishloc eval --operating-point`); default: "
                             "the model's stored point for each view's layout")
    parser.add_argument("--scale-jitter", type=float, nargs="+", default=(), metavar="FACTOR",
                        help="also read every set with each design's bands and nadir view at these "
                             "factors of their scales (e.g. 0.9 0.95 1.05 1.1), at the same operating "
                             "point, and report AP50's mean, min and max over them and 1: a few real "
                             "frames' AP50 at one scale is one draw of how large their people come out")
    parser.add_argument("--rotate-jitter", type=float, nargs="+", default=(), metavar="COLUMNS",
                        help="also read every set with each band's turn started these many columns "
                             "further round (e.g. 4 8 12 16 20 24 28: the network's cells fall elsewhere "
                             "on every person, the scale unchanged), at the same point, and report AP50's "
                             "and precision's mean, min and max over them and 0")
    parser.add_argument("--together", action="store_true",
                        help="read every scale of --scale-jitter at every start of --rotate-jitter (each "
                             "pair, 1 and 0 among them) and report the mean, min and max over all the "
                             "reads, rather than over the scales and over the starts apart")
    parser.add_argument("--nadir-model", default=None, metavar="ONNX",
                        help="run the nadir view by this planned model and the rest by --model "
                             "(`NadirPair`: a head of its own for the nadir view, as two models)")
    parser.add_argument("--fuse-turn", type=float, default=None, metavar="COLUMNS",
                        help="read every frame twice, the second time with every band's turn started "
                             "COLUMNS further round, and fuse the two reads' detections (their union, "
                             "then the rotated NMS): test-time augmentation over the start, at twice "
                             "the bands' cost")
    parser.add_argument("--threads", type=int, default=2, help="inference threads (default 2)")
    parser.add_argument("--json", type=Path, default=None, help="where to write every figure")
    args = parser.parse_args(argv)
    from detector.data.readers import DatasetFormatError, read_dataset

    try:
        model: ContractModel = planned_model(args.model, args.threads)
        if args.nadir_model is not None:
            model = NadirPair(model, planned_model(args.nadir_model, args.threads))
        choose_on = None if args.choose is None else read_dataset(args.choose)[:args.limit]
        sets = read_sets(args.data, args.limit)
        if any(not 0.5 <= factor <= 2 or factor == 1 for factor in args.scale_jitter):
            raise ValueError(f"--scale-jitter factors must lie in [0.5, 2] and differ from 1, got "
                             f"{args.scale_jitter}")
        if any(not 0 < columns < 2048 for columns in args.rotate_jitter):
            raise ValueError(f"--rotate-jitter columns must lie in (0, 2048), got {args.rotate_jitter}")
        if args.together and not (args.scale_jitter and args.rotate_jitter):
            raise ValueError("--together reads scales at starts: give --scale-jitter and --rotate-jitter")
        if args.fuse_turn is not None and not 0 < args.fuse_turn < 2048:
            raise ValueError(f"--fuse-turn columns must lie in (0, 2048), got {args.fuse_turn}")
    except (ModelError, DatasetFormatError, ValueError) as error:
        print(f"view_designs: {error}", file=sys.stderr)
        return 2
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for design, view in DESIGNS.items():
        if args.design is not None and design not in args.design:
            continue
        results[design] = design_figures(design, model, view, sets, choose_on, args.scale_jitter,
                                         args.rotate_jitter, args.together, args.fuse_turn)
    report(results, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
