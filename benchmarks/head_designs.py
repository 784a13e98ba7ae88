"""`python -m benchmarks.head_designs`: one checkpoint, several ways to read its network without training.

Each design changes how the trained network turns features into people, with no weight trained; it
runs in torch (the numbers of the graph `fishloc export` writes), at its own operating point, the
best F1 on the `--choose` set (the validation renders: `fishloc eval --operating-point`), and is
scored with `fishloc eval`'s metrics on every set given (the real check frames and the renders
together). The designs:

- `as-trained`: the checkpoint as it is (its own head, its foot refiner's trained passes).
- `logits:B`, `geometric:B`, `mean:B`: an output ensemble of the fine-tuned head and the COCO head it
  started from (`--pretrained`), both on the same neck features. The boxes and feet are the fine-tuned
  head's; the person score combines the two heads' as B·fine-tuned + (1 − B)·COCO of the objectness
  and class logits (`logits`), as their weighted geometric mean (`geometric`) or as their weighted
  mean (`mean`) of the two heads' person probabilities. WiSE-FT (`detector/yolox/wise.py`) mixes the
  two heads in weight space instead; the ensemble costs a second head per level.
- `coco:PARTS`: the fine-tuned head with the parts named (`+`-joined, of HEAD_PARTS: e.g.
  `cls_convs+cls_preds`, the class branch, which YOLOX multiplies with the box branch's objectness)
  put back to the COCO head's weights, every other weight as trained: a graft, at no cost.
- `foot-passes:N`: the foot refiner run N times, each pass about the previous pass's point.

The figures of docs/DETECTOR.md's "The trained head read otherwise" come from:

    python -m benchmarks.head_designs --checkpoint models/fishloc-default.pt \\
        --choose data/val1024/annotations.json --data lunch3=../shared/real-frames/cepdof_lunch3.json \\
        --data scenes4=../shared/real-frames/scenes4.json --data unseen=data/unseen1024/annotations.json \\
        [--max-view-pixels 4000000] --json head-designs.json
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import torch
from torch import Tensor, nn

from benchmarks.view_designs import design_figures, read_sets, report
from contract.views import DEFAULT_VIEW
from detector.yolox.head import OBJECTNESS, YoloxHead
from models import ASSETS_DIR

DEFAULT_DESIGNS = ("as-trained", "logits:0.5", "geometric:0.5", "geometric:0.7", "mean:0.5",
                   "coco:cls_preds", "coco:cls_convs+cls_preds", "coco:stems+cls_convs+cls_preds",
                   "foot-passes:2", "foot-passes:3")
COMBINATIONS = ("logits", "geometric", "mean")
HEAD_PARTS = ("stems", "cls_convs", "cls_preds", "reg_convs", "reg_preds", "obj_preds")  # `YoloxHead`'s
PROBABILITY_FLOOR = 1e-7  # person probabilities are clamped to [floor, 1 − floor] before their logit
CERTAIN_LOGIT = 30.0  # the class logit of a combined map: p(person) 1, the score is all in objectness


class EnsembleHead(nn.Module):
    """Two YOLOX heads on the same features: the maps of `tuned` with their person score combined
    with that of `other` (`combination` in COMBINATIONS, `weight` on `tuned`); the stem features a
    foot branch reads are `tuned`'s."""

    def __init__(self, tuned: YoloxHead, other: YoloxHead, combination: str, weight: float) -> None:
        super().__init__()
        if combination not in COMBINATIONS:
            raise ValueError(f"unknown combination {combination!r}; one of {', '.join(COMBINATIONS)}")
        if not 0.0 <= weight <= 1.0:
            raise ValueError(f"the fine-tuned head's weight must lie in [0, 1], got {weight}")
        if tuned.num_classes != 1 or other.num_classes != 1:
            raise ValueError("both heads must predict the person class alone")
        self.tuned, self.other = tuned, other
        self.combination, self.weight = combination, weight

    def forward(self, features: Sequence[Tensor]) -> list[Tensor]:
        return self.forward_features(features)[0]

    def forward_features(self, features: Sequence[Tensor]) -> tuple[list[Tensor], list[Tensor]]:
        maps, stem_features = self.tuned.forward_features(features)
        others, _ = self.other.forward_features(features)
        return [self._combined(own, other) for own, other in zip(maps, others, strict=True)], stem_features

    def _combined(self, own: Tensor, other: Tensor) -> Tensor:
        """(B, 6, h, w) maps of both heads -> `own`'s boxes with the combined person score."""
        w = self.weight
        if self.combination == "logits":
            scores = w * own[:, OBJECTNESS:] + (1 - w) * other[:, OBJECTNESS:]
            return torch.cat([own[:, :OBJECTNESS], scores], 1)
        p_own, p_other = person_probability(own), person_probability(other)
        floor = PROBABILITY_FLOOR
        if self.combination == "geometric":
            p = p_own.clamp_min(floor) ** w * p_other.clamp_min(floor) ** (1 - w)
        else:
            p = w * p_own + (1 - w) * p_other
        p = p.clamp(floor, 1 - floor)
        return torch.cat([own[:, :OBJECTNESS], torch.log(p / (1 - p)), torch.full_like(p, CERTAIN_LOGIT)], 1)


def person_probability(maps: Tensor) -> Tensor:
    """(B, 6, h, w) YOLOX maps of one class -> (B, 1, h, w) objectness × p(person)."""
    return torch.sigmoid(maps[:, OBJECTNESS:OBJECTNESS + 1]) * torch.sigmoid(maps[:, OBJECTNESS + 1:])


def design_module(checkpoint: Any, design: str, coco: Callable[[], nn.Module]) -> nn.Module:
    """The contract module of `checkpoint` read as `design` (module docstring), `coco` giving the COCO
    network it started from (read only for the designs that take from it); ValueError for a design
    it cannot be."""
    from detector.graph import contract_module
    from detector.yolox.network import YoloxNano

    module = contract_module(checkpoint)
    network = getattr(module, "net", None)
    if not isinstance(network, YoloxNano):
        raise ValueError("the head designs need a polar YOLOX-Nano checkpoint")
    kind, _, value = design.partition(":")
    if kind == "as-trained" and not value:
        return module
    if kind == "coco":
        parts = value.split("+")
        unknown = [part for part in parts if part not in HEAD_PARTS]
        if unknown or not value:
            raise ValueError(f"{design}: head parts are {'+'.join(HEAD_PARTS)}, got {value!r}")
        coco_state = coco().state_dict()
        state = network.state_dict()
        state.update({name: coco_state[name] for name in state
                      if name.startswith(tuple(f"head.{part}." for part in parts))})
        network.load_state_dict(state)
        return module.eval()
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"unknown design {design!r}") from None
    if kind == "foot-passes":
        if network.foot is None or network.foot.refiner is None or number != int(number) or number < 1:
            raise ValueError(f"{design}: needs a foot refiner and a whole number of passes ≥ 1")
        module.net = network.with_foot_refine_steps(int(number)).eval()
        return module
    if kind not in COMBINATIONS:
        raise ValueError(f"unknown design {design!r}")
    pretrained = coco()
    assert isinstance(pretrained, YoloxNano) and isinstance(network.head, YoloxHead)
    # it answers `forward` and `forward_features` as the head it wraps does
    network.head = cast(YoloxHead, EnsembleHead(network.head, pretrained.head, kind, number))
    return module.eval()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.head_designs", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--checkpoint", required=True, help="a polar YOLOX-Nano checkpoint (.pt)")
    parser.add_argument("--pretrained", default=str(ASSETS_DIR / "pretrained" / "yolox_nano.onnx"),
                        help="the COCO network the checkpoint started from (the ensembles' second head, "
                             "the grafts' parts)")
    parser.add_argument("--choose", type=Path, required=True, metavar="ANNOTATIONS",
                        help="validation renders on which each design gets its operating point")
    parser.add_argument("--data", action="append", required=True, metavar="NAME=ANNOTATIONS",
                        help="an evaluation set (repeat): name=annotations.json")
    parser.add_argument("--design", action="append", default=None,
                        help=f"a design (repeat; default: {' '.join(DEFAULT_DESIGNS)})")
    parser.add_argument("--max-view-pixels", type=int, default=None,
                        help="the view budget, as fishloc serve's (default: the server's default)")
    parser.add_argument("--limit", type=int, default=None, help="the first N frames of each set")
    parser.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    parser.add_argument("--json", type=Path, default=None, help="where to write every figure")
    args = parser.parse_args(argv)
    from detector.checkpoint import CheckpointError, load_checkpoint
    from detector.data.readers import DatasetFormatError, read_dataset
    from detector.evaluate import TorchContract
    from detector.graph import contract_info
    from detector.yolox.onnx_weights import PretrainedWeightsError
    from detector.yolox.polar import PolarDetectorConfig, init_network_from_pretrained

    torch.set_num_threads(args.threads)
    view = DEFAULT_VIEW if args.max_view_pixels is None else dataclasses.replace(
        DEFAULT_VIEW, max_pixels=args.max_view_pixels)
    designs = args.design or list(DEFAULT_DESIGNS)
    try:
        checkpoint = load_checkpoint(args.checkpoint)
        config = checkpoint.config
        if not isinstance(config, PolarDetectorConfig):
            raise ValueError("the head designs need a polar YOLOX-Nano checkpoint")
        # read once, shared by every design that takes from it (none changes it)
        coco = functools.cache(lambda: init_network_from_pretrained(args.pretrained, config).eval())
        modules = {design: design_module(checkpoint, design, coco) for design in designs}
        choose_on = read_dataset(args.choose)[:args.limit]
        sets = read_sets(args.data, args.limit)
    except (CheckpointError, DatasetFormatError, PretrainedWeightsError, ValueError) as error:
        print(f"head_designs: {error}", file=sys.stderr)
        return 2
    info = contract_info(checkpoint)
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for design, module in modules.items():
        results[design] = design_figures(design, TorchContract(module, info), view, sets, choose_on)
    report(results, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
