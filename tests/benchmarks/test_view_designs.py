"""`python -m benchmarks.view_designs`: every design on every set, through the real evaluation."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "contract"))

from polar_double import save_polar_double

from benchmarks.view_designs import DESIGNS, main, markdown_table

ROOT = Path(__file__).resolve().parents[2]


def test_every_design_on_every_set(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = save_polar_double(tmp_path / "planned.onnx", planned=True)
    out = tmp_path / "designs.json"
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(model), "--data", f"samples={samples}", "--data", f"again={samples}",
                 "--limit", "1", "--threads", "1", "--json", str(out)]) == 0
    results = json.loads(out.read_text())
    assert list(results) == list(DESIGNS)
    for by_set in results.values():
        assert set(by_set) == {"samples", "again"}
        assert by_set["samples"] == by_set["again"]  # the same frames score the same
        assert 0.0 <= by_set["samples"]["AP50"] <= 1.0
    assert results["strip (one band, 1.0x)"]["samples"]["cost_ratio"] == pytest.approx(1.0)
    assert all(r["samples"]["cost_ratio"] > 1.0 for name, r in results.items() if "two bands" in name)
    table = capsys.readouterr().out
    assert table.count("\n") == len(DESIGNS) + 2 and "samples AP50 / P" in table  # header, rule, rows


def test_each_design_at_its_own_point_chosen_on_validation_frames(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    from contract import OnnxModel, SessionThreads
    from detector.data.readers import read_dataset
    from detector.evaluate import choose_operating_point

    model = save_polar_double(tmp_path / "planned.onnx", planned=True)
    out = tmp_path / "designs.json"
    samples = ROOT / "samples" / "annotations.json"
    design = "rim band 1.5x across, 1x along + nadir view"
    assert main(["--model", str(model), "--data", f"samples={samples}", "--choose", str(samples),
                 "--design", design, "--limit", "2", "--threads", "1", "--json", str(out)]) == 0
    figures = json.loads(out.read_text())[design]["samples"]
    best = choose_operating_point(OnnxModel(model, SessionThreads(intra_op=1)), read_dataset(samples)[:2],
                                  view=DESIGNS[design])[0]
    assert (figures["min_score"], figures["nms_iou"]) == (best.min_score, best.nms_iou)
    assert f"{design} (at {best.min_score:g} / NMS {best.nms_iou:g})" in capsys.readouterr().out


def test_a_fixed_strip_model_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = save_polar_double(tmp_path / "fixed.onnx")
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(model), "--data", f"samples={samples}"]) == 2
    assert "not a planned model" in capsys.readouterr().err


def test_markdown_table_marks_missing_figures() -> None:
    row = {"AP50": 0.5, "precision": 0.75, "recall": 0.5, "AP_far": None, "recall_nadir": None,
           "mPE": None, "cost_ratio": 2.0}
    table = markdown_table({"one": {"real": row}})
    assert "| one | 0.500 / 0.750 | – / – / – | 2.00x |" in table
