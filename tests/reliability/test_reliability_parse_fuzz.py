"""Property-based fuzzing of the two parsers that take untrusted input: frame decoding (and the
whole pipeline behind it) and camera records. Whatever the input, the answer is a result or the
parser's own error (FrameError / CalibrationError), never another exception or a warning (pytest
turns warnings into errors)."""

from __future__ import annotations

import math
import os
from typing import Any

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from reliability_support import save_double_model

from contract import OnnxModel, SessionThreads
from fisheye import CalibrationError, FisheyeCamera, camera_from_dict, load_camera
from models import DEMO_CAMERA_PATH
from service.frame_decode import FrameError, decode_frame, read_header
from service.pipeline import Pipeline, PipelineConfig

# FISHLOC_FUZZ_SCALE multiplies every example count (the long run of docs/RELIABILITY.md uses 50).
SCALE = int(os.environ.get("FISHLOC_FUZZ_SCALE", "1"))
FUZZ = settings(max_examples=150 * SCALE, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MAX_PIXELS = 4_000_000


def _encoded(ext: str, size: tuple[int, int], **params: int) -> bytes:
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)
    flags = [item for pair in params.items() for item in pair]
    ok, data = cv2.imencode(ext, image, [int(f) for f in flags])
    assert ok
    return bytes(data.tobytes())


SEEDS = [
    _encoded(".jpg", (64, 64)),
    _encoded(".jpg", (48, 48), **{str(cv2.IMWRITE_JPEG_PROGRESSIVE): 1}),
    _encoded(".png", (40, 40)),
    _encoded(".jpg", (256, 256)),
]


@st.composite
def mutated_frames(draw: st.DrawFn) -> bytes:
    """A valid JPEG/PNG with a few bytes overwritten, cut off, inserted or its header rewritten."""
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        action = draw(st.sampled_from(["flip", "truncate", "insert", "size"]))
        position = draw(st.integers(0, max(len(data) - 1, 0)))
        if action == "flip" and data:
            data[position] = draw(st.integers(0, 255))
        elif action == "truncate":
            del data[position:]
        elif action == "insert":
            data[position:position] = draw(st.binary(min_size=1, max_size=16))
        elif action == "size" and len(data) > 30:
            # Rewrite the 4 bytes where a PNG keeps its width, or near a JPEG frame header.
            offset = 16 if data[:4] == b"\x89PNG" else max(data.find(b"\xff\xc0"), 0) + 5
            data[offset:offset + 4] = draw(st.binary(min_size=4, max_size=4))
    return bytes(data)


def _decodes_or_refuses(data: bytes) -> None:
    try:
        header = read_header(data)
        frame = decode_frame(data, input_size=64, max_pixels=MAX_PIXELS, header=header)
    except FrameError as error:
        assert error.code in {"empty_body", "bad_image", "unsupported_image", "image_too_large"}
        assert error.message
        event(error.code)
        return
    event("decoded")
    assert frame.frame_wh == header.size_wh
    width, height = frame.decoded_wh
    assert (width * frame.reduction, height * frame.reduction) == frame.frame_wh


@FUZZ
@given(st.binary(max_size=4096))
def test_decode_random_bytes(data: bytes) -> None:
    _decodes_or_refuses(data)


@FUZZ
@given(st.binary(max_size=2048).map(lambda tail: b"\xff\xd8\xff" + tail)
       | st.binary(max_size=2048).map(lambda tail: b"\x89PNG\r\n\x1a\n" + tail))
def test_decode_random_bytes_behind_a_magic_number(data: bytes) -> None:
    _decodes_or_refuses(data)


@FUZZ
@given(mutated_frames())
def test_decode_mutated_frames(data: bytes) -> None:
    _decodes_or_refuses(data)


@pytest.fixture(scope="module")
def pipeline(tmp_path_factory: pytest.TempPathFactory) -> Pipeline:
    model = OnnxModel(save_double_model(tmp_path_factory.mktemp("fuzz") / "double.onnx"), SessionThreads(1))
    return Pipeline(model, PipelineConfig(max_pixels=MAX_PIXELS))


@settings(max_examples=100 * SCALE, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=mutated_frames(), min_score=st.none() | st.floats(0, 1))
def test_pipeline_on_mutated_frames(pipeline: Pipeline, data: bytes, min_score: float | None) -> None:
    camera = load_camera(DEMO_CAMERA_PATH)
    try:
        result = pipeline.detect(data, camera, min_score=min_score)
    except FrameError as error:
        assert error.code in {"empty_body", "bad_image", "unsupported_image", "image_too_large",
                              "frame_size_mismatch", "frame_too_small"}
        event(error.code)
        return
    event("detected")
    assert result.image_wh == read_header(data).size_wh
    assert np.all(np.isfinite(result.detections.scores))


# ----- camera records

_NUMBERS = (st.floats(allow_nan=True, allow_infinity=True) | st.integers(-10**6, 10**6)
            | st.sampled_from([0, -1, 1e-300, 1e300, 2**63]))
_ANY = _NUMBERS | st.text(max_size=8) | st.none() | st.booleans() | st.lists(_NUMBERS, max_size=3)


def _pair(values: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.lists(values, min_size=2, max_size=2) | st.lists(values, max_size=4) | _ANY


@st.composite
def camera_records(draw: st.DrawFn) -> dict[str, Any]:
    """Camera-file dicts: a plausible record (any lens that r(θ) allows), then up to three fields
    broken (NaN, inf, huge, negative, wrong type or length), removed, or an extra field added."""
    width = draw(st.integers(2, 8000))
    height = draw(st.sampled_from([width, draw(st.integers(2, 8000))]))
    record: dict[str, Any] = {
        "id": draw(st.sampled_from(["cam", "a.b-c_1", "Z9"])),
        "altitude_m": draw(st.floats(0.01, 1000)),
        "image_size": [width, height],
        "principal_point": [draw(st.floats(0, width - 1)), draw(st.floats(0, height - 1))],
        "focal_px": [draw(st.floats(0.01, 1e5)), draw(st.floats(0.01, 1e5))],
        "kb": [draw(st.floats(0.01, 10)), *draw(st.lists(st.floats(-1, 1), max_size=4))],
    }
    if draw(st.booleans()):
        record["max_theta_deg"] = draw(st.floats(1, 179))
    if draw(st.booleans()):
        record["site_pose"] = {"x_m": draw(st.floats(-1e3, 1e3)), "y_m": 0.0,
                               "yaw_deg": draw(st.floats(-720, 720))}
    broken = draw(st.lists(st.sampled_from(sorted(record)), max_size=3, unique=True))
    for key in broken:
        change = draw(st.sampled_from(["value", "pair", "remove"]))
        if change == "remove":
            del record[key]
        elif change == "pair":
            record[key] = draw(_pair(_NUMBERS))
        else:
            record[key] = draw(_ANY | st.text(max_size=70))
    if draw(st.integers(0, 9)) == 0:
        record["extra"] = 1
    return record


@settings(max_examples=400 * SCALE, deadline=None)
@given(camera_records())
def test_camera_records_parse_or_are_refused(record: dict[str, Any]) -> None:
    try:
        camera = camera_from_dict(record)
    except CalibrationError as error:
        assert str(error).startswith("invalid camera:")
        event("refused")
        return
    event("accepted")
    assert isinstance(camera, FisheyeCamera) and camera.altitude_m > 0
    assert all(math.isfinite(value) for value in (*camera.principal_point, *camera.focal_px, *camera.kb))
    # An accepted camera answers every pixel of its image: a floor point, or NaN, never an error.
    width, height = camera.image_size
    axes = np.meshgrid(np.linspace(0, width - 1, 9), np.linspace(0, height - 1, 9))
    grid = np.stack(axes, -1).reshape(-1, 2)
    floor = camera.floor_positions(grid)
    assert np.all(np.isfinite(floor.xy_m[floor.valid])) and np.all(floor.distance_m[floor.valid] >= 0)
    assert np.all(np.isnan(floor.xy_m[~floor.valid]))
    # And the floor points found map back to their pixels.
    back = camera.floor_to_pixels(floor.xy_m[floor.valid])
    scale = max(width, height)
    np.testing.assert_allclose(back, grid[floor.valid], atol=1e-6 * scale)

