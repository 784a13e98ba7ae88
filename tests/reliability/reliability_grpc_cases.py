"""Every bad-input case of the gRPC API and what the server answers: the list that
test_reliability_grpc.py runs and that docs/RELIABILITY.md's gRPC tables are made from.

A frame case is one DetectRequest against a test server (demo camera, pixel limit 9 Mpx, gRPC
message limit 1 MiB). The frame cases of reliability_cases.py that are about the frame's bytes are
sent as `image` and answered as over REST: 200 is OK, 404 is NOT_FOUND, any other 4xx is
INVALID_ARGUMENT whose details start with the REST error code. Camera ids, min_score and frame_id
are fields here rather than a path and a query, so those cases are written out. Inside a
StreamDetect stream the same frame gets an ERROR answer with the same error code and the stream goes
on; only a message over the gRPC limit ends the stream (the gRPC library refuses it before the
servicer sees it).

A camera case is one registry call (PutCamera, GetCamera, DeleteCamera) that must be refused and
leave the registry as it was.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import grpc
from reliability_cases import FRAME_CASES, MAX_BODY_BYTES, Body, HttpCase, Scenario, expect_text
from reliability_samples import Samples

from protos.fishloc.v1 import localizer_pb2 as pb

MAX_MESSAGE_BYTES = MAX_BODY_BYTES
Code = grpc.StatusCode


@dataclass(frozen=True)
class GrpcExpect:
    """The answer: gRPC status code; `error_code` (the REST code, at the start of the details and in
    a stream's ERROR answer) and a fragment of the message; `person`: an OK whose detections hold
    the person at the right floor position; `ends_stream`: refused by the gRPC library, which ends
    a stream instead of answering the frame."""

    code: Code
    error_code: str = ""
    message: str = ""
    person: bool = False
    ends_stream: bool = False


@dataclass(frozen=True)
class GrpcFrameCase:
    name: str
    what: str
    image: Body
    expect: GrpcExpect
    camera_id: str = "demo"
    min_score: float | None = None
    frame_id: str = "bad-1"
    rest: str | None = None  # the REST case of the same input, when there is one

    def request(self, samples: Samples) -> pb.DetectRequest:
        message = pb.DetectRequest(camera_id=self.camera_id, frame_id=self.frame_id,
                                   image=self.image(samples))
        if self.min_score is not None:
            message.min_score = self.min_score
        return message


def _mirrored(case: HttpCase) -> GrpcFrameCase:
    """A REST frame case sent as DetectRequest.image, expected to be answered as over REST."""
    status = case.expect.status
    code = Code.OK if status == 200 else Code.NOT_FOUND if status == 404 else Code.INVALID_ARGUMENT
    expect = GrpcExpect(code, case.expect.code or "", case.expect.message, person=case.expect.person)
    return GrpcFrameCase(case.name, case.what, case.body, expect, rest=case.name)


def _good(samples: Samples) -> bytes:
    return samples.good_jpeg


def _refused(field_name: str) -> GrpcExpect:
    return GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", field_name)


GRPC_FRAME_CASES: list[GrpcFrameCase] = [
    *(_mirrored(case) for case in FRAME_CASES if case.area == "image"),
    GrpcFrameCase("unknown_camera", "unknown camera", _good,
                  GrpcExpect(Code.NOT_FOUND, "camera_not_found", "'nowhere'"), camera_id="nowhere",
                  rest="unknown_camera"),
    GrpcFrameCase("camera_id_empty", "camera_id not set (empty)", _good, _refused("camera_id"), camera_id=""),
    GrpcFrameCase("camera_id_slash", "camera_id `a/b`", _good, _refused("camera_id"), camera_id="a/b",
                  rest="camera_id_slash"),
    GrpcFrameCase("camera_id_dotdot", "camera_id `..`", _good, _refused("camera_id"), camera_id="..",
                  rest="camera_id_dotdot"),
    GrpcFrameCase("camera_id_unicode", "camera_id `caméra`", _good, _refused("camera_id"),
                  camera_id="caméra", rest="camera_id_unicode"),
    GrpcFrameCase("camera_id_newline", "camera_id `demo` + newline", _good, _refused("camera_id"),
                  camera_id="demo\n"),
    GrpcFrameCase("camera_id_10kb", "10 kB camera_id (not echoed whole)", _good,
                  _refused("10000 characters"), camera_id="a" * 10_000, rest="camera_id_10kb"),
    GrpcFrameCase("min_score_2", "min_score 2", _good, _refused("min_score"), min_score=2.0,
                  rest="min_score_2"),
    GrpcFrameCase("min_score_negative", "min_score -0.1", _good, _refused("min_score"), min_score=-0.1,
                  rest="min_score_negative"),
    GrpcFrameCase("min_score_nan", "min_score NaN", _good, _refused("min_score"), min_score=math.nan,
                  rest="min_score_nan"),
    GrpcFrameCase("min_score_inf", "min_score +inf", _good, _refused("min_score"), min_score=math.inf,
                  rest="min_score_inf"),
    GrpcFrameCase("frame_id_too_long", "frame_id of 200 characters", _good, _refused("frame_id"),
                  frame_id="f" * 200, rest="frame_id_too_long"),
    GrpcFrameCase("message_over_limit", "2 MiB image (message limit 1 MiB)",
                  lambda _samples: bytes(2 * MAX_MESSAGE_BYTES),
                  GrpcExpect(Code.RESOURCE_EXHAUSTED, "", "larger than max", ends_stream=True),
                  rest="body_over_limit"),
]


# ----- the registry


def camera_message(**changes: Any) -> pb.Camera:
    """A valid camera `x` (1000x1000, equidistant-ish), with `changes` applied to its fields."""
    fields: dict[str, Any] = {
        "id": "x", "altitude_m": 3.0, "image_size": pb.ImageSize(width=1000, height=1000),
        "principal_point": pb.Point(x=499.5, y=499.5), "focal_px": pb.Point(x=320.0, y=320.0),
        "kb": [1.0, -0.01],
    }
    fields.update(changes)
    return pb.Camera(**fields)


@dataclass(frozen=True)
class GrpcCameraCase:
    """A registry call that must be refused: PutCamera of `camera()` (also tried as a replacement of
    `demo` unless `id_case`), or GetCamera and DeleteCamera of `camera_id`."""

    name: str
    what: str
    expect: GrpcExpect
    camera: Callable[[], pb.Camera] | None = None
    camera_id: str | None = None
    id_case: bool = False


def _calibration(name: str, what: str, fragment: str, **changes: Any) -> GrpcCameraCase:
    return GrpcCameraCase(name, what, GrpcExpect(Code.INVALID_ARGUMENT, "", fragment),
                          camera=lambda: camera_message(**changes))


def _put_id(name: str, what: str, camera_id: str) -> GrpcCameraCase:
    return GrpcCameraCase(name, what, GrpcExpect(Code.INVALID_ARGUMENT, "", "camera id must be"),
                          camera=lambda: camera_message(id=camera_id), id_case=True)


def _read_id(name: str, what: str, camera_id: str, expect: GrpcExpect) -> GrpcCameraCase:
    return GrpcCameraCase(name, what, expect, camera_id=camera_id)


GRPC_CAMERA_CASES: list[GrpcCameraCase] = [
    _calibration("record_nan", "altitude_m NaN", "altitude_m", altitude_m=math.nan),
    _calibration("record_infinity", "focal_px x +inf", "focal_px", focal_px=pb.Point(x=math.inf, y=320)),
    _calibration("kb_nan", "kb [NaN]", "kb", kb=[math.nan]),
    _calibration("principal_point_nan", "principal point x NaN", "principal_point",
                 principal_point=pb.Point(x=math.nan, y=499.5)),
    _calibration("site_pose_inf", "site pose yaw +inf", "site_pose",
                 site_pose=pb.SitePose(yaw_deg=math.inf)),
    _calibration("max_theta_nan", "max_theta_deg NaN", "max_theta_deg", max_theta_deg=math.nan),
    _calibration("view_budget_over_limit", "max_view_pixels over the server's limit",
                 "view_budget_over_limit", max_view_pixels=64_000_000),
    _calibration("view_budget_tiny", "max_view_pixels 100", "max_view_pixels", max_view_pixels=100),
    _calibration("second_look_negative", "second_look_pixels -1", "second_look_pixels",
                 second_look_pixels=-1),
    _calibration("longest_person_nan", "longest_person_ratio NaN", "longest_person_ratio",
                 longest_person_ratio=math.nan),
    _calibration("altitude_zero", "altitude_m 0", "altitude_m", altitude_m=0.0),
    _calibration("altitude_negative", "altitude_m -3", "altitude_m", altitude_m=-3.0),
    _calibration("focal_negative", "focal_px x -320", "focal_px", focal_px=pb.Point(x=-320, y=320)),
    _calibration("kb_not_increasing", "r(θ) not increasing (kb [1, -0.5])", "strictly increasing",
                 kb=[1.0, -0.5]),
    _calibration("kb_negative_k1", "kb[0] negative", "k1", kb=[-1.0]),
    _calibration("kb_empty", "kb []", "kb", kb=[]),
    _calibration("kb_six", "6 kb coefficients", "kb", kb=[1.0, 0, 0, 0, 0, 0]),
    _calibration("kb_huge", "kb [1e308, 1e308, 1e308]", "kb", kb=[1e308] * 3),
    _calibration("principal_point_outside", "principal point outside the image", "principal_point",
                 principal_point=pb.Point(x=1500, y=499.5)),
    _calibration("image_size_zero", "image_size 0x0 (or not set)", "image_size",
                 image_size=pb.ImageSize(width=0, height=0)),
    _calibration("image_size_negative", "image_size -5x1000", "image_size",
                 image_size=pb.ImageSize(width=-5, height=1000)),
    _calibration("image_size_huge", "image_size (2^31-1)²", "image_size",
                 image_size=pb.ImageSize(width=2**31 - 1, height=2**31 - 1)),
    _put_id("put_id_empty", "PutCamera without id", ""),
    _put_id("put_id_slash", "PutCamera id `a/b`", "a/b"),
    _put_id("put_id_dotdot", "PutCamera id `..`", ".."),
    _put_id("put_id_unicode", "PutCamera id `caméra`", "caméra"),
    _put_id("put_id_newline", "PutCamera id `demo` + newline", "demo\n"),
    _put_id("put_id_10kb", "PutCamera 10 kB id", "b" * 10_000),
    _read_id("get_unknown", "GetCamera/DeleteCamera of an unknown camera", "nowhere",
             GrpcExpect(Code.NOT_FOUND, "", "'nowhere'")),
    _read_id("get_id_empty", "GetCamera/DeleteCamera without id", "",
             GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", "camera_id")),
    _read_id("get_id_slash", "GetCamera/DeleteCamera id `a/b`", "a/b",
             GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", "camera_id")),
    _read_id("get_id_dotdot", "GetCamera/DeleteCamera id `..`", "..",
             GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", "camera_id")),
    _read_id("get_id_unicode", "GetCamera/DeleteCamera id `caméra`", "caméra",
             GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", "camera_id")),
    _read_id("get_id_10kb", "GetCamera/DeleteCamera 10 kB id (not echoed whole)", "c" * 10_000,
             GrpcExpect(Code.INVALID_ARGUMENT, "invalid_request", "10000 characters")),
]


# ----- non-request scenarios of gRPC (the tests assert these codes)

T = "tests/reliability/"

GRPC_SCENARIOS: list[Scenario] = [
    Scenario("tls_grpc", "access", "FISHLOC_TLS_CERT/KEY set to a self-signed certificate",
             "gRPC over TLS: Detect OK and health SERVING for a client trusting that certificate; a "
             "client with the system's roots, and a plain-text client, get UNAVAILABLE",
             T + "test_reliability_grpc_access.py::test_grpc_over_tls"),
    Scenario("detect_token_grpc", "access", "FISHLOC_DETECT_TOKEN set: Detect and StreamDetect without, "
             "with a wrong, or with a non-Bearer `authorization` metadata",
             "UNAUTHENTICATED; the detect token and the API token both detect (OK); without "
             "FISHLOC_DETECT_TOKEN detection is open",
             T + "test_reliability_grpc_access.py::test_grpc_detect_token"),
    Scenario("registry_token_grpc", "access", "FISHLOC_API_TOKEN set: PutCamera and DeleteCamera without "
             "a token, with a wrong one, or with the detect token",
             "UNAUTHENTICATED and the registry unchanged; with the API token OK; reads open",
             T + "test_reliability_grpc_access.py::test_grpc_registry_writes_need_the_api_token"),
]


def frame_case_test_id(case: GrpcFrameCase) -> str:
    return f"tests/reliability/test_reliability_grpc.py::test_grpc_frame_case[{case.name}]"


def camera_case_test_id(case: GrpcCameraCase) -> str:
    return f"tests/reliability/test_reliability_grpc.py::test_grpc_camera_case[{case.name}]"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _unary_text(expect: GrpcExpect) -> str:
    if expect.code == Code.OK:
        return "OK, person found at the right floor position" if expect.person else "OK"
    code = expect.code.name
    return f"{code} `{expect.error_code}`" if expect.error_code else code


def _stream_text(expect: GrpcExpect) -> str:
    if expect.ends_stream:
        return f"stream ends with {expect.code.name}; a new stream is served"
    if expect.code == Code.OK:
        return "OK; next frame OK"
    return f"ERROR `{expect.error_code}`; next frame OK"


def grpc_markdown_tables(rest: dict[str, HttpCase]) -> list[str]:
    """The gRPC tables of docs/RELIABILITY.md (`rest`: the REST cases by name)."""
    lines = [
        "| gRPC case | DetectRequest | Detect answers | in StreamDetect | REST answer | message holds "
        "| reproduce |",
        "|---|---|---|---|---|---|---|",
    ]
    for case in GRPC_FRAME_CASES:
        rest_text = expect_text(rest[case.rest].expect) if case.rest is not None else "-"
        lines.append(
            f"| `{case.name}` | {_cell(case.what)} | {_unary_text(case.expect)} | "
            f"{_stream_text(case.expect)} | {rest_text} | {_cell(case.expect.message) or '-'} | "
            f"`{frame_case_test_id(case)}` |"
        )
    lines += [
        "",
        "| gRPC registry case | call | answer | message holds | registry after | reproduce |",
        "|---|---|---|---|---|---|",
    ]
    for row in GRPC_CAMERA_CASES:
        call = "GetCamera, DeleteCamera" if row.camera is None else (
            "PutCamera" if row.id_case else "PutCamera (new camera and replacing `demo`)")
        lines.append(
            f"| `{row.name}` | {call}: {_cell(row.what)} | {_unary_text(row.expect)} | "
            f"{_cell(row.expect.message)} | unchanged | `{camera_case_test_id(row)}` |"
        )
    return lines
