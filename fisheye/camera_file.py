"""Camera files (YAML or JSON, the schema of DESIGN.md) and OpenCV fisheye imports."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import ValidationError

from fisheye.camera import FisheyeCamera

ASSUMED_CAMERA_ID = "assumed"
ASSUMED_ALTITUDE_M = 3.0


class CalibrationError(ValueError):
    """A camera file or calibration that cannot be used; the message names the field at fault and
    `code` says why in a stable, machine-readable word (e.g. `too_few_marks`)."""

    def __init__(self, message: str, code: str = "invalid_camera") -> None:
        super().__init__(message)
        self.code = code


def describe_validation_error(error: ValidationError, whole: str = "camera") -> str:
    """Every problem of a pydantic validation as `field: message`, joined by '; '."""
    parts = []
    for item in error.errors():
        field = ".".join(str(p) for p in item["loc"]) or whole
        parts.append(f"{field}: {item['msg']}")
    return "; ".join(parts)


def camera_from_dict(record: Mapping[str, Any]) -> FisheyeCamera:
    """A validated camera from a camera-file dict; CalibrationError names every bad field."""
    try:
        return FisheyeCamera.model_validate(dict(record))
    except ValidationError as error:
        raise CalibrationError(f"invalid camera: {describe_validation_error(error)}") from None


def read_camera_records(path: str | Path) -> list[dict[str, Any]]:
    """The camera dicts of one YAML/JSON file (a camera, a list of cameras, or {cameras: [...]})."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as error:
        raise CalibrationError(f"cannot read camera file {file}: {error.strerror}") from None
    try:
        data = json.loads(text) if file.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as error:
        raise CalibrationError(f"{file} is not valid YAML/JSON: {error}") from None
    if isinstance(data, Mapping) and "cameras" in data:
        data = data["cameras"]
    records = data if isinstance(data, list) else [data]
    if not all(isinstance(r, Mapping) for r in records):
        raise CalibrationError(f"{file} must hold a camera mapping or a list of them")
    return [dict(r) for r in records]


def load_camera(source: str | Path | Mapping[str, Any]) -> FisheyeCamera:
    """A camera from a camera file (YAML/JSON path) or its dict."""
    if isinstance(source, Mapping):
        return camera_from_dict(source)
    records = read_camera_records(source)
    if len(records) != 1:
        raise CalibrationError(f"{source} holds {len(records)} cameras; load_cameras reads several")
    try:
        return camera_from_dict(records[0])
    except CalibrationError as error:
        raise CalibrationError(f"{source}: {error}") from None


def load_cameras(source: str | Path) -> list[FisheyeCamera]:
    """Every camera of a camera file, or of all *.yaml/*.yml/*.json files in a folder."""
    path = Path(source)
    files = sorted(
        p for p in path.iterdir() if p.suffix.lower() in {".yaml", ".yml", ".json"}
    ) if path.is_dir() else [path]
    cameras = []
    for file in files:
        for record in read_camera_records(file):
            try:
                cameras.append(camera_from_dict(record))
            except CalibrationError as error:
                raise CalibrationError(f"{file}: {error}") from None
    return cameras


def camera_to_dict(camera: FisheyeCamera) -> dict[str, Any]:
    """The camera-file dict of a camera (optional fields left out when unset)."""
    return camera.model_dump(mode="json", exclude_none=True)


def save_camera(camera: FisheyeCamera, path: str | Path) -> None:
    """Write a camera file; JSON for a .json path, YAML otherwise."""
    file = Path(path)
    record = camera_to_dict(camera)
    if file.suffix.lower() == ".json":
        text = json.dumps(record, indent=2) + "\n"
    else:
        text = yaml.safe_dump(record, sort_keys=False, default_flow_style=None)
    file.write_text(text, encoding="utf-8")


def camera_from_opencv(
    camera_id: str,
    K: Sequence[Sequence[float]] | np.ndarray,
    D: Sequence[float] | np.ndarray,
    image_size: tuple[int, int],
    altitude_m: float,
    **extra: Any,
) -> FisheyeCamera:
    """A camera from an OpenCV fisheye calibration: 3x3 `K`, `D` = [d1, d2, d3, d4].

    OpenCV's θ_d = θ(1 + d1θ² + d2θ⁴ + d3θ⁶ + d4θ⁸) is r(θ) with kb = [1, d1, d2, d3, d4].
    """
    matrix = np.asarray(K, dtype=np.float64).reshape(3, 3)
    distortion = np.asarray(D, dtype=np.float64).reshape(-1)
    if distortion.size != 4:
        raise CalibrationError(f"D must hold 4 coefficients, got {distortion.size}")
    if not (np.isfinite(matrix).all() and np.isfinite(distortion).all()):
        raise CalibrationError("K and D must hold finite numbers")
    if abs(matrix[0, 1]) > 1e-9:
        raise CalibrationError("K has a skew term; FishLoc's camera model has none")
    if abs(matrix[1, 0]) > 1e-9 or not np.allclose(matrix[2], [0.0, 0.0, 1.0]):
        raise CalibrationError(f"K must be [[fx, 0, u0], [0, fy, v0], [0, 0, 1]], got {matrix.tolist()}")
    return camera_from_dict({
        "id": camera_id,
        "altitude_m": altitude_m,
        "image_size": list(image_size),
        "principal_point": [matrix[0, 2], matrix[1, 2]],
        "focal_px": [matrix[0, 0], matrix[1, 1]],
        "kb": [1.0, *distortion.tolist()],
        **extra,
    })


def assumed_camera(width: int, height: int) -> FisheyeCamera:
    """The camera DESIGN.md assumes for a frame that has no calibration (CEPDOF, WEPDTOF): an ideal
    equidistant lens (`kb = [1]`) whose 180° image circle fills the frame's shorter side, the
    principal point at the frame's centre, 3 m up. Its floor positions are guesses, not truth."""
    radius_px = min(width, height) / 2.0
    focal_px = radius_px / (math.pi / 2)  # θ = 90° lands on the circle of the shorter side
    return camera_from_dict({
        "id": ASSUMED_CAMERA_ID,
        "altitude_m": ASSUMED_ALTITUDE_M,
        "image_size": [int(width), int(height)],
        "principal_point": [(width - 1) / 2.0, (height - 1) / 2.0],
        "focal_px": [focal_px, focal_px],
        "kb": [1.0],
    })


def _opencv_size(value: Any, file: Path) -> tuple[int, int]:
    flat = np.asarray(value, dtype=np.float64).reshape(-1)
    if flat.size != 2 or not np.isfinite(flat).all():
        raise CalibrationError(f"{file}: image_size must be two numbers [w, h], got {value!r}")
    return int(flat[0]), int(flat[1])


def _read_opencv_storage(file: Path) -> tuple[Any, Any, tuple[int, int] | None]:
    import cv2

    try:
        storage = cv2.FileStorage(str(file), cv2.FILE_STORAGE_READ)
    except cv2.error as error:
        raise CalibrationError(f"{file}: OpenCV cannot read it: {error}") from None
    try:
        nodes = {name: storage.getNode(name) for name in
                 ("K", "D", "camera_matrix", "distortion_coefficients", "image_size", "image_width",
                  "image_height")}
        K = (nodes["K"] if not nodes["K"].empty() else nodes["camera_matrix"]).mat()
        D = (nodes["D"] if not nodes["D"].empty() else nodes["distortion_coefficients"]).mat()
        size = None
        size_node = nodes["image_size"]
        if not size_node.empty():
            values = size_node.mat() if size_node.isMap() else [
                size_node.at(i).real() for i in range(size_node.size())
            ]
            size = _opencv_size(values, file)
        elif not nodes["image_width"].empty() and not nodes["image_height"].empty():
            size = _opencv_size([nodes["image_width"].real(), nodes["image_height"].real()], file)
    finally:
        storage.release()
    return K, D, size


def read_opencv_calibration(path: str | Path) -> tuple[np.ndarray, np.ndarray, tuple[int, int] | None]:
    """`K`, `D` and the image size (if stored) from an OpenCV FileStorage YAML/JSON file, or a
    plain YAML/JSON with `K` (3x3 or 9 numbers), `D` and optional `image_size` [w, h].

    OpenCV's sample names `camera_matrix`, `distortion_coefficients`, `image_width` and
    `image_height` are read as well.
    """
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as error:
        raise CalibrationError(f"cannot read OpenCV calibration {file}: {error.strerror}") from None
    if text.lstrip().startswith("%YAML") or "opencv-matrix" in text:
        K, D, size = _read_opencv_storage(file)
    else:
        try:
            data = json.loads(text) if file.suffix.lower() == ".json" else yaml.safe_load(text)
        except (json.JSONDecodeError, yaml.YAMLError) as error:
            raise CalibrationError(f"{file} is not valid YAML/JSON: {error}") from None
        if not isinstance(data, Mapping):
            raise CalibrationError(f"{file}: expected a mapping with fields K and D")
        K = data.get("K", data.get("camera_matrix"))
        D = data.get("D", data.get("distortion_coefficients"))
        size = None
        if data.get("image_size") is not None:
            size = _opencv_size(data["image_size"], file)
        elif data.get("image_width") is not None and data.get("image_height") is not None:
            size = _opencv_size([data["image_width"], data["image_height"]], file)
    if K is None or D is None:
        raise CalibrationError(f"{file}: needs K (camera_matrix) and D (distortion_coefficients)")
    try:
        matrix = np.asarray(K, dtype=np.float64).reshape(3, 3)
    except (ValueError, TypeError):
        raise CalibrationError(f"{file}: K must be a 3x3 matrix or 9 numbers") from None
    try:
        distortion = np.asarray(D, dtype=np.float64).reshape(-1)
    except (ValueError, TypeError):
        raise CalibrationError(f"{file}: D must be 4 numbers") from None
    return matrix, distortion, size
