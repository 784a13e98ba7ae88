"""JSON shapes of the REST API, for the OpenAPI document (answers are built by `service.result`)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from fisheye import FisheyeCamera


class ErrorBody(BaseModel):
    code: str = Field(description="stable machine-readable reason, e.g. camera_not_found")
    message: str


class ErrorResponse(BaseModel):
    error: ErrorBody


class Box(BaseModel):
    cx: float = Field(description="centre u (frame px)")
    cy: float = Field(description="centre v (frame px)")
    w: float = Field(description="extent across the ray from the principal point (px)")
    h: float = Field(description="extent along the ray (px)")
    angle_deg: float = Field(
        description="direction of the h axis, atan2(cy - v0, cx - u0), clockwise on screen"
    )


class Detection(BaseModel):
    score: float
    box: Box
    corners: list[list[float]] = Field(
        description="4 corners [u, v] px: the two nearest the principal point first"
    )
    foot_px: list[float] | None = Field(description="[u, v] px, the box point nearest the principal point")
    position_m: list[float] | None = Field(description="[x, y] m on the floor (camera floor frame); "
                                                       "null when the foot point has no floor point")
    distance_m: float | None = Field(description="distance from the nadir (m)")
    site_position_m: list[float] | None = Field(
        description="[x, y] m in the site frame, when the camera has a site pose"
    )
    track_id: str | None = Field(
        description="the site's track this person joined (e.g. hall-a:17); null for a camera without a "
                    "site and until a track is confirmed"
    )


class ImageSize(BaseModel):
    width: int
    height: int


class ModelRef(BaseModel):
    name: str
    version: str


class Timing(BaseModel):
    decode: float
    preprocess: float
    inference: float
    postprocess: float = Field(description="score threshold, NMS, foot points and floor positions")
    total: float


class DetectResponse(BaseModel):
    camera_id: str
    frame_id: str | None
    image: ImageSize
    model: ModelRef
    detections: list[Detection]
    timing_ms: Timing
    site_note: str | None = Field(
        None, description="behind a sites bus: why the detections of a site's camera carry no track ids")


class FitNote(BaseModel):
    code: str = Field(description="stable reason, e.g. tilt_undetermined, marks_short, monotonic_constraint")
    level: str = Field(description="info or warning")
    message: str


class MarkResidual(BaseModel):
    ruler: str
    u: float
    v: float
    distance_m: float | None
    x_m: float | None
    y_m: float | None
    fitted_distance_m: float | None = Field(description="the fitted camera's floor distance of the pixel (m)")
    err_m: float | None = Field(description="fitted minus ruler distance (m)")
    pos_err_m: float | None = Field(description="floor position error (m), for marks with x_m, y_m")
    err_px: float | None = Field(description="marked pixel to the fitted camera's pixel of the mark (px)")


class CalibrationFit(BaseModel):
    camera: FisheyeCamera = Field(description="the fitted camera file (not saved)")
    marks: list[MarkResidual]
    rms_m: float | None
    rms_px: float | None
    max_abs_m: float | None
    theta_max_marked_deg: float
    monotonic_constrained: bool
    notes: list[FitNote]


class CameraView(FisheyeCamera):
    """A camera record with the view planned for its frames (a planned model only)."""

    model_config = ConfigDict(extra="allow")
    view: dict[str, Any] | None = None


class CircleCutSides(BaseModel):
    top: bool = Field(description="the circle passes beyond the frame's top edge")
    bottom: bool
    left: bool
    right: bool
    visible_rim_fraction: float = Field(description="fraction of the rim's length inside the frame")


class FittedCircle(BaseModel):
    center_px: tuple[float, float] = Field(description="[u0, v0] (frame px): the principal point")
    radius_px: float = Field(description="R (frame px)")
    cut: CircleCutSides
    inlier_fraction: float = Field(description="rim points found that lie on the circle")
    rms_px: float = Field(description="RMS distance of those from the circle (frame px)")
    rim_points: int = Field(description="rim points found along the rays")
    rays: int = Field(description="rays cast from the centre")


class ImageCircleFit(BaseModel):
    circle: FittedCircle
    camera: FisheyeCamera = Field(description="a starting camera: equidistant 180° lens, kb [1], "
                                              "fx = fy = R / (π/2), max_theta_deg 90 (not saved)")
    notes: list[FitNote]


class CameraList(BaseModel):
    cameras: list[FisheyeCamera]


class ModelResponse(BaseModel):
    name: str
    version: str
    input_size: int = Field(description="side S of the square model input (px)")
    trained_on: str
    box_format: str
    default_min_score: float
    nms_iou: float = Field(description="rotated NMS IoU the service runs the model at")
    view_operating_points: dict[str, dict[str, float]] = Field(
        default_factory=dict, description="a planned model's own operating points (min_score, nms_iou) "
                                          "for some view layouts (e.g. `2band+nadir`); other views run at "
                                          "default_min_score and nms_iou")
    pad_value: int
    sha256: str = Field(description="SHA-256 of the model file")


class Status(BaseModel):
    status: str


class Readiness(Status):
    outputs: dict[str, dict[str, Any]] = Field(
        default_factory=dict, description="per output: `ok` and what is wrong (e.g. the broker's error); "
                                          "behind a sites bus the outputs run in the `fishloc sites` workers")
    sites_bus: str | None = Field(None, description="behind a sites bus: `ok`, or why site state is not")


def error_responses(*statuses: int) -> dict[int | str, dict[str, object]]:
    """OpenAPI `responses` entries for error statuses, all in the error shape."""
    descriptions = {
        400: "bad request (e.g. undecodable image)", 401: "missing or wrong bearer token",
        404: "no such camera", 413: "body or decoded image too large", 415: "not a JPEG/PNG/multipart body",
        422: "invalid parameters or camera record", 503: "not ready, or overloaded (see Retry-After)",
    }
    return {
        status: {"model": ErrorResponse, "description": descriptions.get(status, "error")}
        for status in statuses
    }


def inline_schema(model: type[BaseModel]) -> dict[str, Any]:
    """The JSON schema of `model` with its nested models written in place (a request body schema of
    the OpenAPI document cannot point into the model's own `$defs`)."""
    schema = model.model_json_schema()
    definitions = schema.pop("$defs", {})

    def resolve(node: Any) -> Any:
        if isinstance(node, dict):
            if "$ref" in node:
                return resolve(definitions[node["$ref"].rsplit("/", 1)[-1]])
            return {key: resolve(value) for key, value in node.items()}
        if isinstance(node, list):
            return [resolve(value) for value in node]
        return node

    return dict(resolve(schema))
