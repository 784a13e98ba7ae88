"""`python -m benchmarks.post_designs`: post-processing designs on one run of the network."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.post_designs import main, rescaled, soft_nms
from contract import OnnxModel, SessionThreads
from models import DEFAULT_MODEL_PATH

ROOT = Path(__file__).resolve().parents[2]
PP = (100.0, 100.0)


def test_soft_nms_lowers_an_overlapping_box_rather_than_removing_it() -> None:
    # two boxes on one ray, half overlapping, and one far away
    boxes = np.array([[150.0, 100.0, 20.0, 40.0], [160.0, 100.0, 20.0, 40.0], [100.0, 40.0, 20.0, 40.0]])
    scores = np.array([0.9, 0.8, 0.5])
    kept, decayed = soft_nms(boxes, scores, PP, "gauss", 0.5, 0.05)
    assert kept.tolist() == [0, 2, 1]  # the neighbour survives, below the far box now
    assert decayed[0] == 0.9 and decayed[1] == 0.5 and 0.05 < decayed[2] < 0.8
    kept, decayed = soft_nms(boxes, scores, PP, "linear", 0.9, 0.05)  # under IoU 0.9: untouched
    assert kept.tolist() == [0, 1, 2] and decayed.tolist() == [0.9, 0.8, 0.5]
    kept, _ = soft_nms(boxes, scores, PP, "gauss", 0.01, 0.05)  # a narrow Gaussian: hard NMS
    assert kept.tolist() == [0, 2]
    kept, decayed = soft_nms(np.zeros((0, 4)), np.zeros(0), PP, "gauss", 0.5, 0.05)
    assert len(kept) == len(decayed) == 0


def test_a_part_threshold_lands_on_the_view_threshold_and_keeps_the_order() -> None:
    scores = np.array([0.0, 0.1, 0.2, 0.5, 1.0])
    mapped = rescaled(scores, np.full(5, 0.2), 0.4)
    np.testing.assert_allclose(mapped, [0.0, 0.2, 0.4, 0.625, 1.0])
    assert np.all(np.diff(mapped) > 0)


def test_every_design_on_every_set(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # the shipped model on a shipped frame: each design finds its people from the same outputs
    samples = ROOT / "samples" / "annotations.json"
    out = tmp_path / "post.json"
    assert main(["--model", str(DEFAULT_MODEL_PATH), "--choose", str(samples), "--data", f"samples={samples}",
                 "--limit", "1", "--threads", "1", "--json", str(out)]) == 0
    results = json.loads(out.read_text())
    assert list(results) == ["hard", "soft-gauss:0.1", "soft-gauss:0.3", "soft-linear:0.35", "parts"]
    for row in results.values():
        assert row["samples"] == row["choose"]  # the same frames score the same
        assert row["samples"]["AP50"] > 0.5 and 0.0 < row["threshold"] < 1.0
        assert row["samples"]["mPE"] < 0.5
    shipped = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(1)).info
    assert results["hard"]["threshold"] == shipped.default_min_score
    assert len(results["parts"]["parts"]) == 2  # the nadir view and the strip of the default plan
    table = capsys.readouterr().out
    assert table.count("\n") == len(results) + 2 and "samples AP50 / P" in table and "choose" not in table


@pytest.mark.parametrize(("design", "message"), [("soft-gauss:0", "(0, 1]"), ("vote", "unknown design")])
def test_an_unknown_design_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], design: str,
                                      message: str) -> None:
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(tmp_path / "none.onnx"), "--choose", str(samples), "--data",
                 f"samples={samples}", "--design", design]) == 2
    assert message in capsys.readouterr().err
