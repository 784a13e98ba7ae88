"""The `fishloc.*` metadata of a model (DESIGN.md, "ONNX model contract"): read, checked, written.

`fishloc.view` says how the model sees a frame (absent: `fisheye`, the 0.1.0 models):

- `fisheye`: a letterboxed square of side `fishloc.input_size`; boxes `cxcywh_radius_aligned`.
- `polar`: the frame unwrapped about the camera's principal point (`fisheye.polar.PolarGrid`) into a
  strip of `fishloc.input_size` rows and `fishloc.polar_width` columns per turn plus
  `fishloc.polar_overlap` columns that repeat the first ones; its top row is the ring of the angle
  `fishloc.polar_max_theta_deg` from the optical axis (or the camera's own field, if smaller);
  boxes `xyxy_polar` in strip px.

`fishloc.view_planned` = `1` (a `polar` model whose graph takes any height and width, multiples of
32): the service plans each camera's view (`fisheye.view_plan`: rings of the frame, each at its own
scale, stacked in one input) from the strip the model was trained on, which the `polar_*` metadata
and `input_size` still describe. Without it, a polar model sees the fixed strip.

`fishloc.default_min_score` and `fishloc.nms_iou` are the model's operating point: the score
threshold and rotated-NMS IoU chosen together on validation renders (`detector.operating_point`).
A model without `fishloc.nms_iou` (before 0.3.1) is run at 0.6, the value it was tuned with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

VIEW_FISHEYE = "fisheye"
VIEW_POLAR = "polar"
BOX_FORMATS = {VIEW_FISHEYE: "cxcywh_radius_aligned", VIEW_POLAR: "xyxy_polar"}
LEGACY_NMS_IOU = 0.6  # the NMS IoU of a model whose metadata names none


class ModelError(RuntimeError):
    """A model file that is missing, unreadable, or does not follow the ONNX contract."""


@dataclass(frozen=True)
class PolarSpec:
    """The strip of a `polar` model: `width` columns per turn, `overlap` repeated columns, and the
    angle from the optical axis of its top row."""

    width: int
    overlap: int
    max_theta_deg: float

    def __post_init__(self) -> None:
        if self.width < 8 or not 0 <= self.overlap <= self.width:
            raise ValueError(f"polar strip of width {self.width} and overlap {self.overlap}: "
                             "width ≥ 8, 0 ≤ overlap ≤ width")
        if not (math.isfinite(self.max_theta_deg) and 0 < self.max_theta_deg < 180):
            raise ValueError(f"polar max_theta_deg must lie in (0, 180), got {self.max_theta_deg}")


@dataclass(frozen=True)
class ModelInfo:
    """The model's `fishloc.*` metadata and where it came from."""

    name: str
    version: str
    view: str
    input_size: int  # side of the letterboxed square, or the strip's height
    pad_value: int
    default_min_score: float
    trained_on: str
    box_format: str
    licence: str = ""
    polar: PolarSpec | None = None
    sha256: str = ""
    nms_iou: float = LEGACY_NMS_IOU
    planned: bool = False  # a polar model whose view the service plans per camera

    def __post_init__(self) -> None:
        if self.view not in BOX_FORMATS:
            raise ValueError(f"unknown view {self.view!r} (known: {', '.join(BOX_FORMATS)})")
        if self.box_format != BOX_FORMATS[self.view]:
            raise ValueError(f"a {self.view} model has boxes {BOX_FORMATS[self.view]!r}, "
                             f"not {self.box_format!r}")
        if (self.polar is None) != (self.view != VIEW_POLAR):
            raise ValueError("a polar model needs its strip (fishloc.polar_*), other views none")
        if self.planned and self.polar is None:
            raise ValueError("only a polar model's view can be planned (fishloc.view_planned)")
        if not (0 <= self.pad_value <= 255 and 0.0 <= self.default_min_score <= 1.0
                and self.input_size >= 8 and 0.0 < self.nms_iou <= 1.0):
            raise ValueError(f"pad_value {self.pad_value}, default_min_score {self.default_min_score}, "
                             f"nms_iou {self.nms_iou} or input_size {self.input_size} out of range")

    @property
    def input_wh(self) -> tuple[int, int]:
        """(width, height) of the image the model takes."""
        if self.polar is not None:
            return self.polar.width + self.polar.overlap, self.input_size
        return self.input_size, self.input_size

    def public(self) -> dict[str, object]:
        """The fields `GET /v1/model` answers with."""
        record: dict[str, object] = {
            "name": self.name, "version": self.version, "view": self.view,
            "input_size": self.input_size, "input_wh": list(self.input_wh),
            "trained_on": self.trained_on, "box_format": self.box_format,
            "default_min_score": self.default_min_score, "nms_iou": self.nms_iou,
            "pad_value": self.pad_value, "planned": self.planned,
            "licence": self.licence, "sha256": self.sha256,
        }
        if self.polar is not None:
            record["polar"] = {"width": self.polar.width, "overlap": self.polar.overlap,
                               "max_theta_deg": self.polar.max_theta_deg}
        return record


def parse_metadata(props: dict[str, str], source: str, sha256: str = "") -> ModelInfo:
    """`metadata_props` of an ONNX file -> ModelInfo; ModelError naming `source` when unusable."""
    if "fishloc.input_size" not in props:
        raise ModelError(f"{source}: the model lacks the metadata fishloc.input_size "
                         "(is it a FishLoc export?)")
    view = props.get("fishloc.view", VIEW_FISHEYE)
    try:
        polar = None
        if view == VIEW_POLAR:
            polar = PolarSpec(width=int(props["fishloc.polar_width"]),
                              overlap=int(props.get("fishloc.polar_overlap", "0")),
                              max_theta_deg=float(props.get("fishloc.polar_max_theta_deg", "90")))
        return ModelInfo(
            name=props.get("fishloc.model_name", "unnamed"),
            version=props.get("fishloc.model_version", "unknown"),
            view=view,
            input_size=int(props["fishloc.input_size"]),
            pad_value=int(props.get("fishloc.pad_value", "0")),
            default_min_score=float(props.get("fishloc.default_min_score", "0.3")),
            trained_on=props.get("fishloc.trained_on", "unknown"),
            box_format=props.get("fishloc.box_format", BOX_FORMATS.get(view, "")),
            licence=props.get("fishloc.licence", ""),
            polar=polar,
            sha256=sha256,
            nms_iou=float(props.get("fishloc.nms_iou", repr(LEGACY_NMS_IOU))),
            planned=_flag(props.get("fishloc.view_planned", "0"), "fishloc.view_planned"),
        )
    except KeyError as error:
        raise ModelError(f"{source}: a {view} model needs the metadata {error.args[0]}") from None
    except ValueError as error:
        raise ModelError(f"{source}: unusable fishloc.* metadata: {error}") from None


def _flag(value: str, name: str) -> bool:
    if value not in ("0", "1"):
        raise ValueError(f"{name} must be 0 or 1, got {value!r}")
    return value == "1"


def metadata_props(info: ModelInfo) -> dict[str, str]:
    """ModelInfo -> the `fishloc.*` metadata an export writes (the inverse of `parse_metadata`)."""
    props = {
        "fishloc.view": info.view,
        "fishloc.input_size": str(info.input_size),
        "fishloc.pad_value": str(info.pad_value),
        "fishloc.box_format": info.box_format,
        "fishloc.model_name": info.name,
        "fishloc.model_version": info.version,
        "fishloc.trained_on": info.trained_on,
        "fishloc.default_min_score": repr(float(info.default_min_score)),
        "fishloc.nms_iou": repr(float(info.nms_iou)),
    }
    if info.licence:
        props["fishloc.licence"] = info.licence
    if info.polar is not None:
        props["fishloc.polar_width"] = str(info.polar.width)
        props["fishloc.polar_overlap"] = str(info.polar.overlap)
        props["fishloc.polar_max_theta_deg"] = repr(float(info.polar.max_theta_deg))
    if info.planned:
        props["fishloc.view_planned"] = "1"
    return props
