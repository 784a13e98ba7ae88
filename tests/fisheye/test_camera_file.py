import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

from fisheye import (
    CalibrationError,
    assumed_camera,
    camera_from_dict,
    camera_from_opencv,
    camera_to_dict,
    load_camera,
    load_cameras,
    save_camera,
)
from fisheye.camera_file import read_opencv_calibration
from models import DEMO_CAMERA_PATH

RECORD: dict[str, Any] = {
    "id": "lobby-1",
    "altitude_m": 3.2,
    "image_size": [2952, 2952],
    "principal_point": [1476.25, 1470.5],
    "focal_px": [940.123456789, 939.5],
    "kb": [1.0, -0.0213, 0.00117],
    "max_theta_deg": 92.5,
    "site_pose": {"x_m": 4.0, "y_m": -1.5, "yaw_deg": 30.0},
}
K = np.array([[940.0, 0.0, 1476.25], [0.0, 939.5, 1470.5], [0.0, 0.0, 1.0]])
D = np.array([-0.0213, 0.00117, -0.0002, 0.00001])


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".json"])
@pytest.mark.parametrize("record", [RECORD, {k: v for k, v in RECORD.items() if k not in ("max_theta_deg",
                                                                                          "site_pose")}])
def test_save_load_round_trip(tmp_path: Path, suffix: str, record: dict[str, Any]) -> None:
    camera = camera_from_dict(record)
    path = tmp_path / f"camera{suffix}"
    save_camera(camera, path)
    loaded = load_camera(path)
    assert loaded == camera
    assert camera_to_dict(loaded) == record
    text = path.read_text(encoding="utf-8")
    parsed = json.loads(text) if suffix == ".json" else yaml.safe_load(text)
    assert parsed == record


def test_camera_to_dict_leaves_unset_fields_out() -> None:
    record = camera_to_dict(load_camera(DEMO_CAMERA_PATH))
    assert record["id"] == "demo" and record["image_size"] == [2048, 2048]
    minimal = {k: v for k, v in RECORD.items() if k not in ("max_theta_deg", "site_pose")}
    assert set(camera_to_dict(camera_from_dict(minimal))) == set(minimal)


def test_load_camera_from_dict_equals_from_file(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    path.write_text(json.dumps(RECORD), encoding="utf-8")
    assert load_camera(RECORD) == load_camera(path) == load_camera(str(path))


def test_load_cameras_from_a_folder_and_lists(tmp_path: Path) -> None:
    second = {**RECORD, "id": "lobby-2"}
    third = {**RECORD, "id": "gate"}
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(RECORD), encoding="utf-8")
    (tmp_path / "b.json").write_text(json.dumps([second]), encoding="utf-8")
    (tmp_path / "c.yml").write_text(yaml.safe_dump({"cameras": [third]}), encoding="utf-8")
    (tmp_path / "notes.txt").write_text("not a camera", encoding="utf-8")
    assert [c.id for c in load_cameras(tmp_path)] == ["lobby-1", "lobby-2", "gate"]
    assert [c.id for c in load_cameras(tmp_path / "c.yml")] == ["gate"]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "must hold a camera mapping"),
        ("id: [unclosed", "not valid YAML/JSON"),
        ("- 1\n- 2\n", "must hold a camera mapping"),
        (yaml.safe_dump([RECORD, RECORD]), "holds 2 cameras"),
        (yaml.safe_dump({**RECORD, "altitude_m": -1}), "altitude_m"),
        (yaml.safe_dump({**RECORD, "kb": [1, -0.5]}), "kb"),
    ],
)
def test_bad_camera_files_say_what_is_wrong(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(content, encoding="utf-8")
    with pytest.raises(CalibrationError, match=message):
        load_camera(path)


def test_missing_file_is_a_calibration_error(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="cannot read"):
        load_camera(tmp_path / "absent.yaml")


def test_error_in_a_folder_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "ok.yaml").write_text(yaml.safe_dump(RECORD), encoding="utf-8")
    (tmp_path / "broken.yaml").write_text(yaml.safe_dump({**RECORD, "id": "no spaces"}), encoding="utf-8")
    with pytest.raises(CalibrationError, match=r"broken\.yaml.*id"):
        load_cameras(tmp_path)


def test_camera_from_opencv_maps_k_and_d() -> None:
    camera = camera_from_opencv("cv-1", K, D, (2952, 2952), 3.2, max_theta_deg=90)
    assert camera.kb == [1.0, *D.tolist()]
    assert camera.focal_px == (940.0, 939.5)
    assert camera.principal_point == (1476.25, 1470.5)
    assert camera.altitude_m == 3.2 and camera.theta_max_deg == 90


@pytest.mark.parametrize(
    ("matrix", "distortion", "message"),
    [
        (K, D[:3], "D must hold 4"),
        (K + np.array([[0, 1.0, 0], [0, 0, 0], [0, 0, 0]]), D, "skew"),
        (K + np.array([[0, 0, 0], [0, 0, 0], [0, 0, 1.0]]), D, "K must be"),
        (K * np.array([[1, 1, 1], [1, 1, 1], [1, 1, np.nan]]), D, "finite"),
        (K, [-0.5, 0.0, 0.0, 0.0], "not strictly increasing"),
        (K * np.array([[-1, 1, 1], [1, 1, 1], [1, 1, 1]]), D, "focal_px"),
    ],
)
def test_camera_from_opencv_refusals(matrix: np.ndarray, distortion: Any, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        camera_from_opencv("cv-1", matrix, distortion, (2952, 2952), 3.2)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_read_opencv_filestorage(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"calib{suffix}"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("K", K)
    storage.write("D", D.reshape(4, 1))
    storage.write("image_size", np.array([2952, 2952]))
    storage.release()
    matrix, distortion, size = read_opencv_calibration(path)
    np.testing.assert_array_equal(matrix, K)
    np.testing.assert_array_equal(distortion, D)
    assert size == (2952, 2952)


def test_read_opencv_filestorage_with_sample_names(tmp_path: Path) -> None:
    path = tmp_path / "out_camera_data.yml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("image_width", 1920)
    storage.write("image_height", 1920)
    storage.write("camera_matrix", K)
    storage.write("distortion_coefficients", D)
    storage.release()
    matrix, distortion, size = read_opencv_calibration(path)
    np.testing.assert_array_equal(matrix, K)
    np.testing.assert_array_equal(distortion, D)
    assert size == (1920, 1920)


@pytest.mark.parametrize(
    ("suffix", "record", "size"),
    [
        (".yaml", {"K": K.tolist(), "D": D.tolist(), "image_size": [2952, 2952]}, (2952, 2952)),
        (".json", {"K": K.reshape(-1).tolist(), "D": D.tolist()}, None),
        (".json", {"camera_matrix": K.tolist(), "distortion_coefficients": [D.tolist()],
                   "image_width": 800, "image_height": 600}, (800, 600)),
    ],
)
def test_read_plain_opencv_numbers(tmp_path: Path, suffix: str, record: dict[str, Any],
                                   size: tuple[int, int] | None) -> None:
    path = tmp_path / f"kd{suffix}"
    path.write_text(json.dumps(record) if suffix == ".json" else yaml.safe_dump(record), encoding="utf-8")
    matrix, distortion, found = read_opencv_calibration(path)
    np.testing.assert_array_equal(matrix, K)
    np.testing.assert_array_equal(distortion, D)
    assert found == size


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("K: [1, 2, 3]\nD: [0, 0, 0, 0]\n", "K must be a 3x3"),
        ("K: [1, 0, 0, 0, 1, 0, 0, 0, 1]\n", "needs K"),
        ("[1, 2]\n", "expected a mapping"),
        ("K: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nD: [0, 0, 0, 0]\nimage_size: [5]\n", "image_size"),
        ("K: {a: 1\n", "not valid"),
    ],
)
def test_bad_opencv_files(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "kd.yaml"
    path.write_text(content, encoding="utf-8")
    with pytest.raises(CalibrationError, match=message):
        read_opencv_calibration(path)


def test_missing_opencv_file(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match="cannot read"):
        read_opencv_calibration(tmp_path / "absent.yaml")


@pytest.mark.parametrize(("width", "height"), [(2048, 2048), (640, 480), (1080, 1920)])
def test_assumed_camera_fills_the_shorter_side_with_its_180_degree_circle(width: int, height: int) -> None:
    camera = assumed_camera(width, height)
    half_short = min(width, height) / 2
    assert (camera.id, camera.altitude_m, camera.kb) == ("assumed", 3.0, [1.0])
    assert camera.image_size == (width, height)
    assert camera.principal_point == ((width - 1) / 2, (height - 1) / 2)
    assert camera.focal_px == pytest.approx((half_short / (np.pi / 2),) * 2)
    # Horizontal rays (θ = 90°) land on the edges of the shorter side: pixel centres ±0.5 px inside.
    u0, v0 = camera.principal_point
    edges = camera.rays_to_pixels(np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]))
    np.testing.assert_allclose(edges, [[u0 + half_short, v0], [u0, v0 - half_short]], atol=1e-9)
    assert camera == load_camera(camera_to_dict(camera))  # a valid camera file
