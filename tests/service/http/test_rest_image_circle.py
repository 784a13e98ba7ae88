"""POST /v1/calibrations/image-circle against a real server: the circle of the frame sent, the same
camera as `fishloc calibrate --image-circle`, refusals with a reason, and nothing saved."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from service_live_server import LiveServer

from fisheye import load_camera
from service.cli import main
from tests.fisheye.circle_frames import CircleFrame, draw_circle_frame, encode_jpeg, encode_png

ROUTE = "/v1/calibrations/image-circle"
WIDE = CircleFrame((1312, 1080), (655.0, 541.0), 650.0, seed=2)  # cut at top and bottom
INSIDE = CircleFrame((1024, 1024), (515.0, 505.0), 480.0, seed=3)


def post(server: LiveServer, data: bytes, content_type: str = "image/jpeg", **query: Any) -> httpx.Response:
    return httpx.post(f"{server.url}{ROUTE}", content=data, params=query,
                      headers={"Content-Type": content_type}, timeout=60)


def cameras(server: LiveServer) -> list[dict[str, Any]]:
    return list(httpx.get(f"{server.url}/v1/cameras").json()["cameras"])


@pytest.mark.parametrize(("spec", "cut"), [(INSIDE, []), (WIDE, ["top", "bottom"])], ids=["inside", "wide"])
def test_the_answer_is_the_frames_circle_and_a_camera_on_it(live_server: LiveServer, spec: CircleFrame,
                                                            cut: list[str]) -> None:
    before = cameras(live_server)
    answer = post(live_server, encode_jpeg(draw_circle_frame(spec)), altitude_m=3.4, camera_id="hall-2")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    circle = body["circle"]
    np.testing.assert_allclose(circle["center_px"], spec.center_px, atol=1.0)
    assert circle["radius_px"] == pytest.approx(spec.radius_px, abs=1.0)
    assert [side for side in ("top", "bottom", "left", "right") if circle["cut"][side]] == cut
    assert circle["inlier_fraction"] > 0.9 and 0 <= circle["rms_px"] < 1.5
    camera = body["camera"]
    assert camera["id"] == "hall-2" and camera["altitude_m"] == 3.4 and camera["kb"] == [1.0]
    assert camera["image_size"] == list(spec.wh) and camera["max_theta_deg"] == 90.0
    assert camera["principal_point"] == pytest.approx(circle["center_px"], abs=0.01)
    assert camera["focal_px"][0] == pytest.approx(circle["radius_px"] / (math.pi / 2), abs=0.01)
    codes = [note["code"] for note in body["notes"]]
    assert "starting_camera" in codes and ("circle_cut" in codes) == bool(cut)
    assert cameras(live_server) == before  # nothing saved
    saved = httpx.put(f"{live_server.url}/v1/cameras/hall-2", json=camera)
    assert saved.status_code == 201, saved.text


def test_a_large_jpeg_decoded_at_a_reduced_scale_answers_in_frame_px(live_server: LiveServer) -> None:
    spec = CircleFrame((2048, 2048), (1030.0, 1019.0), 1010.0, seed=4)
    answer = post(live_server, encode_jpeg(draw_circle_frame(spec))).json()
    np.testing.assert_allclose(answer["circle"]["center_px"], spec.center_px, atol=1.5)
    assert answer["circle"]["radius_px"] == pytest.approx(spec.radius_px, abs=1.5)
    assert answer["camera"]["image_size"] == [2048, 2048] and answer["camera"]["altitude_m"] == 3.0


def test_the_route_and_the_cli_give_the_same_camera(live_server: LiveServer, tmp_path: Path) -> None:
    png = encode_png(draw_circle_frame(WIDE))
    frame = tmp_path / "frame.png"
    frame.write_bytes(png)
    output = tmp_path / "wide.json"
    assert main(["calibrate", "--image-circle", str(frame), "--altitude", "2.9", "-o", str(output)]) == 0
    answer = post(live_server, png, "image/png", altitude_m=2.9, camera_id="wide")
    assert answer.status_code == 200, answer.text
    assert answer.json()["camera"] == json.loads(output.read_text(encoding="utf-8"))
    assert load_camera(output).altitude_m == 2.9


def test_a_multipart_frame_is_read_from_its_image_field(live_server: LiveServer) -> None:
    answer = httpx.post(f"{live_server.url}{ROUTE}", timeout=60,
                        files={"image": ("f.jpg", encode_jpeg(draw_circle_frame(INSIDE)), "image/jpeg")})
    assert answer.status_code == 200, answer.text
    assert answer.json()["circle"]["radius_px"] == pytest.approx(INSIDE.radius_px, abs=1.0)


@pytest.mark.parametrize(
    ("data", "query", "status", "code", "message"),
    [
        (b"", {}, 400, "empty_body", "no image"),
        (encode_jpeg(np.zeros((480, 640, 3), np.uint8)), {}, 422, "no_circle", "not brighter"),
        (encode_jpeg(np.full((480, 640, 3), 128, np.uint8)), {}, 422, "no_circle", "not brighter"),
        (encode_jpeg(draw_circle_frame(CircleFrame((640, 480), (319.5, 239.5), 2000.0))), {}, 422,
         "no_visible_rim", "cover the frame"),
        (encode_jpeg(np.zeros((20, 20, 3), np.uint8)), {}, 422, "frame_too_small", "32 px"),
        (b"GIF89a" + bytes(100), {}, 415, "unsupported_image", "neither JPEG nor PNG"),
        (encode_jpeg(draw_circle_frame(INSIDE)), {"altitude_m": 0}, 422, "invalid_request", "altitude_m"),
        (encode_jpeg(draw_circle_frame(INSIDE)), {"camera_id": "a b"}, 422, "invalid_request", "camera_id"),
    ],
    ids=["empty", "black", "grey", "no rim", "tiny", "gif", "altitude 0", "bad id"],
)
def test_frames_without_a_circle_and_bad_queries_are_clear_4xx(
        live_server: LiveServer, data: bytes, query: dict[str, Any], status: int, code: str,
        message: str) -> None:
    before = cameras(live_server)
    answer = post(live_server, data, **query)
    assert answer.status_code == status, answer.text
    error = answer.json()["error"]
    assert error["code"] == code and message in error["message"], error
    assert cameras(live_server) == before


def test_the_route_is_in_the_openapi_document(live_server: LiveServer) -> None:
    document = httpx.get(f"{live_server.url}/openapi.json").json()
    operation = document["paths"][ROUTE]["post"]
    assert set(operation["requestBody"]["content"]) >= {"image/jpeg", "image/png", "multipart/form-data"}
    assert {"200", "413", "415", "422"} <= set(operation["responses"])
