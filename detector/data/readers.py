"""Dataset readers: FishLoc/LOAF-style and CEPDOF/WEPDTOF annotation files -> typed frame records.

FishLoc/LOAF-style files (what `fishloc synth` writes) give each person a radius-aligned
`rotated_box: [cx, cy, w, h]` and a floor position `location_m`, and each image its camera; the
LOAF release's `rotated_box: [cx, cy, w, h, angle_deg]` (angle counter-clockwise, see
`fisheye.boxes.loaf_to_radius_aligned`) is read too.
CEPDOF/WEPDTOF files give `bbox: [cx, cy, w, h, angle_deg]` and no camera; their frames get
DESIGN.md's assumed camera (`fisheye.assumed_camera`, marked `camera_assumed`; with
`assumed_lens="image-circle"` the camera of each frame's fitted image circle instead, so a circle
wider than the frame is not cut to its shorter side), keep the file's boxes
as they are (`file_boxes_cxcywha`, what evaluation scores against) and have them turned
radius-aligned about the image centre beside them. `read_dataset` tells the two apart by their
annotations.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from fisheye import (
    FisheyeCamera,
    assumed_camera,
    camera_from_dict,
    camera_to_dict,
    cepdof_to_radius_aligned,
    loaf_to_radius_aligned,
)
from fisheye.boxes import cxcywh_to_corners
from fisheye.image_circle import camera_of_uncalibrated_frame

FloatArray = NDArray[np.float64]
# What camera a frame without a calibration gets: the circle that fills its shorter side (DESIGN.md),
# or the one fitted to its image circle.
AssumedLens = Literal["short-side", "image-circle"]
ASSUMED_LENSES: tuple[AssumedLens, ...] = ("short-side", "image-circle")
_log = logging.getLogger(__name__)
ANNOTATIONS_FILE = "annotations.json"


class DatasetFormatError(ValueError):
    """An annotation file that neither reader understands; the message says where."""


@dataclass(frozen=True)
class FrameAnnotations:
    """One frame and its people: `boxes_cxcywh` (N, 4) frame px radius-aligned about
    `principal_point`; `locations_m` (N, 2) floor metres, `distances_m` (N,) metres from the nadir
    and `visible_fraction` (N,), NaN where the file does not say. `bboxes_xywh` (N, 4) px and
    `areas_px` (N,) are the file's axis-aligned `bbox` and `area` of each person's silhouette (NaN
    where it gives none; None when the frame was not read from a file). `crowd_cxcywh` (M, 4) are
    the boxes marked `iscrowd` (people too hidden to count): evaluation neither rewards nor
    penalises detections on them, training leaves them out.

    Frames of CEPDOF/WEPDTOF files keep the file's own boxes `[cx, cy, w, h, angle_deg]` as
    `file_boxes_cxcywha` (N, 5) and `file_crowd_cxcywha` (M, 5), parallel to `boxes_cxcywh` and
    `crowd_cxcywh` (None for FishLoc-format frames). `camera_assumed` says the camera is DESIGN.md's
    assumed one, not a calibration: floor positions from it are not ground truth."""

    path: Path
    image_id: int | str
    width: int
    height: int
    camera: FisheyeCamera | None
    scene_id: str
    split: str
    boxes_cxcywh: FloatArray
    locations_m: FloatArray
    distances_m: FloatArray
    visible_fraction: FloatArray
    crowd_cxcywh: FloatArray = field(default_factory=lambda: np.zeros((0, 4)))
    bboxes_xywh: FloatArray | None = None
    areas_px: FloatArray | None = None
    file_boxes_cxcywha: FloatArray | None = None
    file_crowd_cxcywha: FloatArray | None = None
    camera_assumed: bool = False

    def __post_init__(self) -> None:
        n = len(self.boxes_cxcywh)
        file_shapes = (_shape(self.file_boxes_cxcywha), _shape(self.file_crowd_cxcywha))
        if file_shapes not in ((None, None), ((n, 5), (len(self.crowd_cxcywh), 5))):
            raise ValueError(
                f"{self.path}: file boxes {file_shapes[0]} and file crowd boxes {file_shapes[1]} must "
                f"both be given, parallel to boxes {self.boxes_cxcywh.shape} and crowd "
                f"{self.crowd_cxcywh.shape}, or neither"
            )
        if self.camera_assumed and self.camera is None:
            raise ValueError(f"{self.path}: camera_assumed without a camera")
        if (self.boxes_cxcywh.shape != (n, 4) or self.locations_m.shape != (n, 2)
                or self.distances_m.shape != (n,) or self.visible_fraction.shape != (n,)
                or (self.bboxes_xywh is not None and self.bboxes_xywh.shape != (n, 4))
                or (self.areas_px is not None and self.areas_px.shape != (n,))):
            raise ValueError(
                f"{self.path}: arrays disagree: boxes {self.boxes_cxcywh.shape}, locations "
                f"{self.locations_m.shape}, distances {self.distances_m.shape}, "
                f"visible {self.visible_fraction.shape}, bboxes "
                f"{None if self.bboxes_xywh is None else self.bboxes_xywh.shape}, areas "
                f"{None if self.areas_px is None else self.areas_px.shape}"
            )
        if self.camera is not None and tuple(self.camera.image_size) != (self.width, self.height):
            raise ValueError(f"{self.path}: camera is calibrated at {self.camera.image_size}, "
                             f"frame is {self.width}x{self.height}; scale it with scaled_to")

    @property
    def principal_point(self) -> tuple[float, float]:
        """The camera's principal point, or the frame centre when the frame has no camera."""
        if self.camera is not None:
            return self.camera.principal_point
        return (self.width - 1) / 2.0, (self.height - 1) / 2.0

    def __len__(self) -> int:
        return len(self.boxes_cxcywh)


def _shape(array: FloatArray | None) -> tuple[int, ...] | None:
    return None if array is None else array.shape


def _numbers(record: Mapping[str, Any], key: str, count: int, where: str) -> list[float] | None:
    value = record.get(key)
    if value is None:
        return None
    if not isinstance(value, Sequence) or len(value) != count:
        raise DatasetFormatError(f"{where}: {key} must hold {count} numbers, got {value!r}")
    try:
        return [float(v) for v in value]
    except (TypeError, ValueError):
        raise DatasetFormatError(f"{where}: {key} must hold numbers, got {value!r}") from None


def _rotated_box(annotation: Mapping[str, Any], principal: tuple[float, float], where: str
                 ) -> list[float]:
    """A person's radius-aligned box from `rotated_box`: [cx, cy, w, h] as it is, or LOAF's
    [cx, cy, w, h, angle_deg] turned radius-aligned about the principal point."""
    value = annotation.get("rotated_box")
    count = 5 if isinstance(value, Sequence) and len(value) == 5 else 4
    box = _numbers(annotation, "rotated_box", count, where)
    if box is None:
        raise DatasetFormatError(f"{where}: no rotated_box")
    if count == 5:
        return loaf_to_radius_aligned(np.asarray([box]), principal)[0].tolist()
    return box


def sniff_format(data: Mapping[str, Any]) -> str:
    """'fishloc' (rotated_box + location_m) or 'cepdof' (5-number bbox) of a loaded COCO dict."""
    annotations = data.get("annotations") or []
    if any("rotated_box" in a for a in annotations):
        return "fishloc"
    if any(isinstance(a.get("bbox"), Sequence) and len(a["bbox"]) == 5 for a in annotations):
        return "cepdof"
    if annotations:
        raise DatasetFormatError("annotations have neither rotated_box nor a 5-number bbox")
    # No people at all: the images alone decide (FishLoc images carry cameras).
    return "fishloc" if any("camera" in i for i in data.get("images") or []) else "cepdof"


def _circle_camera(path: Path, width: int, height: int, where: str) -> FisheyeCamera:
    """The camera of the frame's image circle (`fisheye.image_circle`), or the shorter side's where
    it shows none (logged)."""
    import cv2

    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if bgr is None:
        raise DatasetFormatError(f"{where}: cannot read {path} to fit its image circle")
    rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    if (rgb.shape[1], rgb.shape[0]) != (width, height):
        raise DatasetFormatError(f"{where}: {path} is {rgb.shape[1]}x{rgb.shape[0]}, the file says "
                                 f"{width}x{height}")
    camera, note = camera_of_uncalibrated_frame(rgb)
    if note.level == "warning":
        _log.warning("%s: %s", where, note.message)
    return camera


def _frame(image: Mapping[str, Any], annotations: list[Mapping[str, Any]], folder: Path,
           file_format: str, source: Path, assumed_lens: AssumedLens = "short-side") -> FrameAnnotations:
    where = f"{source} image {image.get('id')!r}"
    try:
        width, height = int(image["width"]), int(image["height"])
        path = folder / str(image["file_name"])
    except (KeyError, TypeError, ValueError) as error:
        raise DatasetFormatError(f"{where}: needs file_name, width and height ({error})") from None
    camera = None
    if image.get("camera") is not None:
        try:
            camera = camera_from_dict(image["camera"]).scaled_to((width, height))
        except ValueError as error:
            raise DatasetFormatError(f"{where}: {error}") from None
    camera_assumed = file_format == "cepdof" and camera is None
    if camera_assumed and assumed_lens == "image-circle":
        camera = _circle_camera(path, width, height, where)
    elif camera_assumed:
        try:
            camera = assumed_camera(width, height)
        except ValueError as error:
            raise DatasetFormatError(f"{where}: no camera can be assumed: {error}") from None
    principal = camera.principal_point if camera is not None else ((width - 1) / 2, (height - 1) / 2)
    boxes, locations, distances, visible, crowd = [], [], [], [], []
    file_boxes: list[list[float]] = []
    file_crowd: list[list[float]] = []
    bboxes: list[list[float]] = []
    areas: list[float] = []
    for index, annotation in enumerate(annotations):
        at = f"{where} annotation {annotation.get('id', index)!r}"
        raw: list[float] | None = None
        if file_format == "fishloc":
            box = _rotated_box(annotation, principal, at)
        else:
            raw = _numbers(annotation, "bbox", 5, at)
            if raw is None:
                raise DatasetFormatError(f"{at}: no bbox")
            box = cepdof_to_radius_aligned(np.asarray([raw]), principal)[0].tolist()
        if annotation.get("iscrowd", 0):
            crowd.append(box)
            if raw is not None:
                file_crowd.append(raw)
            continue
        if raw is not None:
            file_boxes.append(raw)
        location = _numbers(annotation, "location_m", 2, at)
        xy = np.asarray(location if location is not None else [np.nan, np.nan])
        distance = annotation.get("distance_m")
        boxes.append(box)
        locations.append(xy)
        distances.append(float(distance) if distance is not None else float(np.hypot(*xy)))
        fraction = annotation.get("visible_fraction")
        visible.append(float(fraction) if fraction is not None else np.nan)
        # CEPDOF's bbox is its rotated box and its area that box's: neither is the silhouette's.
        raw_bbox = annotation.get("bbox") if file_format == "fishloc" else None
        # Only an axis-aligned [x, y, w, h] is a silhouette box; other forms are left out.
        bbox = (_numbers(annotation, "bbox", 4, at)
                if isinstance(raw_bbox, Sequence) and len(raw_bbox) == 4 else None)
        bboxes.append(bbox if bbox is not None else [np.nan] * 4)
        area = annotation.get("area") if file_format == "fishloc" else None
        if area is not None and not isinstance(area, int | float):
            raise DatasetFormatError(f"{at}: area must be a number, got {area!r}")
        areas.append(float(area) if area is not None else np.nan)
    n = len(boxes)
    from_file = file_format == "cepdof"
    return FrameAnnotations(
        path=path,
        image_id=image.get("id", path.stem),
        width=width,
        height=height,
        camera=camera,
        scene_id=str(image.get("scene_id", "")),
        split=str(image.get("split", "")),
        boxes_cxcywh=np.asarray(boxes, dtype=np.float64).reshape(n, 4),
        locations_m=np.asarray(locations, dtype=np.float64).reshape(n, 2),
        distances_m=np.asarray(distances, dtype=np.float64).reshape(n),
        visible_fraction=np.asarray(visible, dtype=np.float64).reshape(n),
        crowd_cxcywh=np.asarray(crowd, dtype=np.float64).reshape(-1, 4),
        bboxes_xywh=np.asarray(bboxes, dtype=np.float64).reshape(n, 4),
        areas_px=np.asarray(areas, dtype=np.float64).reshape(n),
        file_boxes_cxcywha=np.asarray(file_boxes, dtype=np.float64).reshape(n, 5) if from_file else None,
        file_crowd_cxcywha=np.asarray(file_crowd, dtype=np.float64).reshape(-1, 5) if from_file else None,
        camera_assumed=camera_assumed,
    )


def read_dataset(path: str | Path, assumed_lens: AssumedLens = "short-side") -> list[FrameAnnotations]:
    """Every frame of an annotation file (or of a folder's `annotations.json`), in file order;
    `assumed_lens` says what camera a frame without a calibration gets (see AssumedLens)."""
    source = Path(path)
    if source.is_dir():
        source = source / ANNOTATIONS_FILE
    try:
        data = json.loads(source.read_text(encoding="utf-8"))
    except OSError as error:
        raise DatasetFormatError(f"cannot read {source}: {error.strerror}") from None
    except json.JSONDecodeError as error:
        raise DatasetFormatError(f"{source} is not valid JSON: {error}") from None
    if not isinstance(data, Mapping) or not isinstance(data.get("images"), list):
        raise DatasetFormatError(f"{source} is not a COCO-style file (no 'images' list)")
    file_format = sniff_format(data)
    by_image: dict[Any, list[Mapping[str, Any]]] = {}
    for annotation in data.get("annotations") or []:
        if int(annotation.get("category_id", 1)) == 1:
            by_image.setdefault(annotation.get("image_id"), []).append(annotation)
    if assumed_lens not in ASSUMED_LENSES:
        raise ValueError(f"assumed_lens must be one of {ASSUMED_LENSES}, got {assumed_lens!r}")
    return [_frame(image, by_image.get(image.get("id"), []), source.parent, file_format, source, assumed_lens)
            for image in data["images"]]


def _annotation_record(frame: FrameAnnotations, index: int, next_id: int) -> dict[str, Any]:
    """A person's record; the silhouette's bbox and area are kept where the frame has them, else
    stood in for by the rotated box's axis-aligned hull and area."""
    box = frame.boxes_cxcywh[index]
    bbox = None if frame.bboxes_xywh is None else frame.bboxes_xywh[index]
    if bbox is None or not np.all(np.isfinite(bbox)):
        corners = cxcywh_to_corners(box[None], frame.principal_point)[0]
        x0, y0 = corners.min(axis=0)
        x1, y1 = corners.max(axis=0)
        bbox = np.array([x0, y0, x1 - x0, y1 - y0])
    area = np.nan if frame.areas_px is None else frame.areas_px[index]
    record: dict[str, Any] = {
        "id": next_id,
        "image_id": frame.image_id,
        "category_id": 1,
        "rotated_box": [float(v) for v in box],
        "bbox": [float(v) for v in bbox],
        "area": float(area) if np.isfinite(area) else float(box[2] * box[3]),
        "iscrowd": 0,
    }
    if np.all(np.isfinite(frame.locations_m[index])):
        record["location_m"] = [float(v) for v in frame.locations_m[index]]
    if np.isfinite(frame.distances_m[index]):
        record["distance_m"] = float(frame.distances_m[index])
    if np.isfinite(frame.visible_fraction[index]):
        record["visible_fraction"] = float(frame.visible_fraction[index])
    return record


def write_dataset(frames: Sequence[FrameAnnotations], path: str | Path,
                  info: Mapping[str, Any] | None = None) -> None:
    """Write frames as a FishLoc-format annotation file; image paths are stored relative to it."""
    target = Path(path)
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for frame in frames:
        image: dict[str, Any] = {
            "id": frame.image_id,
            "file_name": str(Path(frame.path).resolve().relative_to(target.parent.resolve()))
            if Path(frame.path).resolve().is_relative_to(target.parent.resolve()) else str(frame.path),
            "width": frame.width,
            "height": frame.height,
            "scene_id": frame.scene_id,
            "split": frame.split,
        }
        if frame.camera is not None and not frame.camera_assumed:  # an assumption is no calibration
            image["camera"] = camera_to_dict(frame.camera)
        images.append(image)
        for index in range(len(frame)):
            annotations.append(_annotation_record(frame, index, len(annotations) + 1))
        for box in frame.crowd_cxcywh:
            annotations.append({"id": len(annotations) + 1, "image_id": frame.image_id, "category_id": 1,
                                "rotated_box": [float(v) for v in box], "area": float(box[2] * box[3]),
                                "iscrowd": 1})
    document = {"info": dict(info or {}), "categories": [{"id": 1, "name": "person"}],
                "images": images, "annotations": annotations}
    target.write_text(json.dumps(document, indent=1) + "\n", encoding="utf-8")
