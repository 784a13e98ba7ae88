"""Every bad-input case of the REST API and what the server answers: the one list that the tests
run (test_reliability_bad_input.py) and that docs/RELIABILITY.md's table is made from (`python
tests/reliability/reliability_cases.py` prints it; test_reliability_doc.py checks the document).

A case is one HTTP request against a test server (demo camera, body limit 1 MiB, pixel limit 9 Mpx)
and the answer expected: status, error code and a fragment of the message. After every case the
server must still answer a good frame with the person at the right floor position.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from reliability_samples import Samples, jpeg_claiming, png_claiming, png_zero_bomb

MAX_BODY_BYTES = 1024 * 1024
MAX_PIXELS = 9_000_000
DETECT = "/v1/cameras/demo/detect"
JPEG = {"content-type": "image/jpeg"}
PNG = {"content-type": "image/png"}
JSON = {"content-type": "application/json"}
FORM = {"content-type": "multipart/form-data; boundary=fishloc-boundary"}

Body = Callable[[Samples], bytes]


@dataclass(frozen=True)
class Expect:
    """The answer: HTTP status, error code (None: a success, or uvicorn's own error), message fragment;
    `person`: a 200 whose detections must hold the person at the right floor position."""

    status: int
    code: str | None = None
    message: str = ""
    person: bool = False


@dataclass(frozen=True)
class HttpCase:
    name: str
    area: str
    what: str
    method: str
    path: str
    body: Body
    expect: Expect
    headers: dict[str, str] = field(default_factory=dict)
    chunked: bool = False


def _const(data: bytes) -> Body:
    return lambda _samples: data


def _camera_record(**changes: object) -> Body:
    record: dict[str, object] = {
        "altitude_m": 3.0, "image_size": [1000, 1000], "principal_point": [499.5, 499.5],
        "focal_px": [320.0, 320.0], "kb": [1.0, -0.01],
    }
    record.update(changes)
    return _const(json.dumps(record, allow_nan=True).encode())


def _raw_record(text: str) -> Body:
    return _const(text.encode())


_RECORD = ('{"altitude_m": %s, "image_size": [1000, 1000], "principal_point": [499.5, 499.5], '
           '"focal_px": [%s, 320.0], "kb": [1.0]}')

FRAME_CASES: list[HttpCase] = [
    # ----- encodings that are processed
    HttpCase("jpeg_baseline", "image", "good JPEG (reference)", "POST", DETECT,
             lambda s: s.good_jpeg, Expect(200, person=True), JPEG),
    HttpCase("jpeg_progressive", "image", "progressive JPEG", "POST", DETECT,
             lambda s: s.jpeg_progressive, Expect(200, person=True), JPEG),
    HttpCase("png_16bit", "image", "16-bit RGB PNG (scaled to 8 bits)", "POST", DETECT,
             lambda s: s.png_16bit, Expect(200, person=True), PNG),
    HttpCase("png_gray", "image", "8-bit grayscale PNG (gray copied to R, G, B)", "POST", DETECT,
             lambda s: s.png_gray, Expect(200, person=True), PNG),
    HttpCase("png_gray_16bit", "image", "16-bit grayscale PNG", "POST", DETECT,
             lambda s: s.png_gray_16bit, Expect(200, person=True), PNG),
    HttpCase("png_rgba", "image", "RGBA PNG, alpha 50% (alpha ignored)", "POST", DETECT,
             lambda s: s.png_rgba, Expect(200, person=True), PNG),
    HttpCase("png_palette", "image", "palette PNG (expanded)", "POST", DETECT,
             lambda s: s.png_palette, Expect(200, person=True), PNG),
    HttpCase("jpeg_cmyk", "image", "CMYK JPEG (Adobe, made by Pillow; converted to RGB)", "POST", DETECT,
             lambda s: s.jpeg_cmyk, Expect(200, person=True), JPEG),
    # ----- frames that are refused
    HttpCase("empty_body", "image", "empty body", "POST", DETECT, _const(b""),
             Expect(400, "empty_body", "no image"), JPEG),
    HttpCase("random_bytes", "image", "4 kB of random bytes", "POST", DETECT,
             lambda s: s.random_bytes, Expect(415, "unsupported_image", "neither JPEG nor PNG"), JPEG),
    HttpCase("random_after_jpeg_magic", "image", "JPEG magic then random bytes", "POST", DETECT,
             lambda s: s.random_after_jpeg_magic, Expect(400, "bad_image", "corrupt JPEG"), JPEG),
    HttpCase("jpeg_truncated", "image", "JPEG cut in half", "POST", DETECT,
             lambda s: s.jpeg_truncated, Expect(400, "bad_image", "cannot decode"), JPEG),
    HttpCase("jpeg_header_only", "image", "JPEG cut at the start of scan", "POST", DETECT,
             lambda s: s.jpeg_header_only, Expect(400, "bad_image", "cannot decode"), JPEG),
    HttpCase("png_truncated", "image", "PNG cut in half", "POST", DETECT,
             lambda s: s.png_truncated, Expect(400, "bad_image", "cannot decode"), PNG),
    HttpCase("png_bomb_header", "image", "100-byte PNG whose header claims 100000x100000",
             "POST", DETECT, _const(png_claiming(100_000, 100_000)),
             Expect(413, "image_too_large", "100000x100000"), PNG),
    HttpCase("png_bomb_zlib", "image", "valid 5000x5000 PNG of zeros (~40 kB, 75 MB decoded)",
             "POST", DETECT, _const(png_zero_bomb(5000)), Expect(413, "image_too_large", "5000x5000"), PNG),
    HttpCase("jpeg_bomb_header", "image", "JPEG whose frame header claims 60000x60000", "POST", DETECT,
             _const(jpeg_claiming(60_000, 60_000)), Expect(413, "image_too_large", "60000x60000"), JPEG),
    HttpCase("one_pixel", "image", "1x1 JPEG", "POST", DETECT, lambda s: s.black_jpeg(1, 1),
             Expect(422, "frame_too_small", "at least 16 px"), JPEG),
    HttpCase("thin_2048x1", "image", "2048x1 JPEG", "POST", DETECT, lambda s: s.black_jpeg(2048, 1),
             Expect(422, "frame_too_small", "at least 16 px"), JPEG),
    HttpCase("thin_1024x16", "image", "1024x16 JPEG", "POST", DETECT, lambda s: s.black_jpeg(1024, 16),
             Expect(422, "frame_size_mismatch", "aspect ratio"), JPEG),
    HttpCase("non_square", "image", "640x480 frame for a square camera", "POST", DETECT,
             lambda s: s.black_jpeg(640, 480), Expect(422, "frame_size_mismatch", "aspect ratio"), JPEG),
    # ----- bodies and content types
    HttpCase("body_over_limit", "body", "2 MiB body with Content-Length (limit 1 MiB)", "POST", DETECT,
             _const(bytes(2 * MAX_BODY_BYTES)), Expect(413, "payload_too_large", "limit is 1048576"), JPEG),
    HttpCase("body_over_limit_chunked", "body", "2 MiB chunked body (no Content-Length)", "POST", DETECT,
             _const(bytes(2 * MAX_BODY_BYTES)), Expect(413, "payload_too_large", "passes the limit"), JPEG,
             chunked=True),
    HttpCase("content_length_10gb", "body", "Content-Length: 10 GB, 10 bytes sent (refused unread)",
             "POST", DETECT, _const(bytes(10)), Expect(413, "payload_too_large", "10000000000 bytes"),
             {**JPEG, "content-length": "10000000000"}),
    HttpCase("content_length_garbage", "body", "Content-Length: abc", "POST", DETECT, _const(b"x"),
             Expect(400), {**JPEG, "content-length": "abc"}),
    HttpCase("content_type_text", "body", "Content-Type: text/plain", "POST", DETECT,
             lambda s: s.good_jpeg, Expect(415, "unsupported_media_type", "text/plain"),
             {"content-type": "text/plain"}),
    HttpCase("content_type_missing", "body", "no Content-Type", "POST", DETECT, lambda s: s.good_jpeg,
             Expect(415, "unsupported_media_type", "(none)")),
    HttpCase("content_type_gif", "body", "Content-Type: image/gif", "POST", DETECT, lambda s: s.good_jpeg,
             Expect(415, "unsupported_media_type", "image/gif"), {"content-type": "image/gif"}),
    HttpCase("multipart_ok", "body", "multipart field `image` (reference)", "POST", DETECT,
             lambda s: Samples.multipart("image", s.good_jpeg), Expect(200, person=True), FORM),
    HttpCase("multipart_malformed", "body", "multipart body without parts", "POST", DETECT,
             _const(b"--x\r\nbroken"), Expect(400, "bad_multipart", "unreadable multipart"), FORM),
    HttpCase("multipart_no_boundary", "body", "multipart Content-Type without boundary", "POST", DETECT,
             _const(b"abc"), Expect(400, "bad_multipart", "boundary"),
             {"content-type": "multipart/form-data"}),
    HttpCase("multipart_binary_garbage", "body", "multipart of random bytes", "POST", DETECT,
             lambda s: s.random_bytes, Expect(400, "bad_multipart", "unreadable multipart"), FORM),
    HttpCase("multipart_no_image_field", "body", "multipart without field `image`", "POST", DETECT,
             lambda s: Samples.multipart("frame", s.good_jpeg), Expect(422, "missing_image", "'image'"),
             FORM),
    # ----- cameras in the path and query parameters
    HttpCase("unknown_camera", "camera id", "unknown camera", "POST", "/v1/cameras/nowhere/detect",
             lambda s: s.good_jpeg, Expect(404, "camera_not_found", "'nowhere'"), JPEG),
    HttpCase("camera_id_slash", "camera id", "id with `/` (a/b)", "POST", "/v1/cameras/a/b/detect",
             lambda s: s.good_jpeg, Expect(404, "not_found", "Not Found"), JPEG),
    HttpCase("camera_id_encoded_slash", "camera id", "id with `%2F`", "POST",
             "/v1/cameras/a%2Fb/detect", lambda s: s.good_jpeg, Expect(404, "not_found", "Not Found"), JPEG),
    HttpCase("camera_id_dotdot", "camera id", "id `..` (sent unnormalised)", "POST",
             "/v1/cameras/../detect", lambda s: s.good_jpeg, Expect(422, "invalid_request", "camera_id"),
             JPEG),
    HttpCase("camera_id_unicode", "camera id", "id `caméra` (UTF-8)", "POST",
             "/v1/cameras/cam%C3%A9ra/detect", lambda s: s.good_jpeg,
             Expect(422, "invalid_request", "camera_id"), JPEG),
    HttpCase("camera_id_bad_utf8", "camera id", "id with an invalid UTF-8 byte (%FF)", "POST",
             "/v1/cameras/cam%FF/detect", lambda s: s.good_jpeg, Expect(422, "invalid_request", "camera_id"),
             JPEG),
    HttpCase("camera_id_10kb", "camera id", "10 kB id", "POST", "/v1/cameras/" + "a" * 10_000 + "/detect",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "camera_id"), JPEG),
    HttpCase("min_score_2", "query", "min_score=2", "POST", DETECT + "?min_score=2", lambda s: s.good_jpeg,
             Expect(422, "invalid_request", "min_score"), JPEG),
    HttpCase("min_score_negative", "query", "min_score=-0.1", "POST", DETECT + "?min_score=-0.1",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "min_score"), JPEG),
    HttpCase("min_score_nan", "query", "min_score=nan", "POST", DETECT + "?min_score=nan",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "min_score"), JPEG),
    HttpCase("min_score_inf", "query", "min_score=inf", "POST", DETECT + "?min_score=inf",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "min_score"), JPEG),
    HttpCase("min_score_text", "query", "min_score=abc", "POST", DETECT + "?min_score=abc",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "min_score"), JPEG),
    HttpCase("frame_id_too_long", "query", "frame_id of 200 characters", "POST",
             DETECT + "?frame_id=" + "f" * 200, lambda s: s.good_jpeg,
             Expect(422, "invalid_request", "frame_id"), JPEG),
]

CAMERA_CASES: list[HttpCase] = [
    HttpCase("record_nan", "calibration", "altitude_m NaN", "PUT", "/v1/cameras/x",
             _raw_record(_RECORD % ("NaN", "320.0")), Expect(422, "invalid_camera", "altitude_m"), JSON),
    HttpCase("record_infinity", "calibration", "focal_px Infinity", "PUT", "/v1/cameras/x",
             _raw_record(_RECORD % ("3.0", "Infinity")), Expect(422, "invalid_camera", "focal_px"), JSON),
    HttpCase("record_overflow", "calibration", "focal_px 1e999 (inf once parsed)", "PUT", "/v1/cameras/x",
             _raw_record(_RECORD % ("3.0", "1e999")), Expect(422, "invalid_camera", "focal_px"), JSON),
    HttpCase("view_budget_over_limit", "calibration", "max_view_pixels over the server's limit", "PUT",
             "/v1/cameras/x", _camera_record(max_view_pixels=64_000_000),
             Expect(422, "view_budget_over_limit", "--max-camera-view-pixels"), JSON),
    HttpCase("view_budget_tiny", "calibration", "max_view_pixels 100", "PUT", "/v1/cameras/x",
             _camera_record(max_view_pixels=100), Expect(422, "invalid_camera", "max_view_pixels"), JSON),
    HttpCase("second_look_negative", "calibration", "second_look_pixels -1", "PUT", "/v1/cameras/x",
             _camera_record(second_look_pixels=-1), Expect(422, "invalid_camera", "second_look_pixels"),
             JSON),
    HttpCase("longest_person_half", "calibration", "longest_person_ratio 0.5", "PUT", "/v1/cameras/x",
             _camera_record(longest_person_ratio=0.5), Expect(422, "invalid_camera", "longest_person_ratio"),
             JSON),
    HttpCase("altitude_zero", "calibration", "altitude_m 0", "PUT", "/v1/cameras/x",
             _camera_record(altitude_m=0), Expect(422, "invalid_camera", "altitude_m"), JSON),
    HttpCase("altitude_negative", "calibration", "altitude_m -3", "PUT", "/v1/cameras/x",
             _camera_record(altitude_m=-3), Expect(422, "invalid_camera", "altitude_m"), JSON),
    HttpCase("focal_negative", "calibration", "focal_px negative", "PUT", "/v1/cameras/x",
             _camera_record(focal_px=[-320, 320]), Expect(422, "invalid_camera", "focal_px"), JSON),
    HttpCase("kb_not_increasing", "calibration", "r(θ) not increasing (kb [1, -0.5])", "PUT",
             "/v1/cameras/x", _camera_record(kb=[1.0, -0.5]),
             Expect(422, "invalid_camera", "strictly increasing"), JSON),
    HttpCase("kb_negative_k1", "calibration", "kb[0] negative", "PUT", "/v1/cameras/x",
             _camera_record(kb=[-1.0]), Expect(422, "invalid_camera", "k1"), JSON),
    HttpCase("kb_empty", "calibration", "kb []", "PUT", "/v1/cameras/x", _camera_record(kb=[]),
             Expect(422, "invalid_camera", "kb"), JSON),
    HttpCase("kb_six", "calibration", "6 kb coefficients", "PUT", "/v1/cameras/x",
             _camera_record(kb=[1, 0, 0, 0, 0, 0]), Expect(422, "invalid_camera", "kb"), JSON),
    HttpCase("kb_huge", "calibration", "kb [1e308, 1e308, 1e308]", "PUT", "/v1/cameras/x",
             _camera_record(kb=[1e308, 1e308, 1e308]), Expect(422, "invalid_camera", "kb"), JSON),
    HttpCase("principal_point_outside", "calibration", "principal point outside the image", "PUT",
             "/v1/cameras/x", _camera_record(principal_point=[1500, 499.5]),
             Expect(422, "invalid_camera", "principal_point"), JSON),
    HttpCase("image_size_zero", "calibration", "image_size [0, 0]", "PUT", "/v1/cameras/x",
             _camera_record(image_size=[0, 0]), Expect(422, "invalid_camera", "image_size"), JSON),
    HttpCase("image_size_huge", "calibration", "image_size [10^12, 10^12]", "PUT", "/v1/cameras/x",
             _camera_record(image_size=[10**12, 10**12]), Expect(422, "invalid_camera", "image_size"), JSON),
    HttpCase("record_unknown_field", "calibration", "unknown field", "PUT", "/v1/cameras/x",
             _camera_record(colour="red"), Expect(422, "invalid_camera", "colour"), JSON),
    HttpCase("record_id_mismatch", "calibration", "id in body differs from the path", "PUT", "/v1/cameras/x",
             _camera_record(id="y"), Expect(422, "invalid_camera", "differs"), JSON),
    HttpCase("record_not_object", "calibration", "body is a JSON array", "PUT", "/v1/cameras/x",
             _const(b"[1, 2]"), Expect(422, "invalid_camera", "JSON object"), JSON),
    HttpCase("record_not_json", "calibration", "body is not JSON", "PUT", "/v1/cameras/x",
             _const(b"{not json"), Expect(400, "bad_json", "not JSON"), JSON),
    HttpCase("record_deep_nesting", "calibration", "60000 nested arrays", "PUT", "/v1/cameras/x",
             _const(b"[" * 60_000), Expect(400, "bad_json", "nested too deeply"), JSON),
    HttpCase("record_huge_integer", "calibration", "a 5000-digit number", "PUT", "/v1/cameras/x",
             _const(b'{"altitude_m": ' + b"9" * 5000 + b"}"), Expect(400, "bad_json", "digits"), JSON),
    HttpCase("record_over_64kb", "calibration", "70 kB record", "PUT", "/v1/cameras/x",
             _camera_record(note="n" * 70_000), Expect(413, "payload_too_large", "limit is 65536"), JSON),
    HttpCase("put_id_dotdot", "camera id", "PUT id `..`", "PUT", "/v1/cameras/..", _camera_record(),
             Expect(422, "invalid_request", "camera_id"), JSON),
    HttpCase("put_id_unicode", "camera id", "PUT id `caméra`", "PUT", "/v1/cameras/cam%C3%A9ra",
             _camera_record(), Expect(422, "invalid_request", "camera_id"), JSON),
    HttpCase("put_id_10kb", "camera id", "PUT 10 kB id", "PUT", "/v1/cameras/" + "b" * 10_000,
             _camera_record(), Expect(422, "invalid_request", "camera_id"), JSON),
    HttpCase("get_unknown", "camera id", "GET unknown camera", "GET", "/v1/cameras/nowhere", _const(b""),
             Expect(404, "camera_not_found", "'nowhere'")),
    HttpCase("delete_unknown", "camera id", "DELETE unknown camera", "DELETE", "/v1/cameras/nowhere",
             _const(b""), Expect(404, "camera_not_found", "'nowhere'")),
    HttpCase("method_not_allowed", "camera id", "DELETE /v1/cameras", "DELETE", "/v1/cameras", _const(b""),
             Expect(405, "method_not_allowed", "Method Not Allowed")),
]

CIRCLE = "/v1/calibrations/image-circle"

# POST /v1/calibrations/image-circle reads its body as detect does: the same refusals, and its own.
_CIRCLE_LIKE_DETECT = ("random_bytes", "jpeg_truncated", "png_bomb_header", "body_over_limit",
                       "content_type_text")
CIRCLE_CASES: list[HttpCase] = [
    *(replace(case, name=f"circle_{case.name}", area="image circle", path=CIRCLE)
      for case in FRAME_CASES if case.name in _CIRCLE_LIKE_DETECT),
    HttpCase("circle_black_frame", "image circle", "all-black 640x480 frame", "POST", CIRCLE,
             lambda s: s.black_jpeg(640, 480), Expect(422, "no_circle", "not brighter"), JPEG),
    HttpCase("circle_one_pixel", "image circle", "1x1 JPEG", "POST", CIRCLE, lambda s: s.black_jpeg(1, 1),
             Expect(422, "frame_too_small", "at least 32 px"), JPEG),
    HttpCase("circle_bad_altitude", "image circle", "altitude_m=-1", "POST", f"{CIRCLE}?altitude_m=-1",
             lambda s: s.good_jpeg, Expect(422, "invalid_request", "altitude_m"), JPEG),
]

ALL_CASES = FRAME_CASES + CAMERA_CASES + CIRCLE_CASES


# ----- non-request scenarios: what each test does and observes (the tests assert these statuses)


@dataclass(frozen=True)
class Scenario:
    name: str
    area: str
    what: str
    observed: str
    test: str
    status: int | None = None  # the HTTP status the test asserts, where there is one


T = "tests/reliability/"

SCENARIOS: list[Scenario] = [
    Scenario("slow_body", "timeouts", "headers sent, then 100 of 100000 body bytes, then nothing "
             "(body deadline 1 s in the test, 30 s by default)",
             "408 `request_timeout`, `Connection: close`; a good frame sent meanwhile by another client: 200",
             T + "test_reliability_timeouts.py::test_slow_body_gets_408_and_others_are_served", 408),
    Scenario("trickled_body", "timeouts", "body sent one byte every 50 ms (never idle, never complete)",
             "408 `request_timeout` once the whole-body deadline passes; next good frame 200",
             T + "test_reliability_timeouts.py::test_trickled_body_gets_408", 408),
    Scenario("slow_camera_record", "timeouts", "PUT whose JSON body stops half way",
             "408 `request_timeout`; nothing written",
             T + "test_reliability_timeouts.py::test_slow_camera_record_gets_408", 408),
    Scenario("slow_head", "timeouts", "connection opened and silent, or request line and half the headers "
             "(head deadline 1 s in the test, 10 s by default)",
             "408 `request_timeout` written by the HTTP protocol, connection closed; other clients served",
             T + "test_reliability_timeouts.py::test_slow_or_silent_head_gets_408", 408),
    Scenario("idle_keep_alive", "timeouts", "keep-alive connection left idle after an answer",
             "closed by the server after FISHLOC_KEEP_ALIVE_TIMEOUT_S (1 s in the test, 5 s by default)",
             T + "test_reliability_timeouts.py::test_idle_keep_alive_connection_is_closed"),
    Scenario("concurrent_put_delete", "registry", "3 clients send 40 frames each to camera `flip` while "
             "a 4th replaces it (altitude 2 m / 4 m) and deletes it, 60 writes",
             "every frame answered: 200 with positions of exactly one of the two altitudes, or 404 "
             "`camera_not_found`, or 503 with Retry-After; no 5xx; writes 200/201/204/404",
             T + "test_reliability_concurrency.py::test_put_and_delete_while_frames_are_in_flight"),
    Scenario("token_wrong", "access", "registry writes with tokens of 1 character, the token minus or "
             "plus a character, 4 kB",
             "401 `unauthorized` + `WWW-Authenticate: Bearer`; each one compared by hmac.compare_digest "
             "against the configured token",
             T + "test_reliability_access.py::test_tokens_are_compared_with_compare_digest", 401),
    Scenario("detect_token", "access", "FISHLOC_DETECT_TOKEN set: detection without, with a wrong, or with "
             "a non-Bearer token", "401 `unauthorized`; the detect token and the API token both detect "
             "(200); the detect token cannot write the registry (401); without FISHLOC_DETECT_TOKEN "
             "detection is open", T + "test_reliability_access.py::test_detect_token", 401),
    Scenario("token_not_logged", "access", "`fishloc serve` at debug level; writes and detections with "
             "right, wrong and near-miss tokens", "neither token (nor a near miss of it) appears anywhere "
             "in the server's log", T + "test_reliability_access.py::test_tokens_never_reach_the_log"),
    Scenario("tls_rest", "access", "FISHLOC_TLS_CERT/KEY set to a self-signed certificate (made with "
             "`cryptography`)", "HTTPS detection 200 for a client verifying against that certificate; a "
             "client without it fails the handshake; plain HTTP to the port fails",
             T + "test_reliability_access.py::test_rest_over_tls", 200),
    Scenario("tls_bad_files", "access", "certificate missing, key of another certificate, certificate "
             "without key", "start-up stops: exit status 2 and `cannot read the TLS certificate ...`, "
             "`... does not fit the certificate ...`, `tls_cert and tls_key go together`",
             T + "test_reliability_access.py::test_tls_files_are_checked_at_start", 2),
    Scenario("cors", "access", "browser preflight and GET with an Origin header",
             "no CORS headers at all by default (preflight 405); with FISHLOC_CORS_ORIGINS the listed "
             "origin is allowed (200, Access-Control-Allow-Origin), others refused (400)",
             T + "test_reliability_access.py::test_cors_is_off_unless_configured"),
    Scenario("kill_9_registry", "faults", "`fishloc serve` (SQLite file) killed with SIGKILL while a client "
             "loops PUTs (new cameras and replacements of one camera), after 40 acknowledged",
             "`PRAGMA integrity_check` ok; after restart every camera acknowledged with 2xx is there, "
             "intact; the replaced camera holds the last acknowledged record or the one cut off; at most "
             "the one unacknowledged write in flight is kept; detection on a restored camera 200",
             T + "test_reliability_faults.py::test_kill_9_while_writing_keeps_every_acknowledged_camera",
             200),
    Scenario("bad_model", "faults", "`fishloc serve --model` naming a missing file, a folder, an empty "
             "file, text, or an ONNX file cut in half",
             "exit status 2 before listening; stderr `fishloc serve: cannot load the model: <path> does "
             "not exist` / `... is not a loadable ONNX model: ...`; no traceback",
             T + "test_reliability_faults.py::test_a_model_that_cannot_be_served_stops_start_up", 2),
    Scenario("warm_up", "faults", "model warm-up held back (test gate on Pipeline.warm_up)",
             "`/readyz` 503 `not_ready` + Retry-After, detection 503 `not_ready`, `/healthz` 200, "
             "`fishloc_ready 0`; once warm: `/readyz` 200, detection 200, `fishloc_ready 1`",
             T + "test_reliability_faults.py::test_not_ready_until_the_model_is_warm", 503),
    Scenario("soak", "overload", "`fishloc serve` child process, 6 keep-alive clients for 20 s on loopback "
             "(70% good frames, 15% bad frames, camera replacements, reads), admission limit 2 frames",
             "every request answered; only 200, 400, 415, 422 and 503 (with Retry-After, the deliberate "
             "overload); server VmRSS of the late fifth of the run within 10% + 24 MiB of the early "
             "one; long run: `python tests/reliability/reliability_soak.py --minutes 30`",
             T + "test_reliability_soak.py::test_short_soak", 503),
    Scenario("read_only_root", "deployment", "`fishloc serve` in a mount namespace whose root filesystem "
             "is read-only, only the registry folder writable (tmpfs)",
             "starts, ready, camera PUT 201, detection 200; nothing else is written (the image runs as "
             "uid 10001 with `--read-only --tmpfs /tmp` and the registry on /var/lib/fishloc); where "
             "mount namespaces are not allowed the test skips, except in CI, where it fails",
             T + "test_reliability_readonly_root.py::test_serves_from_a_read_only_root", 200),
]
SCENARIO = {row.name: row for row in SCENARIOS}


def case_test_id(case: HttpCase) -> str:
    return f"tests/reliability/test_reliability_bad_input.py::test_rest_case[{case.name}]"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def expect_text(expect: Expect) -> str:
    if expect.status == 200:
        return "200, person found at the right floor position" if expect.person else "200"
    if expect.code is None:
        return f"{expect.status} (uvicorn, before the app)"
    return f"{expect.status} `{expect.code}`"


def markdown_tables() -> str:
    """The tables of docs/RELIABILITY.md, made from the case and scenario lists (REST, then gRPC)."""
    lines = [
        "| case | request | answer | message holds | server after | reproduce |",
        "|---|---|---|---|---|---|",
    ]
    for case in ALL_CASES:
        after = "nothing stored; next frame 200" if case.method == "PUT" else "next frame 200"
        lines.append(
            f"| `{case.name}` | {_cell(case.method)} {_cell(case.what)} | {expect_text(case.expect)} | "
            f"{_cell(case.expect.message) or '-'} | {after} | `{case_test_id(case)}` |"
        )
    # Imported here: the gRPC cases are made from this module's frame cases.
    from reliability_grpc_cases import GRPC_SCENARIOS, grpc_markdown_tables

    lines += ["", *grpc_markdown_tables({case.name: case for case in ALL_CASES})]
    lines += [
        "",
        "| scenario | what is done | observed | reproduce |",
        "|---|---|---|---|",
    ]
    for row in SCENARIOS + GRPC_SCENARIOS:
        lines.append(f"| `{row.name}` | {_cell(row.what)} | {_cell(row.observed)} | `{row.test}` |")
    return "\n".join(lines) + "\n"


BEGIN = "<!-- reliability-cases:begin (made by tests/reliability/reliability_cases.py) -->\n"
END = "<!-- reliability-cases:end -->\n"


def document_block(text: str) -> str:
    """The generated part of docs/RELIABILITY.md (between the markers)."""
    return text[text.index(BEGIN) + len(BEGIN):text.index(END)]


def rewrite_document(path: Path) -> None:
    text = path.read_text()
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    path.write_text(text[:start] + markdown_tables() + text[end:])


if __name__ == "__main__":
    if sys.argv[1:2] == ["--write"]:
        rewrite_document(Path(sys.argv[2]))
    else:
        print(markdown_tables(), end="")
