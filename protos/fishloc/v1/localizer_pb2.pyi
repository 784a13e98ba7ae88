import datetime

from google.protobuf import timestamp_pb2 as _timestamp_pb2
from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class DetectRequest(_message.Message):
    __slots__ = ("camera_id", "frame_id", "capture_time", "image", "min_score")
    CAMERA_ID_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_FIELD_NUMBER: _ClassVar[int]
    IMAGE_FIELD_NUMBER: _ClassVar[int]
    MIN_SCORE_FIELD_NUMBER: _ClassVar[int]
    camera_id: str
    frame_id: str
    capture_time: _timestamp_pb2.Timestamp
    image: bytes
    min_score: float
    def __init__(self, camera_id: _Optional[str] = ..., frame_id: _Optional[str] = ..., capture_time: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., image: _Optional[bytes] = ..., min_score: _Optional[float] = ...) -> None: ...

class Point(_message.Message):
    __slots__ = ("x", "y")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ...) -> None: ...

class Box(_message.Message):
    __slots__ = ("cx", "cy", "w", "h", "angle_deg")
    CX_FIELD_NUMBER: _ClassVar[int]
    CY_FIELD_NUMBER: _ClassVar[int]
    W_FIELD_NUMBER: _ClassVar[int]
    H_FIELD_NUMBER: _ClassVar[int]
    ANGLE_DEG_FIELD_NUMBER: _ClassVar[int]
    cx: float
    cy: float
    w: float
    h: float
    angle_deg: float
    def __init__(self, cx: _Optional[float] = ..., cy: _Optional[float] = ..., w: _Optional[float] = ..., h: _Optional[float] = ..., angle_deg: _Optional[float] = ...) -> None: ...

class Detection(_message.Message):
    __slots__ = ("score", "box", "corners", "foot_px", "position_m", "distance_m", "site_position_m", "track_id")
    SCORE_FIELD_NUMBER: _ClassVar[int]
    BOX_FIELD_NUMBER: _ClassVar[int]
    CORNERS_FIELD_NUMBER: _ClassVar[int]
    FOOT_PX_FIELD_NUMBER: _ClassVar[int]
    POSITION_M_FIELD_NUMBER: _ClassVar[int]
    DISTANCE_M_FIELD_NUMBER: _ClassVar[int]
    SITE_POSITION_M_FIELD_NUMBER: _ClassVar[int]
    TRACK_ID_FIELD_NUMBER: _ClassVar[int]
    score: float
    box: Box
    corners: _containers.RepeatedCompositeFieldContainer[Point]
    foot_px: Point
    position_m: Point
    distance_m: float
    site_position_m: Point
    track_id: str
    def __init__(self, score: _Optional[float] = ..., box: _Optional[_Union[Box, _Mapping]] = ..., corners: _Optional[_Iterable[_Union[Point, _Mapping]]] = ..., foot_px: _Optional[_Union[Point, _Mapping]] = ..., position_m: _Optional[_Union[Point, _Mapping]] = ..., distance_m: _Optional[float] = ..., site_position_m: _Optional[_Union[Point, _Mapping]] = ..., track_id: _Optional[str] = ...) -> None: ...

class ImageSize(_message.Message):
    __slots__ = ("width", "height")
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_FIELD_NUMBER: _ClassVar[int]
    width: int
    height: int
    def __init__(self, width: _Optional[int] = ..., height: _Optional[int] = ...) -> None: ...

class ModelRef(_message.Message):
    __slots__ = ("name", "version")
    NAME_FIELD_NUMBER: _ClassVar[int]
    VERSION_FIELD_NUMBER: _ClassVar[int]
    name: str
    version: str
    def __init__(self, name: _Optional[str] = ..., version: _Optional[str] = ...) -> None: ...

class Timing(_message.Message):
    __slots__ = ("decode", "preprocess", "inference", "postprocess", "total")
    DECODE_FIELD_NUMBER: _ClassVar[int]
    PREPROCESS_FIELD_NUMBER: _ClassVar[int]
    INFERENCE_FIELD_NUMBER: _ClassVar[int]
    POSTPROCESS_FIELD_NUMBER: _ClassVar[int]
    TOTAL_FIELD_NUMBER: _ClassVar[int]
    decode: float
    preprocess: float
    inference: float
    postprocess: float
    total: float
    def __init__(self, decode: _Optional[float] = ..., preprocess: _Optional[float] = ..., inference: _Optional[float] = ..., postprocess: _Optional[float] = ..., total: _Optional[float] = ...) -> None: ...

class DetectResponse(_message.Message):
    __slots__ = ("camera_id", "frame_id", "capture_time", "status", "error_code", "error_message", "image", "model", "detections", "timing_ms", "site_note")
    class Status(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        STATUS_UNSPECIFIED: _ClassVar[DetectResponse.Status]
        OK: _ClassVar[DetectResponse.Status]
        DROPPED: _ClassVar[DetectResponse.Status]
        ERROR: _ClassVar[DetectResponse.Status]
    STATUS_UNSPECIFIED: DetectResponse.Status
    OK: DetectResponse.Status
    DROPPED: DetectResponse.Status
    ERROR: DetectResponse.Status
    CAMERA_ID_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    CAPTURE_TIME_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    ERROR_CODE_FIELD_NUMBER: _ClassVar[int]
    ERROR_MESSAGE_FIELD_NUMBER: _ClassVar[int]
    IMAGE_FIELD_NUMBER: _ClassVar[int]
    MODEL_FIELD_NUMBER: _ClassVar[int]
    DETECTIONS_FIELD_NUMBER: _ClassVar[int]
    TIMING_MS_FIELD_NUMBER: _ClassVar[int]
    SITE_NOTE_FIELD_NUMBER: _ClassVar[int]
    camera_id: str
    frame_id: str
    capture_time: _timestamp_pb2.Timestamp
    status: DetectResponse.Status
    error_code: str
    error_message: str
    image: ImageSize
    model: ModelRef
    detections: _containers.RepeatedCompositeFieldContainer[Detection]
    timing_ms: Timing
    site_note: str
    def __init__(self, camera_id: _Optional[str] = ..., frame_id: _Optional[str] = ..., capture_time: _Optional[_Union[datetime.datetime, _timestamp_pb2.Timestamp, _Mapping]] = ..., status: _Optional[_Union[DetectResponse.Status, str]] = ..., error_code: _Optional[str] = ..., error_message: _Optional[str] = ..., image: _Optional[_Union[ImageSize, _Mapping]] = ..., model: _Optional[_Union[ModelRef, _Mapping]] = ..., detections: _Optional[_Iterable[_Union[Detection, _Mapping]]] = ..., timing_ms: _Optional[_Union[Timing, _Mapping]] = ..., site_note: _Optional[str] = ...) -> None: ...

class SitePose(_message.Message):
    __slots__ = ("x_m", "y_m", "yaw_deg")
    X_M_FIELD_NUMBER: _ClassVar[int]
    Y_M_FIELD_NUMBER: _ClassVar[int]
    YAW_DEG_FIELD_NUMBER: _ClassVar[int]
    x_m: float
    y_m: float
    yaw_deg: float
    def __init__(self, x_m: _Optional[float] = ..., y_m: _Optional[float] = ..., yaw_deg: _Optional[float] = ...) -> None: ...

class Camera(_message.Message):
    __slots__ = ("id", "altitude_m", "image_size", "principal_point", "focal_px", "kb", "max_theta_deg", "site_pose", "site", "tilt_deg", "masks_px", "max_view_pixels", "second_look_pixels", "longest_person_ratio")
    ID_FIELD_NUMBER: _ClassVar[int]
    ALTITUDE_M_FIELD_NUMBER: _ClassVar[int]
    IMAGE_SIZE_FIELD_NUMBER: _ClassVar[int]
    PRINCIPAL_POINT_FIELD_NUMBER: _ClassVar[int]
    FOCAL_PX_FIELD_NUMBER: _ClassVar[int]
    KB_FIELD_NUMBER: _ClassVar[int]
    MAX_THETA_DEG_FIELD_NUMBER: _ClassVar[int]
    SITE_POSE_FIELD_NUMBER: _ClassVar[int]
    SITE_FIELD_NUMBER: _ClassVar[int]
    TILT_DEG_FIELD_NUMBER: _ClassVar[int]
    MASKS_PX_FIELD_NUMBER: _ClassVar[int]
    MAX_VIEW_PIXELS_FIELD_NUMBER: _ClassVar[int]
    SECOND_LOOK_PIXELS_FIELD_NUMBER: _ClassVar[int]
    LONGEST_PERSON_RATIO_FIELD_NUMBER: _ClassVar[int]
    id: str
    altitude_m: float
    image_size: ImageSize
    principal_point: Point
    focal_px: Point
    kb: _containers.RepeatedScalarFieldContainer[float]
    max_theta_deg: float
    site_pose: SitePose
    site: str
    tilt_deg: Point
    masks_px: _containers.RepeatedCompositeFieldContainer[Polygon]
    max_view_pixels: int
    second_look_pixels: int
    longest_person_ratio: float
    def __init__(self, id: _Optional[str] = ..., altitude_m: _Optional[float] = ..., image_size: _Optional[_Union[ImageSize, _Mapping]] = ..., principal_point: _Optional[_Union[Point, _Mapping]] = ..., focal_px: _Optional[_Union[Point, _Mapping]] = ..., kb: _Optional[_Iterable[float]] = ..., max_theta_deg: _Optional[float] = ..., site_pose: _Optional[_Union[SitePose, _Mapping]] = ..., site: _Optional[str] = ..., tilt_deg: _Optional[_Union[Point, _Mapping]] = ..., masks_px: _Optional[_Iterable[_Union[Polygon, _Mapping]]] = ..., max_view_pixels: _Optional[int] = ..., second_look_pixels: _Optional[int] = ..., longest_person_ratio: _Optional[float] = ...) -> None: ...

class Polygon(_message.Message):
    __slots__ = ("points",)
    POINTS_FIELD_NUMBER: _ClassVar[int]
    points: _containers.RepeatedCompositeFieldContainer[Point]
    def __init__(self, points: _Optional[_Iterable[_Union[Point, _Mapping]]] = ...) -> None: ...

class ListCamerasRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class ListCamerasResponse(_message.Message):
    __slots__ = ("cameras",)
    CAMERAS_FIELD_NUMBER: _ClassVar[int]
    cameras: _containers.RepeatedCompositeFieldContainer[Camera]
    def __init__(self, cameras: _Optional[_Iterable[_Union[Camera, _Mapping]]] = ...) -> None: ...

class GetCameraRequest(_message.Message):
    __slots__ = ("camera_id",)
    CAMERA_ID_FIELD_NUMBER: _ClassVar[int]
    camera_id: str
    def __init__(self, camera_id: _Optional[str] = ...) -> None: ...

class PutCameraRequest(_message.Message):
    __slots__ = ("camera",)
    CAMERA_FIELD_NUMBER: _ClassVar[int]
    camera: Camera
    def __init__(self, camera: _Optional[_Union[Camera, _Mapping]] = ...) -> None: ...

class PutCameraResponse(_message.Message):
    __slots__ = ("camera", "created")
    CAMERA_FIELD_NUMBER: _ClassVar[int]
    CREATED_FIELD_NUMBER: _ClassVar[int]
    camera: Camera
    created: bool
    def __init__(self, camera: _Optional[_Union[Camera, _Mapping]] = ..., created: _Optional[bool] = ...) -> None: ...

class DeleteCameraRequest(_message.Message):
    __slots__ = ("camera_id",)
    CAMERA_ID_FIELD_NUMBER: _ClassVar[int]
    camera_id: str
    def __init__(self, camera_id: _Optional[str] = ...) -> None: ...

class DeleteCameraResponse(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class GetModelRequest(_message.Message):
    __slots__ = ()
    def __init__(self) -> None: ...

class OperatingPoint(_message.Message):
    __slots__ = ("min_score", "nms_iou")
    MIN_SCORE_FIELD_NUMBER: _ClassVar[int]
    NMS_IOU_FIELD_NUMBER: _ClassVar[int]
    min_score: float
    nms_iou: float
    def __init__(self, min_score: _Optional[float] = ..., nms_iou: _Optional[float] = ...) -> None: ...

class ModelInfo(_message.Message):
    __slots__ = ("name", "version", "input_size", "trained_on", "box_format", "default_min_score", "pad_value", "sha256", "nms_iou", "view_operating_points")
    class ViewOperatingPointsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: OperatingPoint
        def __init__(self, key: _Optional[str] = ..., value: _Optional[_Union[OperatingPoint, _Mapping]] = ...) -> None: ...
    NAME_FIELD_NUMBER: _ClassVar[int]
    VERSION_FIELD_NUMBER: _ClassVar[int]
    INPUT_SIZE_FIELD_NUMBER: _ClassVar[int]
    TRAINED_ON_FIELD_NUMBER: _ClassVar[int]
    BOX_FORMAT_FIELD_NUMBER: _ClassVar[int]
    DEFAULT_MIN_SCORE_FIELD_NUMBER: _ClassVar[int]
    PAD_VALUE_FIELD_NUMBER: _ClassVar[int]
    SHA256_FIELD_NUMBER: _ClassVar[int]
    NMS_IOU_FIELD_NUMBER: _ClassVar[int]
    VIEW_OPERATING_POINTS_FIELD_NUMBER: _ClassVar[int]
    name: str
    version: str
    input_size: int
    trained_on: str
    box_format: str
    default_min_score: float
    pad_value: int
    sha256: str
    nms_iou: float
    view_operating_points: _containers.MessageMap[str, OperatingPoint]
    def __init__(self, name: _Optional[str] = ..., version: _Optional[str] = ..., input_size: _Optional[int] = ..., trained_on: _Optional[str] = ..., box_format: _Optional[str] = ..., default_min_score: _Optional[float] = ..., pad_value: _Optional[int] = ..., sha256: _Optional[str] = ..., nms_iou: _Optional[float] = ..., view_operating_points: _Optional[_Mapping[str, OperatingPoint]] = ...) -> None: ...

class WatchSiteRequest(_message.Message):
    __slots__ = ("site",)
    SITE_FIELD_NUMBER: _ClassVar[int]
    site: str
    def __init__(self, site: _Optional[str] = ...) -> None: ...

class TrackedPerson(_message.Message):
    __slots__ = ("track_id", "position_m", "velocity_mps", "cameras", "first_seen", "last_seen", "dwell_s")
    class DwellSEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: float
        def __init__(self, key: _Optional[str] = ..., value: _Optional[float] = ...) -> None: ...
    TRACK_ID_FIELD_NUMBER: _ClassVar[int]
    POSITION_M_FIELD_NUMBER: _ClassVar[int]
    VELOCITY_MPS_FIELD_NUMBER: _ClassVar[int]
    CAMERAS_FIELD_NUMBER: _ClassVar[int]
    FIRST_SEEN_FIELD_NUMBER: _ClassVar[int]
    LAST_SEEN_FIELD_NUMBER: _ClassVar[int]
    DWELL_S_FIELD_NUMBER: _ClassVar[int]
    track_id: str
    position_m: Point
    velocity_mps: Point
    cameras: _containers.RepeatedScalarFieldContainer[str]
    first_seen: float
    last_seen: float
    dwell_s: _containers.ScalarMap[str, float]
    def __init__(self, track_id: _Optional[str] = ..., position_m: _Optional[_Union[Point, _Mapping]] = ..., velocity_mps: _Optional[_Union[Point, _Mapping]] = ..., cameras: _Optional[_Iterable[str]] = ..., first_seen: _Optional[float] = ..., last_seen: _Optional[float] = ..., dwell_s: _Optional[_Mapping[str, float]] = ...) -> None: ...

class ZoneCount(_message.Message):
    __slots__ = ("count",)
    COUNT_FIELD_NUMBER: _ClassVar[int]
    count: int
    def __init__(self, count: _Optional[int] = ...) -> None: ...

class LineCount(_message.Message):
    __slots__ = ("in_count", "out_count")
    IN_COUNT_FIELD_NUMBER: _ClassVar[int]
    OUT_COUNT_FIELD_NUMBER: _ClassVar[int]
    in_count: int
    out_count: int
    def __init__(self, in_count: _Optional[int] = ..., out_count: _Optional[int] = ...) -> None: ...

class SiteOccupancy(_message.Message):
    __slots__ = ("site", "time", "count", "people", "zones", "lines")
    class ZonesEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: ZoneCount
        def __init__(self, key: _Optional[str] = ..., value: _Optional[_Union[ZoneCount, _Mapping]] = ...) -> None: ...
    class LinesEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: LineCount
        def __init__(self, key: _Optional[str] = ..., value: _Optional[_Union[LineCount, _Mapping]] = ...) -> None: ...
    SITE_FIELD_NUMBER: _ClassVar[int]
    TIME_FIELD_NUMBER: _ClassVar[int]
    COUNT_FIELD_NUMBER: _ClassVar[int]
    PEOPLE_FIELD_NUMBER: _ClassVar[int]
    ZONES_FIELD_NUMBER: _ClassVar[int]
    LINES_FIELD_NUMBER: _ClassVar[int]
    site: str
    time: float
    count: int
    people: _containers.RepeatedCompositeFieldContainer[TrackedPerson]
    zones: _containers.MessageMap[str, ZoneCount]
    lines: _containers.MessageMap[str, LineCount]
    def __init__(self, site: _Optional[str] = ..., time: _Optional[float] = ..., count: _Optional[int] = ..., people: _Optional[_Iterable[_Union[TrackedPerson, _Mapping]]] = ..., zones: _Optional[_Mapping[str, ZoneCount]] = ..., lines: _Optional[_Mapping[str, LineCount]] = ...) -> None: ...
