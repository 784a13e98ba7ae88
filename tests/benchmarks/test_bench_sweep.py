"""`fishloc bench sweep` over two test-double models of different input sizes, end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from service_doubles import save_double_model

from benchmarks.frames import FrameSpec, make_frames
from benchmarks.sweep import evaluate_ap50, precision_of
from service.cli import main


def test_sweep_times_every_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    small = save_double_model(tmp_path / "double-128.onnx", size=128)
    large = save_double_model(tmp_path / "double-256.onnx", size=256)
    frames = make_frames(FrameSpec(size=512, count=2), tmp_path / "frames")
    out = tmp_path / "sweep.json"
    code = main(["bench", "--frames", str(frames), "--runs", "3", "--warmup", "1", "--threads", "1",
                 "sweep", "--models", str(small), str(large), "--sweep-json", str(out)])
    assert code == 0
    report = json.loads(out.read_text(encoding="utf-8"))
    assert report["schema"] == "fishloc-bench-sweep/1"
    rows = report["rows"]
    assert [(row["input_size"], row["precision"]) for row in rows] == [(128, "fp32"), (256, "fp32")]
    for row in rows:
        assert row["pipeline_ms"]["n"] == 3 and row["inference_cpu_ms"]["n"] == 3
        assert row["ap50"] is None and row["ap50_note"] == "no --eval-data given"
    printed = capsys.readouterr().out
    assert "| double-128.onnx | 128 | fp32 |" in printed


def test_precision_and_missing_eval_set(double_model_path: Path) -> None:
    assert precision_of(double_model_path) == "fp32"
    assert evaluate_ap50(double_model_path, None) == (None, "no --eval-data given")
