"""`python -m benchmarks.head_designs`: the trained network read other ways, without training."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from benchmarks.head_designs import EnsembleHead, design_module, main, person_probability
from detector.checkpoint import load_checkpoint
from detector.yolox.head import OBJECTNESS, YoloxHead
from detector.yolox.polar import init_network_from_pretrained

ROOT = Path(__file__).resolve().parents[2]
CHECKPOINT = ROOT / "models" / "fishloc-default.pt"
SAMPLES = ROOT / "samples" / "annotations.json"
PRETRAINED = ROOT / "models" / "pretrained" / "yolox_nano.onnx"


def _heads() -> tuple[YoloxHead, YoloxHead, list[torch.Tensor]]:
    torch.manual_seed(0)
    tuned, other = (YoloxHead(1, (8, 16), 8, depthwise=True).eval() for _ in range(2))
    for head in (tuned, other):  # scores away from the prior, so that the combinations differ
        for pred in [*head.obj_preds, *head.cls_preds]:
            torch.nn.init.normal_(pred.weight, std=1.0)
    return tuned, other, [torch.randn(1, 8, 6, 10), torch.randn(1, 16, 3, 5)]


def _geometric(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return (a * b).sqrt()


def _mean(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return (a + b) / 2


@torch.no_grad()
def test_each_combination_keeps_the_boxes_and_combines_the_scores() -> None:
    tuned, other, features = _heads()
    own, coco = tuned(features), other(features)
    for combination, expected in (("logits", None), ("geometric", _geometric), ("mean", _mean)):
        maps, stems = EnsembleHead(tuned, other, combination, 0.5).forward_features(features)
        assert [s.shape[1] for s in stems] == [8, 8]
        for got, a, b in zip(maps, own, coco, strict=True):
            torch.testing.assert_close(got[:, :OBJECTNESS], a[:, :OBJECTNESS])  # the fine-tuned boxes
            if expected is None:
                torch.testing.assert_close(got[:, OBJECTNESS:], (a[:, OBJECTNESS:] + b[:, OBJECTNESS:]) / 2)
            else:
                torch.testing.assert_close(person_probability(got), expected(person_probability(a),
                                                                              person_probability(b)))
    whole = EnsembleHead(tuned, other, "logits", 1.0)(features)  # all weight on the fine-tuned head
    for got, a in zip(whole, own, strict=True):
        torch.testing.assert_close(got, a)


@pytest.mark.parametrize(("combination", "weight", "message"), [
    ("vote", 0.5, "unknown combination"), ("mean", 1.5, "[0, 1]")])
def test_an_ensemble_that_cannot_be_is_refused(combination: str, weight: float, message: str) -> None:
    tuned, other, _ = _heads()
    with pytest.raises(ValueError, match=message.replace("[", r"\[").replace("]", r"\]")):
        EnsembleHead(tuned, other, combination, weight)


def test_a_graft_takes_the_named_parts_from_coco_and_keeps_the_rest() -> None:
    checkpoint = load_checkpoint(CHECKPOINT)
    network = init_network_from_pretrained(str(PRETRAINED), checkpoint.config)
    trained = design_module(checkpoint, "as-trained", lambda: network).state_dict()
    grafted = design_module(checkpoint, "coco:cls_convs+cls_preds", lambda: network).state_dict()
    coco = network.state_dict()
    taken = [name for name in grafted if name.startswith(("net.head.cls_convs.", "net.head.cls_preds."))]
    assert len(taken) == 30
    for name, tensor in grafted.items():
        if name in taken:
            assert torch.equal(tensor, coco[name.removeprefix("net.")])
            assert not torch.equal(tensor, trained[name]) or not tensor.is_floating_point()
        else:
            assert torch.equal(tensor, trained[name])


def test_designs_on_a_shipped_frame(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "heads.json"
    designs = ["as-trained", "logits:1", "logits:0", "foot-passes:2"]
    assert main(["--checkpoint", str(CHECKPOINT), "--choose", str(SAMPLES), "--data", f"samples={SAMPLES}",
                 "--limit", "1", "--threads", "1", "--json", str(out),
                 *[arg for design in designs for arg in ("--design", design)]]) == 0
    results = json.loads(out.read_text())
    assert list(results) == designs
    trained = results["as-trained"]["samples"]
    assert trained["AP50"] > 0.5 and trained["mPE"] < 0.5
    assert results["logits:1"]["samples"] == trained  # all weight on the fine-tuned head: the same people
    assert results["logits:0"]["samples"]["min_score"] != trained["min_score"]  # COCO's scores: another point
    passes = results["foot-passes:2"]["samples"]
    assert passes["AP50"] == trained["AP50"] and passes["mPE"] != trained["mPE"]  # the feet alone move
    table = capsys.readouterr().out
    assert table.count("\n") == len(designs) + 2 and "samples AP50 / P" in table


@pytest.mark.parametrize(("design", "message"), [
    ("vote:0.5", "unknown design"), ("logits", "unknown design"), ("foot-passes:0", "whole number"),
    ("foot-passes:1.5", "whole number"), ("mean:2", "[0, 1]"), ("coco:wings", "head parts are"),
    ("coco:", "head parts are")])
def test_a_design_that_cannot_be_is_refused(design: str, message: str, capsys: pytest.CaptureFixture[str]
                                            ) -> None:
    assert main(["--checkpoint", str(CHECKPOINT), "--choose", str(SAMPLES), "--data", f"samples={SAMPLES}",
                 "--design", design]) == 2
    assert message in capsys.readouterr().err
