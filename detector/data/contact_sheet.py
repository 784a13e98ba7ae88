"""A contact sheet: a PNG grid of a data set's frames with their ground truth drawn on them.

Green: radius-aligned boxes (orange for ignore regions, `iscrowd` 1); red dot: the box's foot
point (`fisheye.boxes.foot_points`); cyan ring: `location_m` projected back into the frame with the
frame's camera. The two should sit together near the feet.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from fisheye import camera_from_dict, cxcywh_to_corners, foot_points

ImageU8 = NDArray[np.uint8]


def draw_truth(frame_bgr: ImageU8, image: dict[str, Any], annotations: list[dict[str, Any]],
               scale: float) -> ImageU8:
    """A copy of the frame scaled by `scale` with boxes, foot points and floor points drawn."""
    height, width = frame_bgr.shape[:2]
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    canvas = np.asarray(cv2.resize(frame_bgr, size, interpolation=cv2.INTER_AREA), np.uint8)
    if not annotations:
        return canvas
    camera = camera_from_dict(image["camera"]) if "camera" in image else None
    pp = camera.principal_point if camera is not None else ((width - 1) / 2, (height - 1) / 2)
    boxes = np.array([a["rotated_box"] for a in annotations], dtype=np.float64)
    corners = cxcywh_to_corners(boxes, pp)
    feet = foot_points(boxes, pp)
    thickness = 1 if scale < 0.6 else 2
    for ann, quad, foot in zip(annotations, corners, feet, strict=True):
        color = (0, 165, 255) if ann.get("iscrowd", 0) else (0, 220, 0)
        pts = ((quad + 0.5) * scale - 0.5).round().astype(np.int32)
        cv2.polylines(canvas, [pts], True, color, thickness, cv2.LINE_AA)
        fx, fy = (foot + 0.5) * scale - 0.5
        cv2.circle(canvas, (round(fx), round(fy)), 2 + thickness, (0, 0, 255), -1, cv2.LINE_AA)
    if camera is not None:
        located = np.array([a["location_m"] for a in annotations], dtype=np.float64)
        uv = camera.scaled_to((width, height)).floor_to_pixels(located)
        for u, v in uv:
            if np.isfinite(u) and np.isfinite(v):
                center = (round((u + 0.5) * scale - 0.5), round((v + 0.5) * scale - 0.5))
                cv2.circle(canvas, center, 4 + thickness, (255, 255, 0), thickness, cv2.LINE_AA)
    return canvas


def make_contact_sheet(annotations_path: str | Path, out_png: str | Path, columns: int = 4,
                       tile_px: int = 512, max_images: int = 16) -> Path:
    """Draw the first `max_images` frames of a data set into a grid PNG; returns its path."""
    ann_file = Path(annotations_path)
    document = json.loads(ann_file.read_text(encoding="utf-8"))
    by_image: dict[int, list[dict[str, Any]]] = defaultdict(list)
    for ann in document["annotations"]:
        by_image[int(ann["image_id"])].append(ann)
    images = document["images"][:max_images]
    if not images:
        raise ValueError(f"{ann_file} holds no images")
    rows = -(-len(images) // columns)
    sheet = np.zeros((rows * tile_px, columns * tile_px, 3), np.uint8)
    for k, image in enumerate(images):
        frame = cv2.imread(str(ann_file.parent / image["file_name"]), cv2.IMREAD_COLOR)
        if frame is None:
            raise FileNotFoundError(f"cannot read frame {image['file_name']} beside {ann_file}")
        scale = tile_px / max(frame.shape[:2])
        tile = draw_truth(np.asarray(frame, np.uint8), image, by_image[int(image["id"])], scale)
        label = f"{image['file_name']} {image.get('scene_id', '')} n={len(by_image[int(image['id'])])}"
        cv2.putText(tile, label, (6, tile.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255),
                    1, cv2.LINE_AA)
        r, c = divmod(k, columns)
        sheet[r * tile_px:r * tile_px + tile.shape[0], c * tile_px:c * tile_px + tile.shape[1]] = tile
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), sheet):
        raise OSError(f"cannot write {out}")
    return out
