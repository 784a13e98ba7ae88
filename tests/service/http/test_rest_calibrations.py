"""POST /v1/calibrations/fit against a real server: the same camera as `fishloc calibrate`, coded
notes and refusals, and nothing saved."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from service_live_server import LiveServer

from fisheye import camera_from_dict
from fisheye.ruler_marks import RulerMarks, marks_to_csv, simulate_ruler_marks
from service.cli import main

SIZE = (2952, 2952)
TILTED = camera_from_dict({
    "id": "lobby", "altitude_m": 3.2, "image_size": list(SIZE), "principal_point": [1480.3, 1469.8],
    "focal_px": [940.0, 940.0], "kb": [1.0, -0.02, 0.001], "tilt_deg": [2.0, -1.5],
})
FOUR_TAPES = [0.0, 90.0, 180.0, 270.0]
DISTANCES = np.arange(0.25, 10.001, 0.25)


def tilted_marks(directions: list[float] = FOUR_TAPES, distances: Any = DISTANCES) -> RulerMarks:
    return simulate_ruler_marks(TILTED, directions, distances, noise_px=0.4, seed=5)


def marks_json(marks: RulerMarks) -> list[dict[str, Any]]:
    return [{"ruler": marks.ruler[i], "u": float(marks.uv_px[i, 0]), "v": float(marks.uv_px[i, 1]),
             "distance_m": float(marks.distance_m[i])} for i in range(len(marks))]


def fit_body(marks: RulerMarks, **options: Any) -> dict[str, Any]:
    return {"camera_id": "lobby", "altitude_m": 3.2, "image_size": list(SIZE), "marks": marks_json(marks),
            "options": options}


def fit(server: LiveServer, body: Any) -> httpx.Response:
    return httpx.post(f"{server.url}/v1/calibrations/fit", json=body, timeout=60)


def cameras(server: LiveServer) -> list[dict[str, Any]]:
    return list(httpx.get(f"{server.url}/v1/cameras").json()["cameras"])


@pytest.mark.parametrize(
    ("options", "flags"),
    [
        ({}, []),
        ({"fit_tilt": True}, ["--fit-tilt"]),
        ({"fit_principal_point": True, "coefficients": 4}, ["--fit-principal-point", "--coefficients", "4"]),
        ({"fit_tilt": True, "principal_point": [1480.0, 1470.0], "max_theta_deg": 88.0},
         ["--fit-tilt", "--principal-point", "1480.0", "1470.0", "--max-theta-deg", "88"]),
    ],
)
def test_the_route_and_the_cli_give_the_same_camera(live_server: LiveServer, tmp_path: Path,
                                                     options: dict[str, Any], flags: list[str]) -> None:
    marks = tilted_marks()
    csv = tmp_path / "marks.csv"
    csv.write_text(marks_to_csv(marks), encoding="utf-8")
    output = tmp_path / "lobby.json"
    assert main(["calibrate", "--marks", str(csv), "--altitude", "3.2", "--image-size", *map(str, SIZE),
                 "-o", str(output), *flags]) == 0
    answer = fit(live_server, fit_body(marks, **options))
    assert answer.status_code == 200, answer.text
    assert answer.json()["camera"] == json.loads(output.read_text(encoding="utf-8"))


def test_the_answer_has_residuals_and_notes_and_nothing_is_saved(live_server: LiveServer) -> None:
    before = cameras(live_server)
    marks = tilted_marks()
    answer = fit(live_server, fit_body(marks, fit_tilt=True)).json()
    assert cameras(live_server) == before
    camera = answer["camera"]
    assert camera["id"] == "lobby" and camera["tilt_deg"] == pytest.approx([2.0, -1.5], abs=0.15)
    assert len(answer["marks"]) == len(marks)
    first = answer["marks"][1]
    assert first["ruler"] == marks.ruler[1] and first["distance_m"] == marks.distance_m[1]
    assert set(first) >= {"u", "v", "fitted_distance_m", "err_m", "pos_err_m", "err_px"}
    assert first["pos_err_m"] is None  # the mark has no x_m, y_m
    assert 0 < answer["rms_px"] < 1.0 and 0 < answer["rms_m"] < 0.02
    codes = {note["code"]: note for note in answer["notes"]}
    assert codes["tilt"]["level"] == "info" and "tilt fitted" in codes["tilt"]["message"]
    assert "marks_reach" in codes and answer["monotonic_constrained"] is False
    # Saving is a PUT of the answer's camera.
    saved = httpx.put(f"{live_server.url}/v1/cameras/lobby", json=camera)
    assert saved.status_code == 201
    assert httpx.get(f"{live_server.url}/v1/cameras/lobby").json() == camera


def test_warnings_for_short_marks_and_an_undetermined_tilt(live_server: LiveServer) -> None:
    answer = fit(live_server, fit_body(tilted_marks(distances=np.arange(0.25, 2.001, 0.25)), fit_tilt=True))
    warnings = {note["code"] for note in answer.json()["notes"] if note["level"] == "warning"}
    assert warnings == {"marks_short", "tilt_undetermined"}


def test_marks_clicked_on_a_smaller_frame_are_scaled(live_server: LiveServer) -> None:
    marks = tilted_marks()
    full = fit(live_server, fit_body(marks, fit_tilt=True)).json()["camera"]
    half = fit_body(RulerMarks((marks.uv_px + 0.5) / 2 - 0.5, marks.distance_m, marks.xy_m, marks.ruler),
                    fit_tilt=True) | {"frame_size": [1476, 1476]}
    answer = fit(live_server, half)
    assert answer.status_code == 200
    scaled = answer.json()["camera"]
    assert scaled["image_size"] == list(SIZE)
    np.testing.assert_allclose(scaled["principal_point"], full["principal_point"], atol=1e-6)
    np.testing.assert_allclose(scaled["tilt_deg"], full["tilt_deg"], atol=1e-8)


def _with(body: dict[str, Any], index: int, **fields: Any) -> dict[str, Any]:
    body["marks"][index] |= fields
    return body


BAD_FITS = [
    ("too_few_marks", lambda: fit_body(tilted_marks(distances=[1.0, 2.0]), coefficients=3),
     "3 coefficients need marks at 3 or more"),
    ("one_direction", lambda: fit_body(tilted_marks(directions=[45.0]), fit_tilt=True),
     "3 or more directions"),
    ("one_direction", lambda: fit_body(tilted_marks(directions=[45.0, 225.0]), fit_principal_point=True),
     "two directions that are not on one line"),
    ("one_direction", lambda: fit_body(tilted_marks(directions=[45.0])), "one radius from the nadir"),
    ("nadir_mismatch", lambda: _with(fit_body(tilted_marks()), 7, distance_m=0.0), "has distance 0 but lies"),
    ("not_monotonic", lambda: _with(fit_body(tilted_marks()), 30, distance_m=0.5), "a lens cannot do that"),
    ("frame_size_mismatch", lambda: fit_body(tilted_marks()) | {"frame_size": [1476, 1000]}, "aspect ratio"),
    ("frame_size_mismatch", lambda: fit_body(tilted_marks()) | {"image_size": [1476, 1476]},
     "outside the 1476x1476 image"),
    ("invalid_marks", lambda: _with(fit_body(tilted_marks()), 3, distance_m=None), "give distance_m or both"),
    ("invalid_marks", lambda: _with(fit_body(tilted_marks()), 3, x_m=9.0, y_m=0.0), "disagrees with"),
    ("invalid_request", lambda: fit_body(tilted_marks(), coefficients=9), "options.coefficients"),
    ("invalid_request", lambda: fit_body(tilted_marks(), fit_everything=True), "fit_everything"),
    ("invalid_request", lambda: {"image_size": [10, 10], "marks": []}, "altitude_m"),
    ("invalid_request", lambda: [1, 2], "body"),
]


@pytest.mark.parametrize(("code", "make", "message"), BAD_FITS, ids=[f"{c}-{i}" for i, (c, _, _) in
                                                                      enumerate(BAD_FITS)])
def test_bad_fits_are_clear_4xx_and_save_nothing(live_server: LiveServer, code: str, make: Any,
                                                 message: str) -> None:
    before = cameras(live_server)
    answer = fit(live_server, make())
    assert answer.status_code == 422, answer.text
    error = answer.json()["error"]
    assert error["code"] == code and message in error["message"], error
    assert cameras(live_server) == before


@pytest.mark.parametrize(("body", "status", "code"), [
    (b"{not json", 400, "bad_json"),
    (b'{"altitude_m": NaN, "image_size": [10, 10], "marks": [{"u": 1, "v": 1, "distance_m": 0}]}', 422,
     "invalid_request"),
    (b"[" * 100000, 400, "bad_json"),
])
def test_bodies_that_are_not_fit_requests(live_server: LiveServer, body: bytes, status: int,
                                          code: str) -> None:
    answer = httpx.post(f"{live_server.url}/v1/calibrations/fit", content=body,
                        headers={"Content-Type": "application/json"})
    assert answer.status_code == status and answer.json()["error"]["code"] == code
