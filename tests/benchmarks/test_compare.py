"""`python -m benchmarks.compare` on the shipped samples: every row evaluated and timed, one table."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.compare import main
from contract.views import DEFAULT_VIEW

ROOT = Path(__file__).resolve().parents[2]


def test_compare_table_and_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "compare.json"
    assert main(["--model", f"shipped={ROOT / 'models' / 'fishloc-default.onnx'}",
                 "--baseline", f"letterbox=letterbox:{ROOT / 'models' / 'pretrained' / 'yolox_nano.onnx'}",
                 "--data", f"samples={ROOT / 'samples' / 'annotations.json'}",
                 "--frames", str(ROOT / "samples"), "--runs", "2", "--warmup", "0",
                 "--json", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| shipped |" in table and "| letterbox |" in table and "samples AP50" in table
    record = json.loads(out.read_text())
    shipped = record["rows"]["shipped"]
    # The shipped model finds the samples' people (model card: AP50 0.74); the zero-shot letterbox
    # view of the same COCO weights barely does.
    assert shipped["metrics"]["samples"]["AP50"] > 0.5
    assert record["rows"]["letterbox"]["metrics"]["samples"]["AP50"] < shipped["metrics"]["samples"]["AP50"]
    times = shipped["times"]
    assert all(times[k] > 0 for k in ("inference_p50_ms", "e2e_p50_ms", "e2e_p95_ms"))  # measured, not judged
    assert record["rows"]["letterbox"]["times"]["inference_p50_ms"] is None


def test_rows_compare_their_feet_over_the_people_all_of_them_match(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "compare.json"
    model = ROOT / "models" / "fishloc-default.onnx"
    assert main(["--model", f"shipped={model}", "--model", f"small view={model}@300000",
                 "--data", f"samples={ROOT / 'samples' / 'annotations.json'}", "--json", str(out)]) == 0
    assert "samples mPE_common (m)" in capsys.readouterr().out
    rows = json.loads(out.read_text())["rows"]
    shipped, small = (rows[name]["metrics"]["samples"] for name in ("shipped", "small view"))
    # The smaller view matches fewer of the samples' people; both rows' feet are then compared
    # over those both match, fewer than the shipped view's own matches.
    assert small["PE_matches"] < shipped["PE_matches"]
    assert 0 < shipped["PE_matches_common"] == small["PE_matches_common"] <= small["PE_matches"]
    assert shipped["PE_matches_common"] < shipped["PE_matches"]
    assert shipped["mPE_common"] != shipped["mPE"]


def test_a_model_spec_names_the_budget_and_other_fields_of_the_plan() -> None:
    from benchmarks.compare import view_from_spec

    view = view_from_spec("1000000,nadir_scale=1.25,nadir_strip_from=0.1")
    assert view.max_pixels == 1_000_000 and view.nadir_scale == 1.25 and view.nadir_strip_from == 0.1
    assert view_from_spec("4000000").nadir_scale == DEFAULT_VIEW.nadir_scale
    without = view_from_spec("900000,second_look_patches=0")  # an integer field: the second look off
    assert without.second_look_patches == 0 and DEFAULT_VIEW.second_look_patches > 0
    for bad in ("1000000,scales=2", "1000000,size=3", "many", "900000,second_look_patches=1.5",
                "900000,max_pixels=5"):
        with pytest.raises(ValueError):
            view_from_spec(bad)


def test_a_model_spec_may_let_its_threads_spin() -> None:
    from benchmarks.compare import build_entry

    model = ROOT / "models" / "fishloc-default.onnx"
    for spec, policy in ((f"{model}", "off"), (f"{model}@900000,onnx_spinning=on", "on"),
                         (f"{model}@onnx_spinning=alone", "alone")):
        entry = build_entry("m", spec, 1)
        assert entry.predictor.runner.model.threads.spinning == policy  # type: ignore[attr-defined]
    with pytest.raises(ValueError, match="spinning"):
        build_entry("m", f"{model}@onnx_spinning=sometimes", 1)


def test_a_coco_file_read_in_windows_is_evaluated_and_timed_in_the_planned_view(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "compare.json"
    coco = ROOT / "models" / "pretrained" / "yolox_nano.onnx"
    assert main(["--baseline", f"tiled=tiled:{coco}",
                 "--baseline", f"tiled 4M=tiled:{coco}@4000000,min_score=0.4,nms_iou=0.45",
                 "--data", f"samples={ROOT / 'samples' / 'annotations.json'}",
                 "--frames", str(ROOT / "samples"), "--runs", "1", "--warmup", "0",
                 "--json", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert "| tiled 4M |" in capsys.readouterr().out
    for name in ("tiled", "tiled 4M"):
        assert 0.0 < rows[name]["metrics"]["samples"]["AP50"] <= 1.0
        assert all(rows[name]["times"][k] > 0 for k in ("inference_p50_ms", "e2e_p50_ms"))
    assert rows["tiled"]["metrics"]["samples"]["min_score"] == 0.3  # the spec's point, else 0.3
    assert rows["tiled 4M"]["metrics"]["samples"]["min_score"] == 0.4


def _two_lenses(tmp_path: Path) -> Path:
    """The samples' first frame, and the same frame at half size with its camera scaled: one set of
    two frames, each of its own size and camera."""
    import cv2

    from fisheye import camera_from_dict, camera_to_dict

    record = json.loads((ROOT / "samples" / "annotations.json").read_text())
    first = record["images"][0]
    image = cv2.imread(str(ROOT / "samples" / first["file_name"]))
    small = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(tmp_path / "large.jpg"), image)
    cv2.imwrite(str(tmp_path / "small.jpg"), small)
    camera = camera_from_dict(first["camera"])
    half = camera_to_dict(camera.scaled_to((small.shape[1], small.shape[0])))
    images = [dict(first, id=1, file_name="large.jpg"),
              dict(first, id=2, file_name="small.jpg", width=small.shape[1], height=small.shape[0],
                   camera=half)]
    path = tmp_path / "annotations.json"
    path.write_text(json.dumps({**record, "images": images, "annotations": []}))
    return path


def test_the_frames_of_a_set_are_timed_each_with_its_own_camera(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.compare import set_frames

    path = _two_lenses(tmp_path)
    frames = set_frames(str(path))
    assert [camera.image_size for _, camera in frames] == [(2048, 2048), (1024, 1024)]
    out = tmp_path / "compare.json"
    assert main(["--model", f"shipped={ROOT / 'models' / 'fishloc-default.onnx'}", "--time-on", str(path),
                 "--runs", "2", "--warmup", "0", "--json", str(out)]) == 0
    times = json.loads(out.read_text())["rows"]["shipped"]["times"]
    assert all(times[k] > 0 for k in ("inference_p50_ms", "e2e_p50_ms", "e2e_p95_ms"))  # measured, not judged
    with pytest.raises(SystemExit):  # one way to time, not both
        main(["--model", f"shipped={ROOT / 'models' / 'fishloc-default.onnx'}", "--time-on", str(path),
              "--frames", str(ROOT / "samples")])
