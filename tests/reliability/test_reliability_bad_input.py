"""Every bad-input case of reliability_cases.py against a real server: the answer expected, then
proof that the server is unharmed (the next good frame gets the person at the right place)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from reliability_cases import ALL_CASES, JPEG, MAX_BODY_BYTES, MAX_PIXELS, HttpCase
from reliability_samples import PERSON_FLOOR_XY_M, Samples
from reliability_support import LiveServer, RawResponse, raw_request, test_settings

from fisheye import FisheyeCamera

pytest_plugins = ["reliability_fixtures"]  # fixtures shared by the reliability tests


@pytest.fixture(scope="module")
def server(double_model_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = test_settings(double_model_path, tmp_path_factory.mktemp("bad-input"),
                             max_body_bytes=MAX_BODY_BYTES, max_pixels=MAX_PIXELS)
    with LiveServer(settings) as live:
        yield live


@pytest.fixture(scope="module")
def samples(demo_camera: FisheyeCamera) -> Samples:
    return Samples(demo_camera)


def assert_person(response: RawResponse) -> None:
    assert response.status == 200, response.body[:300]
    detections = response.json_body["detections"]
    best = max(detections, key=lambda d: d["score"])
    np.testing.assert_allclose(best["position_m"], PERSON_FLOOR_XY_M, atol=0.01)


@pytest.mark.parametrize("case", ALL_CASES, ids=[case.name for case in ALL_CASES])
def test_rest_case(server: LiveServer, samples: Samples, case: HttpCase) -> None:
    response = raw_request(server.url, case.method, case.path, case.body(samples), case.headers,
                           chunked=case.chunked)
    expect = case.expect
    assert response.status == expect.status, response.body[:300]
    if expect.person:
        assert_person(response)
    if expect.code is not None:
        assert set(response.json_body) == {"error"}, response.json_body
        assert response.error_code == expect.code
        assert expect.message in response.error_message, response.error_message
    if expect.code in ("payload_too_large", "request_timeout"):
        assert response.headers.get("connection") == "close"  # the rest of the body is not read
    # Unharmed: the next good frame is answered, and no refused record reached the registry.
    assert_person(raw_request(server.url, "POST", "/v1/cameras/demo/detect", samples.good_jpeg, JPEG))
    assert raw_request(server.url, "GET", "/v1/cameras/x").status == 404


@pytest.mark.parametrize("name", ["png_bomb_header", "png_bomb_zlib", "jpeg_bomb_header"])
def test_bombs_are_refused_without_decoding(server: LiveServer, samples: Samples, name: str,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The pixel limit is applied to the header: the decoder is never called for a bomb."""
    import service.frame_decode

    def no_decoding(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a frame over the pixel limit reached the decoder")

    monkeypatch.setattr(service.frame_decode.cv2, "imdecode", no_decoding)
    monkeypatch.setattr(service.frame_decode.simplejpeg, "decode_jpeg", no_decoding)
    case = next(case for case in ALL_CASES if case.name == name)
    response = raw_request(server.url, "POST", case.path, case.body(samples), case.headers)
    assert response.status == 413 and response.error_code == "image_too_large"
