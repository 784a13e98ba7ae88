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
A planned model may carry its own points for some of the views the service plans
(`fishloc.view_operating_points`, JSON: `{"2band+nadir": {"min_score": 0.346, "nms_iou": 0.3}}`,
keyed by `fisheye.view_plan.ViewPlan.layout`), each chosen the same way on renders seen through that
view; a view with the second look (`+look`) and no point of its own runs at the point of the
same view without it; any other view runs at the model's own point.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass

VIEW_FISHEYE = "fisheye"
VIEW_POLAR = "polar"
BOX_FORMATS = {VIEW_FISHEYE: "cxcywh_radius_aligned", VIEW_POLAR: "xyxy_polar"}
LEGACY_NMS_IOU = 0.6  # the NMS IoU of a model whose metadata names none
VIEW_POINTS_KEY = "fishloc.view_operating_points"
LAYOUT_PATTERN = re.compile(r"[1-9][0-9]*band(\+nadir)?(\+look)?")  # fisheye.view_plan.view_layout's names


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
class OperatingPoint:
    """A score threshold and rotated-NMS IoU, chosen together (`detector.operating_point`)."""

    min_score: float
    nms_iou: float

    def __post_init__(self) -> None:
        if not (0.0 <= self.min_score <= 1.0 and 0.0 < self.nms_iou <= 1.0):
            raise ValueError(f"an operating point needs min_score in [0, 1] and nms_iou in (0, 1], "
                             f"got {self.min_score} and {self.nms_iou}")


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
    # (layout, point) pairs: a planned view's own operating point (module docstring)
    view_points: tuple[tuple[str, OperatingPoint], ...] = ()

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
        if self.view_points and not self.planned:
            raise ValueError("only a planned model has operating points of its views")
        layouts = [layout for layout, _ in self.view_points]
        for layout in layouts:
            if not LAYOUT_PATTERN.fullmatch(layout):
                raise ValueError(f"unknown view layout {layout!r} (e.g. '1band', '2band+nadir')")
        if len(set(layouts)) != len(layouts):
            raise ValueError(f"view layouts named twice: {layouts}")

    def point_for(self, layout: str | None, nms_iou: float | None = None) -> OperatingPoint:
        """The operating point of a view of `layout` (None: not a planned view): its own where the
        model has one, else the model's; with `nms_iou` (a caller's) in place of the point's."""
        points = dict(self.view_points)
        # a view with the second look takes the point of the same view without it where the model
        # has none for it (a model released before the second look)
        own = points.get(layout or "", points.get((layout or "").removesuffix("+look"),
                                                   OperatingPoint(self.default_min_score, self.nms_iou)))
        return own if nms_iou is None else OperatingPoint(own.min_score, nms_iou)

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
            "view_operating_points": view_points_record(self.view_points),
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
            view_points=parse_view_points(props.get(VIEW_POINTS_KEY, "{}")),
        )
    except KeyError as error:
        raise ModelError(f"{source}: a {view} model needs the metadata {error.args[0]}") from None
    except ValueError as error:
        raise ModelError(f"{source}: unusable fishloc.* metadata: {error}") from None


def view_points_record(points: tuple[tuple[str, OperatingPoint], ...]) -> dict[str, dict[str, float]]:
    """View operating points as their JSON object (`fishloc.view_operating_points`)."""
    return {layout: {"min_score": p.min_score, "nms_iou": p.nms_iou} for layout, p in points}


def parse_view_points(text: str) -> tuple[tuple[str, OperatingPoint], ...]:
    """`fishloc.view_operating_points` -> (layout, point) pairs; ValueError when malformed (the
    layouts themselves are checked by ModelInfo)."""
    try:
        record = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{VIEW_POINTS_KEY} is not JSON ({error})") from None
    if not isinstance(record, dict):
        raise ValueError(f"{VIEW_POINTS_KEY} must be a JSON object of layout -> point")
    points = []
    for layout, point in record.items():
        if not (isinstance(point, dict) and set(point) == {"min_score", "nms_iou"}
                and all(isinstance(v, int | float) and not isinstance(v, bool) for v in point.values())):
            raise ValueError(f"{VIEW_POINTS_KEY}[{layout!r}] must be {{\"min_score\": S, \"nms_iou\": I}}")
        points.append((layout, OperatingPoint(float(point["min_score"]), float(point["nms_iou"]))))
    return tuple(sorted(points, key=lambda pair: pair[0]))


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
    if info.view_points:
        props[VIEW_POINTS_KEY] = json.dumps(view_points_record(info.view_points), sort_keys=True)
    return props
