"""The pipeline's typed result, which the REST and gRPC front ends both serialise.

`Detections` holds N people as parallel arrays; `DetectionResult` adds the frame, camera, model,
per-stage timings and, for a camera of a site, the track each person joined. Positions are NaN where
a foot point has no floor point; the JSON form writes those as `null`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

STAGES = ("decode", "preprocess", "inference", "postprocess", "total")


@dataclass(frozen=True)
class Detections:
    """N detected people in frame pixels and floor metres.

    scores (N,); cxcywh (N, 4) px radius-aligned; angle_deg (N,) direction of the `h` axis from the
    camera's principal point; corners_xy (N, 4, 2) px; foot_px (N, 2); position_m (N, 2) in the
    camera's floor frame; distance_m (N,) from the nadir; site_position_m (N, 2) or None when the
    camera has no site pose.
    """

    scores: FloatArray
    cxcywh: FloatArray
    angle_deg: FloatArray
    corners_xy: FloatArray
    foot_px: FloatArray
    position_m: FloatArray
    distance_m: FloatArray
    site_position_m: FloatArray | None

    def __post_init__(self) -> None:
        n = len(self.scores)
        shapes = {
            "scores": (self.scores.shape, (n,)),
            "cxcywh": (self.cxcywh.shape, (n, 4)),
            "angle_deg": (self.angle_deg.shape, (n,)),
            "corners_xy": (self.corners_xy.shape, (n, 4, 2)),
            "foot_px": (self.foot_px.shape, (n, 2)),
            "position_m": (self.position_m.shape, (n, 2)),
            "distance_m": (self.distance_m.shape, (n,)),
        }
        if self.site_position_m is not None:
            shapes["site_position_m"] = (self.site_position_m.shape, (n, 2))
        wrong = {name: got for name, (got, want) in shapes.items() if got != want}
        if wrong:
            raise ValueError(f"Detections of {n} people with mismatched arrays: {wrong}")

    def __len__(self) -> int:
        return len(self.scores)

    def take(self, keep: NDArray[np.bool_]) -> Detections:
        """The people where `keep` (N,) is True, in the same order."""
        return Detections(
            scores=self.scores[keep], cxcywh=self.cxcywh[keep], angle_deg=self.angle_deg[keep],
            corners_xy=self.corners_xy[keep], foot_px=self.foot_px[keep], position_m=self.position_m[keep],
            distance_m=self.distance_m[keep],
            site_position_m=None if self.site_position_m is None else self.site_position_m[keep],
        )

    @classmethod
    def empty(cls, with_site: bool) -> Detections:
        return cls(
            scores=np.zeros(0), cxcywh=np.zeros((0, 4)), angle_deg=np.zeros(0),
            corners_xy=np.zeros((0, 4, 2)), foot_px=np.zeros((0, 2)), position_m=np.zeros((0, 2)),
            distance_m=np.zeros(0), site_position_m=np.zeros((0, 2)) if with_site else None,
        )


@dataclass(frozen=True)
class DetectionResult:
    """One frame's answer: who is where, for which camera and model, how long each stage took, and
    how many detections the camera's masks dropped."""

    camera_id: str
    frame_id: str | None
    image_wh: tuple[int, int]
    model_name: str
    model_version: str
    detections: Detections
    timing_ms: dict[str, float] = field(default_factory=dict)
    masked: int = 0  # detections dropped because their foot point fell inside one of the camera's masks
    # For a camera of a site: (N,) the confirmed track of each detection (None: not (yet) tracked).
    track_ids: tuple[str | None, ...] | None = None
    # Why a site's camera's detections carry no track ids (the sites bus did not answer in time).
    site_note: str | None = None


def _number(value: float, digits: int) -> float | None:
    return round(float(value), digits) if math.isfinite(value) else None


def _pair(values: FloatArray, digits: int) -> list[float] | None:
    if not (math.isfinite(values[0]) and math.isfinite(values[1])):
        return None
    return [round(float(values[0]), digits), round(float(values[1]), digits)]


def detection_to_json(detections: Detections, index: int, track_id: str | None = None) -> dict[str, Any]:
    """The JSON object of one detection (DESIGN.md's `detect` answer)."""
    cx, cy, w, h = (float(v) for v in detections.cxcywh[index])
    site = detections.site_position_m
    return {
        "score": round(float(detections.scores[index]), 4),
        "box": {"cx": round(cx, 2), "cy": round(cy, 2), "w": round(w, 2), "h": round(h, 2),
                "angle_deg": round(float(detections.angle_deg[index]), 3)},
        "corners": [[round(float(x), 2), round(float(y), 2)] for x, y in detections.corners_xy[index]],
        "foot_px": _pair(detections.foot_px[index], 2),
        "position_m": _pair(detections.position_m[index], 4),
        "distance_m": _number(detections.distance_m[index], 4),
        "site_position_m": None if site is None else _pair(site[index], 4),
        "track_id": track_id,
    }


def result_to_json(result: DetectionResult) -> dict[str, Any]:
    """The JSON answer of `POST /v1/cameras/{id}/detect`."""
    answer = {
        "camera_id": result.camera_id,
        "frame_id": result.frame_id,
        "image": {"width": result.image_wh[0], "height": result.image_wh[1]},
        "model": {"name": result.model_name, "version": result.model_version},
        "detections": [detection_to_json(result.detections, i, None if result.track_ids is None
                                         else result.track_ids[i]) for i in range(len(result.detections))],
        "timing_ms": {stage: round(result.timing_ms.get(stage, 0.0), 3) for stage in STAGES},
    }
    if result.site_note is not None:
        answer["site_note"] = result.site_note
    return answer
