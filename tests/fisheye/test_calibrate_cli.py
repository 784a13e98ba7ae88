import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from fisheye import camera_from_dict, camera_to_dict, load_camera
from fisheye.ruler_marks import marks_to_csv, simulate_ruler_marks
from service.cli import main

REPO = Path(__file__).resolve().parents[2]
TRUE = camera_from_dict({
    "id": "lobby-1", "altitude_m": 3.2, "image_size": [2952, 2952], "principal_point": [1480.3, 1469.8],
    "focal_px": [940.0, 940.0], "kb": [1.0, -0.02, 0.001],
})
K = np.array([[940.0, 0.0, 1480.3], [0.0, 940.0, 1469.8], [0.0, 0.0, 1.0]])
D = np.array([-0.02, 0.001, 0.0, 0.0])


@pytest.fixture
def marks_csv(tmp_path: Path) -> Path:
    marks = simulate_ruler_marks(TRUE, [0.0, 90.0, 180.0, 270.0], np.arange(1.0, 8.001, 1.0), noise_px=0.3,
                                 seed=2)
    path = tmp_path / "marks.csv"
    path.write_text("# four rulers, a mark every metre\n" + marks_to_csv(marks), encoding="utf-8")
    return path


def _floor_error_m(path: Path, distance_m: float = 8.0) -> float:
    camera = load_camera(path)
    phi = np.radians(np.arange(0, 360, 10))
    xy = distance_m * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return float(np.hypot(*(camera.pixels_to_floor(TRUE.floor_to_pixels(xy)) - xy).T).max())


def test_calibrate_from_marks(marks_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    output = tmp_path / "lobby-1.yaml"
    code = main(["calibrate", "--marks", str(marks_csv), "--altitude", "3.2", "--image-size", "2952", "2952",
                 "-o", str(output), "--fit-principal-point"])
    out = capsys.readouterr().out
    assert code == 0
    lines = out.splitlines()
    header = ["mark", "ruler", "u", "v", "dist_m", "fitted_m", "err_m", "pos_err_m", "err_px"]
    assert lines[0].split() == header
    assert sum(1 for line in lines if line.split() and line.split()[0].isdigit()) == 33
    assert any(line.startswith("RMS ") and " m, " in line and " px over 33 marks" in line for line in lines)
    assert "note: principal point from the nadir mark, then fitted" in out
    assert f"wrote {output}" in out
    camera = load_camera(output)
    assert camera.id == "lobby-1" and camera.image_size == (2952, 2952) and camera.kb[0] == 1.0
    assert len(camera.kb) == 3
    assert _floor_error_m(output) < 0.02


def test_calibrate_options(marks_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    output = tmp_path / "out.json"
    code = main(["calibrate", "--marks", str(marks_csv), "--altitude", "3.2", "--image-size", "2952", "2952",
                 "-o", str(output), "--id", "gate-2", "--coefficients", "4", "--focal", "900"])
    assert code == 0, capsys.readouterr().err
    record = json.loads(output.read_text(encoding="utf-8"))
    assert record["id"] == "gate-2" and record["focal_px"] == [900.0, 900.0] and len(record["kb"]) == 4
    assert record["kb"][0] == pytest.approx(940 / 900, rel=1e-3)
    assert _floor_error_m(output) < 0.05


def test_default_id_falls_back_when_the_file_name_is_no_id(marks_csv: Path, tmp_path: Path) -> None:
    output = tmp_path / "my camera.yaml"
    assert main(["calibrate", "--marks", str(marks_csv), "--altitude", "3.2", "--image-size", "2952", "2952",
                 "-o", str(output)]) == 0
    assert load_camera(output).id == "camera"


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_calibrate_from_opencv_filestorage(tmp_path: Path, suffix: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    source = tmp_path / f"kd{suffix}"
    storage = cv2.FileStorage(str(source), cv2.FILE_STORAGE_WRITE)
    storage.write("K", K)
    storage.write("D", D)
    storage.write("image_size", np.array([2952, 2952]))
    storage.release()
    output = tmp_path / "cv-1.yaml"
    assert main(["calibrate", "--opencv", str(source), "--altitude", "3.2", "-o", str(output)]) == 0
    assert "camera cv-1: 2952x2952 px" in capsys.readouterr().out
    camera = load_camera(output)
    assert camera.kb == [1.0, *D.tolist()] and camera.focal_px == (940.0, 940.0)
    assert _floor_error_m(output) < 1e-9


def test_opencv_import_scales_to_the_requested_size(tmp_path: Path) -> None:
    source = tmp_path / "kd.json"
    record = {"K": K.tolist(), "D": D.tolist(), "image_size": [2952, 2952]}
    source.write_text(json.dumps(record), encoding="utf-8")
    output = tmp_path / "half.yaml"
    assert main(["calibrate", "--opencv", str(source), "--altitude", "3.2", "--image-size", "1476", "1476",
                 "-o", str(output), "--max-theta-deg", "88"]) == 0
    camera = load_camera(output)
    assert camera.image_size == (1476, 1476) and camera.focal_px == (470.0, 470.0)
    assert camera.theta_max_deg == 88


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--image-size", "2952", "2952", "--altitude", "0"], "altitude_m"),
        (["--altitude", "3.2"], "--image-size W H is required"),
        (["--image-size", "2952", "2952", "--altitude", "3.2", "--coefficients", "7"], "coefficients"),
        (["--image-size", "100", "100", "--altitude", "3.2"], "lies outside the 100x100 image"),
        (["--image-size", "2952", "2952", "--altitude", "3.2", "--id", "no spaces"], "id"),
    ],
)
def test_refusals_exit_2_with_the_reason(marks_csv: Path, tmp_path: Path, arguments: list[str], message: str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    output = tmp_path / "out.yaml"
    assert main(["calibrate", "--marks", str(marks_csv), "-o", str(output), *arguments]) == 2
    error = capsys.readouterr().err
    assert error.startswith("fishloc calibrate: error:") and message in error
    assert not output.exists()


def test_bad_marks_file_names_the_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    marks = tmp_path / "marks.csv"
    marks.write_text("u,v,distance_m\n1476,1476,0\n1700,1476,one\n", encoding="utf-8")
    assert main(["calibrate", "--marks", str(marks), "--altitude", "3.2", "--image-size", "2952", "2952",
                 "-o", str(tmp_path / "c.yaml")]) == 2
    assert "line 3: distance_m must be a number" in capsys.readouterr().err


def test_opencv_without_a_size_needs_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = tmp_path / "kd.yaml"
    source.write_text(f"K: {K.tolist()}\nD: {D.tolist()}\n", encoding="utf-8")
    output = tmp_path / "c.yaml"
    assert main(["calibrate", "--opencv", str(source), "--altitude", "3.2", "-o", str(output)]) == 2
    assert "give --image-size" in capsys.readouterr().err


@pytest.mark.parametrize(
    "arguments",
    [
        ["--altitude", "3.2", "-o", "c.yaml"],
        ["--marks", "m.csv", "--opencv", "k.yaml", "--altitude", "3.2", "-o", "c.yaml"],
        ["--marks", "m.csv", "--altitude", "3.2", "-o", "c.yaml", "--focal", "900", "--fit-focal"],
    ],
)
def test_argument_conflicts_are_usage_errors(arguments: list[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["calibrate", *arguments])
    assert exit_info.value.code == 2


def test_command_line_end_to_end(marks_csv: Path, tmp_path: Path) -> None:
    output = tmp_path / "lobby-1.json"
    result = subprocess.run(
        [sys.executable, "-m", "service.cli", "calibrate", "--marks", str(marks_csv), "--altitude", "3.2",
         "--image-size", "2952", "2952", "-o", str(output)],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "RMS " in result.stdout and output.exists()
    help_text = subprocess.run(
        [sys.executable, "-m", "service.cli", "calibrate", "--help"],
        cwd=REPO, capture_output=True, text=True, check=False, timeout=120,
    )
    assert help_text.returncode == 0 and "--marks" in help_text.stdout and "--opencv" in help_text.stdout


@pytest.mark.parametrize(("distances", "warned"), [(np.arange(0.25, 10.001, 0.25), False),
                                                   (np.arange(0.25, 2.001, 0.25), True)])
def test_fit_tilt_prints_the_tilt_and_warns_when_it_is_not_pinned_down(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], distances: np.ndarray, warned: bool) -> None:
    tilted = camera_from_dict(TRUE.model_dump(mode="json", exclude_none=True) | {"tilt_deg": [2.0, -1.5]})
    marks = simulate_ruler_marks(tilted, [0.0, 90.0, 180.0, 270.0], distances, noise_px=0.5, seed=4)
    csv = tmp_path / "marks.csv"
    csv.write_text(marks_to_csv(marks), encoding="utf-8")
    output = tmp_path / "tilted.json"
    assert main(["calibrate", "--marks", str(csv), "--altitude", "3.2", "--image-size", "2952", "2952",
                 "-o", str(output), "--fit-tilt"]) == 0
    out = capsys.readouterr().out
    assert "principal point from the nadir mark, then fitted with the tilt" in out
    assert ", tilt [" in out
    assert ("warning: tilt fitted" in out) == warned and ("note: tilt fitted" in out) != warned
    assert load_camera(output).tilt_deg is not None


def test_check_altitude_reports_the_fitted_beside_the_configured(marks_csv: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(json.dumps({**camera_to_dict(TRUE), "altitude_m": 3.0}), encoding="utf-8")
    before = wrong.read_text(encoding="utf-8")
    assert main(["calibrate", "--check-altitude", str(wrong), "--marks", str(marks_csv)]) == 0
    out = capsys.readouterr().out
    fitted = float(out.split("fitted ")[1].split(" m")[0])
    assert "configured 3.000 m" in out and fitted == pytest.approx(3.2, abs=0.01)
    assert wrong.read_text(encoding="utf-8") == before  # nothing written
    assert main(["calibrate", "--check-altitude", str(wrong), "--opencv", str(marks_csv)]) == 2
    assert "needs --marks" in capsys.readouterr().err
    assert main(["calibrate", "--marks", str(marks_csv), "--image-size", "2952", "2952"]) == 2
    assert "--altitude and -o/--output are required" in capsys.readouterr().err


def test_calibrate_from_the_image_circle(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame, encode_jpeg

    spec = CircleFrame((1312, 1080), (655.0, 541.0), 650.0, jpeg_quality=85)
    frame = tmp_path / "hall.jpg"
    frame.write_bytes(encode_jpeg(draw_circle_frame(spec)))
    output = tmp_path / "hall-3.yaml"
    assert main(["calibrate", "--image-circle", str(frame), "-o", str(output)]) == 0
    camera = load_camera(output)
    assert camera.id == "hall-3" and camera.altitude_m == 3.0 and camera.kb == [1.0]
    np.testing.assert_allclose(camera.principal_point, spec.center_px, atol=1.0)
    assert camera.focal_px[0] == pytest.approx(spec.radius_px / (np.pi / 2), abs=1.0)
    printed = capsys.readouterr().out
    assert "cuts the circle at its top, bottom" in printed and "starting camera" in printed


@pytest.mark.parametrize(("content", "message"), [
    (b"", "cannot read"),
    (b"not an image", "cannot read"),
    (None, "no image circle"),
])
def test_calibrate_from_the_image_circle_refuses_frames_without_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes | None, message: str) -> None:
    frame = tmp_path / "frame.png"
    if content is None:
        cv2.imwrite(str(frame), np.zeros((480, 640, 3), np.uint8))
    else:
        frame.write_bytes(content)
    output = tmp_path / "camera.yaml"
    assert main(["calibrate", "--image-circle", str(frame), "-o", str(output)]) == 2
    assert message in capsys.readouterr().err and not output.exists()
