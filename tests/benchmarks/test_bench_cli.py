"""A tiny `fishloc bench` run, end to end: a real `fishloc serve` subprocess with the test-double
model, real HTTP clients, the JSON report and the budget's exit code. No assertion on timings."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from benchmarks.frames import FrameSpec, make_frames
from benchmarks.machine import cpu_model_name
from benchmarks.report import EXIT_OK, EXIT_OVER_BUDGET, budget_verdict, check_report
from service.cli import main


@pytest.fixture(scope="module")
def small_frames(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_frames(FrameSpec(size=256, count=2), tmp_path_factory.mktemp("frames"))


def test_tiny_bench_run_writes_its_report(double_model_path: Path, small_frames: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report.json"
    code = main([
        "bench", "--model", str(double_model_path), "--frames", str(small_frames), "--runs", "4",
        "--warmup", "1", "--clients", "2", "--threads", "1", "--streams", "2", "--fps", "4",
        "--duration", "1.5", "--stream-warmup", "0.5", "--budget-ms", "0.001", "--json", str(out),
    ])
    # No real frame is answered in 1 µs: the budget check must fail the run.
    assert code == EXIT_OVER_BUDGET
    report = json.loads(out.read_text(encoding="utf-8"))
    assert check_report(report) == []
    assert report["model"]["name"] == "plumbing-double" and report["model"]["input_size"] == 256
    assert report["frames"]["count"] == 2 and report["frames"]["width"] == 256
    sections = report["sections"]
    in_process = sections["in_process"]
    assert in_process["available"] and in_process["stages_ms"]["decode"]["n"] == 4
    # The double finds no bright blob in these frames, only its three constant boxes: one survives
    # the threshold and NMS, as in the service tests.
    assert in_process["detections_per_frame"] == 1.0
    assert in_process["decode_reduction"] == 1 and in_process["decoded_wh"] == [256, 256]  # 256 px input
    http = sections["http"]
    assert http["available"]
    assert http["single"]["ok"] == 4 and http["single"]["errors"] == 0
    assert http["concurrent"]["clients"] == 2 and http["concurrent"]["requests"] == 4
    assert http["concurrent"]["ok"] + http["concurrent"]["overloaded_503"] == 4
    grpc = sections["grpc"]
    if grpc["available"]:
        assert grpc["cameras"] == 2 and grpc["sent"] == grpc["ok"] + grpc["dropped"] + grpc["errors"]
    else:
        assert "gRPC" in grpc["reason"]
    assert report["budget"]["passed"] is False
    assert budget_verdict(report, 1e9).exit_code == EXIT_OK
    printed = capsys.readouterr().out
    assert "| HTTP, 1 client |" in printed and str(out) in printed


def test_bench_refuses_a_missing_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["bench", "--model", str(tmp_path / "none.onnx"), "--frames", str(tmp_path),
                 "--json", str(tmp_path / "r.json")])
    assert code == 2 and not (tmp_path / "r.json").exists()
    assert "fishloc bench:" in capsys.readouterr().err


def test_cpu_model_name_from_cpuinfo() -> None:
    text = "processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7B13 64-Core Processor\n"
    assert cpu_model_name(text) == "AMD EPYC 7B13 64-Core Processor"
    assert cpu_model_name("Hardware\t: BCM2835\n") == "BCM2835"


def _recorded_runs(monkeypatch: pytest.MonkeyPatch, model: Any, method: str) -> list[tuple[int, ...]]:
    """The input shapes of every call of `model`'s `method` (`run` or `run_boxes`) from now on."""
    shapes: list[tuple[int, ...]] = []
    call = getattr(model, method)

    def recorded(image: Any) -> Any:
        shapes.append(image.shape)
        return call(image)

    monkeypatch.setattr(model, method, recorded)
    return shapes


def test_the_staged_and_naive_paths_see_the_view_the_service_plans(monkeypatch: pytest.MonkeyPatch) -> None:
    # With a budget that has room for the nadir view, the stage-by-stage timing and the naive
    # pipeline run it too, and find what `Pipeline.detect` finds.
    import numpy as np

    from benchmarks.inprocess import NaivePipeline, service_pipeline, staged_detect
    from fisheye import load_camera
    from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH

    monkeypatch.setenv("FISHLOC_MAX_VIEW_PIXELS", "1000000")
    pipeline = service_pipeline(DEFAULT_MODEL_PATH, 1)
    camera = load_camera(DEMO_CAMERA_PATH)
    data = (Path(__file__).resolve().parents[2] / "samples" / "000001.jpg").read_bytes()
    images, _, frame_camera = NaivePipeline.full_decode_input(data, pipeline, camera)
    plan = pipeline.plan(frame_camera)
    assert plan is not None and plan.nadir is not None and len(images) == 2
    threshold = pipeline.info.default_min_score
    nadir_runs = _recorded_runs(monkeypatch, pipeline.model, "run_boxes")
    _, staged = staged_detect(pipeline, data, camera, threshold)
    assert nadir_runs == [(plan.nadir.side, plan.nadir.side, 3)]  # the stages ran the nadir view
    served = pipeline.detect(data, camera, min_score=threshold).detections
    np.testing.assert_allclose(staged.cxcywh, served.cxcywh, atol=1e-6)
    naive = NaivePipeline(DEFAULT_MODEL_PATH, pipeline, camera).detect(data, threshold)
    assert len(naive.scores) >= len(served.scores) - 1  # full decode, box-side feet: nearly the same people


def test_the_staged_path_runs_the_second_look_as_the_service_does(monkeypatch: pytest.MonkeyPatch) -> None:
    # With the look on, the stage-by-stage timing runs the patches' canvas as `Pipeline.detect` does
    # (the same runs of the model, the same people) and counts it as inference.
    import numpy as np

    from benchmarks.inprocess import look_canvas, service_pipeline, staged_detect
    from fisheye import load_camera
    from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH

    monkeypatch.setenv("FISHLOC_SECOND_LOOK", "786432")
    pipeline = service_pipeline(DEFAULT_MODEL_PATH, 1)
    camera = load_camera(DEMO_CAMERA_PATH)
    data = (Path(__file__).resolve().parents[2] / "samples" / "000001.jpg").read_bytes()
    plan = pipeline.plan(camera.scaled_to((2048, 2048)))  # the sample frame's size
    assert plan is not None and plan.layout.endswith("+look")
    threshold = pipeline.point(plan.layout).min_score
    runs = _recorded_runs(monkeypatch, pipeline.model, "run")
    times, staged = staged_detect(pipeline, data, camera, threshold)
    staged_runs, runs[:] = list(runs), []
    served = pipeline.detect(data, camera, min_score=threshold).detections
    assert len(staged_runs) == 2 and staged_runs == runs  # the strip, then the patches' canvas
    np.testing.assert_allclose(staged.cxcywh, served.cxcywh, atol=1e-6)
    assert times["postprocess"] == 0.0 and times["inference"] > 0
    # the floor times the same canvas beside the view's inputs; a view without the look has none
    canvas = look_canvas(pipeline, data, camera)
    assert canvas is not None and canvas.shape == runs[1]
    monkeypatch.setenv("FISHLOC_SECOND_LOOK", "0")
    assert look_canvas(service_pipeline(DEFAULT_MODEL_PATH, 1), data, camera) is None
