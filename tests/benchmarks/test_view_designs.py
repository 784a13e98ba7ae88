"""`python -m benchmarks.view_designs`: every design on every set, through the real evaluation."""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "contract"))

from polar_double import save_polar_double

from benchmarks.view_designs import (
    DESIGNS,
    NadirPair,
    Read,
    fused,
    main,
    markdown_table,
    read_design,
    scaled_view,
    steadiness,
    turned_view,
)
from detector.people import SIZES
from fisheye import load_camera
from fisheye.view_plan import ViewPlanConfig, plan_view

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


def test_a_scaled_view_plans_the_same_layout_with_every_person_larger() -> None:
    camera = load_camera(ROOT / "models" / "demo_camera.yaml")
    view = DESIGNS["strip + nadir view 0.35 at 1.25x"]
    assert scaled_view(view, 1.0) == view
    plain = plan_view(camera, config=view)
    for factor in (0.9, 1.1):
        scaled = plan_view(camera, config=scaled_view(view, factor))
        assert scaled.layout == plain.layout == "1band+nadir"
        assert [b.scale for b in scaled.bands] == pytest.approx([b.scale * factor for b in plain.bands])
        assert scaled.nadir is not None and plain.nadir is not None
        assert scaled.nadir.half_px == plain.nadir.half_px  # the same disc, read at another size
        assert (scaled.nadir.side > plain.nadir.side) == (factor > 1)
    # two bands keep their two bands, each scaled
    bands = DESIGNS["two bands 1.0x / 1.5x, margin 0.6"]
    wide = plan_view(camera, config=scaled_view(bands, 1.1))
    assert [b.scale for b in wide.bands] == pytest.approx([1.1, 1.65])
    # the second look's patches grow with their bands, and so does its budget
    looking = DESIGNS["the default view + second look"]
    assert scaled_view(looking, 1.1).second_look_pixels > looking.second_look_pixels


JITTERED_DESIGN = "strip + nadir view 0.35 at 1.25x"


def read_jittered(tmp_path: Path, *jitter: str
                  ) -> tuple[Path, dict[str, Any], Callable[[ViewPlanConfig], Read]]:
    """The toy planned model, its figures on two sample frames read with `jitter`'s options, and
    `read_design` of a view of it on the same frames, with who it found."""
    from contract import OnnxModel, SessionThreads
    from detector.data.readers import read_dataset

    model = save_polar_double(tmp_path / "planned.onnx", planned=True)
    out = tmp_path / "designs.json"
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(model), "--data", f"samples={samples}", "--design", JITTERED_DESIGN,
                 "--limit", "2", "--threads", "1", *jitter, "--json", str(out)]) == 0
    onnx = OnnxModel(model, SessionThreads(intra_op=1))
    frames = read_dataset(samples)[:2]
    return model, json.loads(out.read_text())[JITTERED_DESIGN]["samples"], (
        lambda view: read_design(onnx, view, frames, people=True))


def test_scale_jitter_reads_every_set_again_at_each_factor(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    model, figures, evaluated = read_jittered(tmp_path, "--scale-jitter", "0.9", "1.1")
    by_scale = figures["AP50_by_scale"]
    assert list(by_scale) == ["1", "0.9", "1.1"] and by_scale["1"] == figures["AP50"]
    read = evaluated(scaled_view(DESIGNS[JITTERED_DESIGN], 0.9)).figures
    assert by_scale["0.9"] == read["AP50"] and figures["precision_by_scale"]["0.9"] == read["precision"]
    assert figures["precision_by_scale"]["1"] == figures["precision"]
    summary = figures["AP50_over_scales"]
    assert summary["min"] == min(by_scale.values()) and summary["max"] == max(by_scale.values())
    assert summary["mean"] == pytest.approx(sum(by_scale.values()) / 3)
    assert "samples AP50 over scales: mean [min, max] / P mean" in capsys.readouterr().out
    # a factor of 1 (always read) or outside [0.5, 2] is refused
    samples = ROOT / "samples" / "annotations.json"
    for bad in ("1", "3"):
        assert main(["--model", str(model), "--data", f"samples={samples}", "--scale-jitter", bad]) == 2
    assert "--scale-jitter" in capsys.readouterr().err


def test_rotate_jitter_reads_every_set_again_with_the_turn_started_further_round(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model, figures, evaluated = read_jittered(tmp_path, "--rotate-jitter", "8", "16")
    assert list(figures["AP50_by_rotation"]) == ["0", "8", "16"]
    assert figures["AP50_by_rotation"]["0"] == figures["AP50"] and "AP50_by_scale" not in figures
    read = evaluated(dataclasses.replace(DESIGNS[JITTERED_DESIGN], start_columns=16)).figures
    assert figures["AP50_by_rotation"]["16"] == read["AP50"]
    assert figures["precision_by_rotation"]["16"] == read["precision"]
    summary = figures["precision_over_rotations"]
    assert summary["min"] <= summary["mean"] <= summary["max"]
    assert "samples AP50 over rotations: mean [min, max] / P mean" in capsys.readouterr().out
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(model), "--data", f"samples={samples}", "--rotate-jitter", "0"]) == 2
    assert "--rotate-jitter" in capsys.readouterr().err


def test_together_reads_every_scale_at_every_start(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    model, figures, evaluated = read_jittered(tmp_path, "--scale-jitter", "0.9", "--rotate-jitter", "16",
                                              "--together")
    by_read = figures["AP50_by_read"]
    assert list(by_read) == ["1x+0", "1x+16", "0.9x+0", "0.9x+16"] and by_read["1x+0"] == figures["AP50"]
    assert "AP50_by_scale" not in figures and "AP50_by_rotation" not in figures
    both = evaluated(turned_view(scaled_view(DESIGNS[JITTERED_DESIGN], 0.9), 16)).figures
    assert by_read["0.9x+16"] == both["AP50"] and figures["precision_by_read"]["0.9x+16"] == both["precision"]
    assert figures["AP50_over_reads"]["mean"] == pytest.approx(sum(by_read.values()) / 4)
    # who was found in every read, in none, in some
    design = DESIGNS[JITTERED_DESIGN]
    reads = [evaluated(turned_view(scaled_view(design, factor), columns)).found
             for factor in (1, 0.9) for columns in (0, 16)]
    people = figures["people_over_reads"]["all"]
    assert people["people"] == len(reads[0]) > 0
    assert people["every_read"] == sum(all(read[i] for read in reads) for i in range(len(reads[0])))
    assert people["no_read"] == sum(not any(read[i] for read in reads) for i in range(len(reads[0])))
    assert people["every_read"] + people["no_read"] + people["some_reads"] == people["people"]
    assert sum(figures["people_over_reads"][size]["people"] for size in SIZES) == people["people"]
    assert "samples AP50 over reads: mean [min, max] / P mean" in capsys.readouterr().out
    # together wants both draws
    samples = ROOT / "samples" / "annotations.json"
    assert main(["--model", str(model), "--data", f"samples={samples}", "--scale-jitter", "0.9",
                 "--together"]) == 2
    assert "--together" in capsys.readouterr().err


def test_steadiness_counts_who_each_read_found_by_size() -> None:
    # three people, small, medium and large, over two reads: found in both, in neither, in one
    steady = steadiness([[True, False, True], [True, False, False]], [30.0, 60.0, 120.0])
    assert steady["all"] == {"people": 3, "every_read": 1, "no_read": 1, "some_reads": 1}
    assert steady["small"] == {"people": 1, "every_read": 1, "no_read": 0, "some_reads": 0}
    assert steady["medium"]["no_read"] == 1 and steady["large"]["some_reads"] == 1


def test_a_nadir_pair_runs_the_nadir_view_by_its_second_model(tmp_path: Path) -> None:
    from contract import OnnxModel, SessionThreads

    strip = OnnxModel(save_polar_double(tmp_path / "strip.onnx", planned=True, score=0.9), SessionThreads(1))
    nadir = OnnxModel(save_polar_double(tmp_path / "nadir.onnx", planned=True, score=0.4), SessionThreads(1))
    pair = NadirPair(strip, nadir)
    image = np.zeros((64, 96, 3), np.uint8)
    image[20:30, 40:50] = 255  # one bright person for the double to box
    assert pair.info == strip.info
    assert pair.run(image).scores[0] == pytest.approx(0.9, abs=1e-3)  # the canvas of bands: the strip's model
    assert pair.run_boxes(image).scores[0] == pytest.approx(0.4, abs=1e-3)  # the nadir view: its own
    # read through the service's runner, the nadir view's people take the second model's scores
    samples = ROOT / "samples" / "annotations.json"
    out, paired = tmp_path / "alone.json", tmp_path / "paired.json"
    common = ["--data", f"samples={samples}", "--limit", "1", "--threads", "1",
              "--design", "strip + nadir view 0.35 at 1.25x"]
    assert main(["--model", str(tmp_path / "strip.onnx"), *common, "--json", str(out)]) == 0
    assert main(["--model", str(tmp_path / "strip.onnx"), "--nadir-model", str(tmp_path / "strip.onnx"),
                 *common, "--json", str(paired)]) == 0
    assert json.loads(out.read_text()) == json.loads(paired.read_text())


def test_fused_reads_keep_each_person_once_at_the_better_score_with_its_feet() -> None:
    from contract import FrameDetections
    from contract.metadata import OperatingPoint

    point = OperatingPoint(0.3, 0.4)
    # one person seen by both reads (boxes 2 px apart), and one more person in each read alone
    centre = (512.0, 512.0)
    first = FrameDetections(np.array([[400.0, 300.0, 20.0, 40.0], [700.0, 500.0, 20.0, 40.0]]),
                            np.array([0.9, 0.5]), centre, np.array([[400.0, 320.0], [700.0, 480.0]]), point)
    second = FrameDetections(np.array([[402.0, 300.0, 20.0, 40.0], [200.0, 600.0, 20.0, 40.0]]),
                             np.array([0.95, 0.4]), centre, np.array([[402.0, 321.0], [200.0, 590.0]]), point)
    both = fused([first, second], None)  # at the reads' own IoU
    assert both.scores.tolist() == [0.95, 0.5, 0.4]
    assert both.boxes_cxcywh[0].tolist() == [402.0, 300.0, 20.0, 40.0]
    assert both.foot_px is not None
    assert both.foot_px.tolist() == [[402.0, 321.0], [700.0, 480.0], [200.0, 590.0]]
    assert both.view_point == point
    # an IoU of 0.99 keeps the two boxes of the one person apart
    assert len(fused([first, second], 0.99).scores) == 4
    without_feet = dataclasses.replace(second, foot_px=None)
    assert fused([first, without_feet], None).foot_px is None


def test_two_reads_fused_at_one_start_read_as_one_at_twice_the_cost() -> None:
    from contract import OnnxModel, SessionThreads
    from detector.data.readers import read_dataset

    model = OnnxModel(ROOT / "models" / "fishloc-default.onnx", SessionThreads(intra_op=1))  # finds people
    frames = read_dataset(ROOT / "samples" / "annotations.json")[:2]
    view = DESIGNS[JITTERED_DESIGN]
    once = read_design(model, view, frames).figures
    twice = read_design(model, view, frames, fuse_turn=0.0).figures
    assert once["AP50"] > 0.0  # people found, so that the fusion has something to keep or lose
    keys = ("AP50", "precision", "recall", "AP_far", "mPE")
    np.testing.assert_array_equal([twice[key] for key in keys], [once[key] for key in keys])  # NaN alike
    assert twice["cost_ratio"] == pytest.approx(2 * once["cost_ratio"])
    assert twice["fused_turn"] == 0.0 and "fused_turn" not in once


def test_fuse_turn_reads_every_set_twice_at_a_point_chosen_fused(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    model = save_polar_double(tmp_path / "planned.onnx", planned=True)
    out = tmp_path / "fused.json"
    samples = ROOT / "samples" / "annotations.json"
    common = ["--model", str(model), "--data", f"samples={samples}", "--design", JITTERED_DESIGN,
              "--limit", "2", "--threads", "1"]
    assert main([*common, "--choose", str(samples), "--fuse-turn", "8", "--json", str(out)]) == 0
    figures = json.loads(out.read_text())[JITTERED_DESIGN]["samples"]
    assert figures["fused_turn"] == 8 and 0.0 <= figures["AP50"] <= 1.0
    assert {"min_score", "nms_iou"} <= set(figures)
    assert main([*common, "--fuse-turn", "0"]) == 2
    assert "--fuse-turn" in capsys.readouterr().err


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
