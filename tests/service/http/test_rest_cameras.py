"""The camera registry over REST: CRUD with and without the token, persistence across restarts."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from service_live_server import LiveServer

from fisheye import FisheyeCamera, camera_to_dict
from models import DEFAULT_MODEL_PATH
from service.core.config import Settings

SAMPLES = Path(__file__).resolve().parents[3] / "samples"

TOKEN = "s3cret-token-for-tests"


def lobby(altitude_m: float = 3.0) -> dict[str, Any]:
    return {"altitude_m": altitude_m, "image_size": [1200, 1200], "principal_point": [600.0, 600.0],
            "focal_px": [380.0, 380.0], "kb": [1.0, -0.02]}


def put_demo_field(url: str, field: str, value: Any) -> dict[str, Any]:
    """The demo camera's record at `url` (the cameras route) written again with `field` at `value`,
    checked stored; the record as read (its view left out) for further writes."""
    record = httpx.get(f"{url}/demo").json()
    del record["view"]
    saved = httpx.put(f"{url}/demo", json={**record, field: value})
    assert saved.status_code == 200 and saved.json()[field] == value
    return record


def assert_field_refused(url: str, record: dict[str, Any], field: str, values: tuple[Any, ...]) -> None:
    """PUT `url` with `record`'s `field` at each of `values`: each a 422 `invalid_camera` naming the
    field, the camera's stored `field` the same afterwards."""
    stored = httpx.get(url).json()[field]
    for bad in values:
        refused = httpx.put(url, json={**record, field: bad})
        assert refused.status_code == 422 and refused.json()["error"]["code"] == "invalid_camera"
        assert field in refused.json()["error"]["message"]
    assert httpx.get(url).json()[field] == stored


def test_crud_without_a_token(live_server: LiveServer, demo_camera: FisheyeCamera) -> None:
    url = f"{live_server.url}/v1/cameras"
    listed = httpx.get(url).json()
    assert listed == {"cameras": [camera_to_dict(demo_camera)]}
    created = httpx.put(f"{url}/lobby", json=lobby())
    assert created.status_code == 201 and created.json() == {"id": "lobby", **lobby()}
    replaced = httpx.put(f"{url}/lobby", json=lobby(3.5))
    assert replaced.status_code == 200 and replaced.json()["altitude_m"] == 3.5
    assert httpx.get(f"{url}/lobby").json()["altitude_m"] == 3.5
    assert [c["id"] for c in httpx.get(url).json()["cameras"]] == ["demo", "lobby"]
    assert httpx.delete(f"{url}/lobby").status_code == 204
    for response in (httpx.get(f"{url}/lobby"), httpx.delete(f"{url}/lobby")):
        assert response.status_code == 404 and response.json()["error"]["code"] == "camera_not_found"


@pytest.mark.parametrize(("body", "status", "code"), [
    (b"{not json", 400, "bad_json"),
    (b"[1, 2]", 422, "invalid_camera"),
    (b'{"altitude_m": 3}', 422, "invalid_camera"),
    (b'{"id": "other", "altitude_m": 3, "image_size": [10, 10], "principal_point": [5, 5], '
     b'"focal_px": [3, 3], "kb": [1]}', 422, "invalid_camera"),
    (b'{"altitude_m": 3, "image_size": [10, 10], "principal_point": [5, 5], "focal_px": [3, 3], '
     b'"kb": [1.0, -0.5]}', 422, "invalid_camera"),
    (b'{"altitude_m": 3, "image_size": [10, 10], "principal_point": [5, 5], "focal_px": [3, 3], '
     b'"kb": [1], "colour": "red"}', 422, "invalid_camera"),
])
def test_invalid_records_are_refused(live_server: LiveServer, body: bytes, status: int, code: str) -> None:
    response = httpx.put(f"{live_server.url}/v1/cameras/cam", content=body,
                         headers={"content-type": "application/json"})
    assert response.status_code == status and response.json()["error"]["code"] == code
    assert httpx.get(f"{live_server.url}/v1/cameras/cam").status_code == 404


def test_invalid_camera_id_in_the_path(live_server: LiveServer) -> None:
    response = httpx.put(f"{live_server.url}/v1/cameras/bad%20id", json=lobby())
    assert response.status_code == 422 and response.json()["error"]["code"] == "invalid_request"


def test_writes_need_the_token(settings_for: Callable[..., Settings],
                               caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.DEBUG)
    with LiveServer(settings_for(api_token=TOKEN)) as live:
        url = f"{live.url}/v1/cameras/lobby"
        good = {"Authorization": f"Bearer {TOKEN}"}
        for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": TOKEN},
                        {"Authorization": f"Basic {TOKEN}"}):
            attempts = (httpx.put(url, json=lobby(), headers=headers), httpx.delete(url, headers=headers))
            for response in attempts:
                assert response.status_code == 401, headers
                assert response.json()["error"]["code"] == "unauthorized"
                assert response.headers["www-authenticate"] == "Bearer"
        assert httpx.get(url).status_code == 404  # nothing was written
        assert httpx.put(url, json=lobby(), headers=good).status_code == 201
        assert httpx.get(url).status_code == 200  # reads need no token
        assert httpx.get(f"{live.url}/v1/cameras").status_code == 200
        assert httpx.delete(url, headers=good).status_code == 204
    assert caplog.records and not any(TOKEN in record.getMessage() or TOKEN in str(record.__dict__)
                                      for record in caplog.records)


def test_registry_survives_a_restart(settings_for: Callable[..., Settings]) -> None:
    settings = settings_for()
    with LiveServer(settings) as first:
        assert httpx.put(f"{first.url}/v1/cameras/lobby", json=lobby(2.7)).status_code == 201
        assert httpx.delete(f"{first.url}/v1/cameras/demo").status_code == 204
    with LiveServer(settings) as second:  # same database file, new server
        cameras = httpx.get(f"{second.url}/v1/cameras").json()["cameras"]
        assert cameras == [{"id": "lobby", **lobby(2.7)}]  # and the deleted demo camera stays deleted


def test_cameras_flag_seeds_the_registry(settings_for: Callable[..., Settings], tmp_path: Any) -> None:
    folder = tmp_path / "cams"
    folder.mkdir()
    (folder / "a.json").write_text('{"id": "entrance", "altitude_m": 2.9, "image_size": [800, 800], '
                                   '"principal_point": [400, 400], "focal_px": [250, 250], "kb": [1]}')
    with LiveServer(settings_for(cameras=folder, demo_camera=False)) as live:
        ids = [c["id"] for c in httpx.get(f"{live.url}/v1/cameras").json()["cameras"]]
        assert ids == ["entrance"]


def test_a_planned_model_reports_each_camera_view(settings_for: Callable[..., Settings]) -> None:
    # The shipped model plans its views: within the default budget the demo camera keeps the
    # trained strip beside a nadir view; a larger budget gives its rim a band of its own, at 1.5x.
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH)) as live:
        view = httpx.get(f"{live.url}/v1/cameras/demo").json()["view"]
        assert view["input_wh"] == [1792, 416] and view["nadir"]["input_wh"] == [384, 384]
        assert view["cost_ratio"] == pytest.approx((1792 * 416 + 384 * 384) / (1792 * 416), abs=1e-3)
        assert [band["scale"] for band in view["bands"]] == [1.0]
        assert any("budget" in note for note in view["notes"])
        # the strip and nadir view run at the model's own operating point
        model = httpx.get(f"{live.url}/v1/model").json()
        assert view["layout"] == "1band+nadir" and view["operating_point"] == {
            "min_score": model["default_min_score"], "nms_iou": model["nms_iou"]}
        assert view["second_look"] is None and view["longest_person_ratio"] is None  # none unless asked for
        assert "view" not in httpx.get(f"{live.url}/v1/cameras").json()["cameras"][0]
        # A record read back is written back as it is: its view is the service's, not part of it.
        record = httpx.get(f"{live.url}/v1/cameras/demo").json()
        assert httpx.put(f"{live.url}/v1/cameras/demo", json=record).status_code == 200
        assert "view" not in httpx.put(f"{live.url}/v1/cameras/demo", json=record).json()
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, second_look=786_432)) as live:
        # the second look asked for: the same view, at the point the model carries for it
        view = httpx.get(f"{live.url}/v1/cameras/demo").json()["view"]
        points = httpx.get(f"{live.url}/v1/model").json()["view_operating_points"]
        assert view["layout"] == "1band+nadir+look" and view["operating_point"] == points["1band+nadir+look"]
        assert view["second_look"] == {"max_patches": 12, "zoom": 2.0, "target_rows": 48.0, "max_zoom": 4.0,
                                       "patch_px": [96, 256],
                                       "max_pixels": 786_432, "source": "server",
                                       "max_cost_ratio": round(786_432 / (1792 * 416), 3)}
        assert view["input_wh"] == [1792, 416]
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, longest_person_ratio=1.8)) as live:
        # the bound on a person's length asked for: the same view, reported with it, serving people
        view = httpx.get(f"{live.url}/v1/cameras/demo").json()["view"]
        assert view["layout"] == "1band+nadir" and view["longest_person_ratio"] == 1.8
        sample = (SAMPLES / "000001.jpg").read_bytes()
        answer = httpx.post(f"{live.url}/v1/cameras/demo/detect", content=sample,
                            headers={"Content-Type": "image/jpeg"}, timeout=60)
        assert answer.status_code == 200 and len(answer.json()["detections"]) >= 5
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, max_view_pixels=4_000_000)) as live:
        view = httpx.get(f"{live.url}/v1/cameras/demo").json()["view"]
        assert [band["scale"] for band in view["bands"]] == [1.0, 1.5]
        # the nadir view is a second input beside the canvas, counted in the same budget
        assert view["nadir"]["input_wh"] == [384, 384]
        assert view["pixels"] == view["input_wh"][0] * view["input_wh"][1] + 384 * 384 <= 4_000_000
        # ... at the operating point the model carries for that view (chosen on renders seen through it)
        points = httpx.get(f"{live.url}/v1/model").json()["view_operating_points"]
        assert view["layout"] == "2band+nadir" and view["operating_point"] == points["2band+nadir"]
        # the served frame runs both inputs and answers the people of the shipped sample
        sample = (SAMPLES / "000001.jpg").read_bytes()
        answer = httpx.post(f"{live.url}/v1/cameras/demo/detect", content=sample,
                            headers={"Content-Type": "image/jpeg"}, timeout=60)
        assert answer.status_code == 200
        people = answer.json()["detections"]
        assert len(people) >= 5 and all(math.isfinite(p["position_m"][0]) for p in people)
        assert view["smallest_person"]["along_px"] > 0


def test_a_camera_whose_view_cannot_be_planned_is_refused(settings_for: Callable[..., Settings]) -> None:
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH)) as live:
        url = f"{live.url}/v1/cameras/pinhole"
        response = httpx.put(url, json={**lobby(), "focal_px": [4.0, 4.0]})  # an image circle of 6 px
        assert response.status_code == 422 and response.json()["error"]["code"] == "view_unplannable"
        assert "no view" in response.json()["error"]["message"]
        assert httpx.get(url).status_code == 404  # nothing was saved
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, max_view_pixels=4096)) as live:
        response = httpx.get(f"{live.url}/v1/cameras/demo")
        assert response.status_code == 422 and "budget of 4096 px" in response.json()["error"]["message"]


def test_a_camera_record_sets_its_own_length_bound(settings_for: Callable[..., Settings]) -> None:
    # A calibrated camera bounds its people's length (its record's longest_person_ratio) where the
    # server does not; an uncalibrated one turns a server's bound off for itself (0).
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH)) as live:
        url = f"{live.url}/v1/cameras"
        record = put_demo_field(url, "longest_person_ratio", 1.8)
        view = httpx.get(f"{url}/demo").json()["view"]
        assert view["longest_person_ratio"] == 1.8 and view["layout"] == "1band+nadir"
        answer = httpx.post(f"{url}/demo/detect", content=(SAMPLES / "000001.jpg").read_bytes(),
                            headers={"Content-Type": "image/jpeg"}, timeout=60)
        assert answer.status_code == 200 and len(answer.json()["detections"]) >= 5
        assert_field_refused(f"{url}/demo", record, "longest_person_ratio", (-1, 0.5, 10.5, "long"))
        unbounded = {**record, "id": "twin", "longest_person_ratio": 0}
        assert httpx.put(f"{url}/twin", json=unbounded).status_code == 201
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, longest_person_ratio=2.5)) as live:
        url = f"{live.url}/v1/cameras"
        assert httpx.get(f"{url}/demo").json()["view"]["longest_person_ratio"] == 1.8  # its own
        assert httpx.get(f"{url}/twin").json()["view"]["longest_person_ratio"] is None  # 0: none
        assert httpx.put(f"{url}/third", json={**record, "id": "third"}).status_code == 201
        assert httpx.get(f"{url}/third").json()["view"]["longest_person_ratio"] == 2.5  # the server's


def test_a_camera_record_sets_its_own_second_look(settings_for: Callable[..., Settings]) -> None:
    # A crowded scene's camera takes the second look (its record's second_look_pixels) where the
    # server runs none, and a camera may turn a server's look off for itself.
    sample = (SAMPLES / "000001.jpg").read_bytes()
    jpeg = {"Content-Type": "image/jpeg"}
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH)) as live:
        url = f"{live.url}/v1/cameras"
        record = put_demo_field(url, "second_look_pixels", 786_432)
        view = httpx.get(f"{url}/demo").json()["view"]
        points = httpx.get(f"{live.url}/v1/model").json()["view_operating_points"]
        assert view["layout"] == "1band+nadir+look" and view["operating_point"] == points["1band+nadir+look"]
        assert view["second_look"]["max_pixels"] == 786_432 and view["second_look"]["source"] == "camera"
        assert view["budget"] == {"max_pixels": 900_000, "source": "server"}  # the view's budget is apart
        assert httpx.put(f"{url}/twin", json={**record, "id": "twin"}).status_code == 201
        assert httpx.get(f"{url}/twin").json()["view"]["second_look"] is None
        looked = httpx.post(f"{url}/demo/detect", content=sample, headers=jpeg, timeout=60)
        plain = httpx.post(f"{url}/twin/detect", content=sample, headers=jpeg, timeout=60)
        assert looked.status_code == plain.status_code == 200
        assert looked.json()["detections"] != plain.json()["detections"]
        assert_field_refused(f"{url}/demo", record, "second_look_pixels", (-1, 64 * 256 * 256 + 1, 1.5))
        # 0: no look for this camera, whatever the server's
        no_look = {**record, "id": "twin", "second_look_pixels": 0}
        assert httpx.put(f"{url}/twin", json=no_look).status_code == 200
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, second_look=300_000)) as live:
        url = f"{live.url}/v1/cameras"
        demo, twin = httpx.get(f"{url}/demo").json()["view"], httpx.get(f"{url}/twin").json()["view"]
        assert demo["second_look"]["max_pixels"] == 786_432 and demo["second_look"]["source"] == "camera"
        assert twin["layout"] == "1band+nadir" and twin["second_look"] is None
        assert httpx.post(f"{url}/twin/detect", content=sample, headers=jpeg, timeout=60).json()[
            "detections"] == plain.json()["detections"]


def test_a_camera_record_sets_its_own_view_budget(settings_for: Callable[..., Settings]) -> None:
    # One camera may take the rim band (its record's max_view_pixels) while the others keep the
    # server's budget; the server's limit bounds what a record may ask, now and after a restart.
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, max_camera_view_pixels=2_500_000)) as live:
        url = f"{live.url}/v1/cameras"
        record = httpx.get(f"{url}/demo").json()
        assert record["view"]["budget"] == {"max_pixels": 900_000, "source": "server"}
        assert record["view"]["layout"] == "1band+nadir"
        del record["view"]
        saved = httpx.put(f"{url}/demo", json={**record, "max_view_pixels": 2_400_000})
        assert saved.status_code == 200 and saved.json()["max_view_pixels"] == 2_400_000
        view = httpx.get(f"{url}/demo").json()["view"]
        assert view["budget"] == {"max_pixels": 2_400_000, "source": "camera"}
        assert view["layout"] == "2band+nadir" and [band["scale"] for band in view["bands"]] == [1.0, 1.5]
        assert view["pixels"] <= 2_400_000
        # ... at the operating point the model carries for that view
        points = httpx.get(f"{live.url}/v1/model").json()["view_operating_points"]
        assert view["operating_point"] == points["2band+nadir"]
        # its frames run that view: more input pixels than the same frame through the server's budget
        sample = (SAMPLES / "000001.jpg").read_bytes()
        jpeg = {"Content-Type": "image/jpeg"}
        own = httpx.post(f"{url}/demo/detect", content=sample, headers=jpeg, timeout=60)
        assert httpx.put(f"{url}/twin", json={**record, "id": "twin"}).status_code == 201
        twin_view = httpx.get(f"{url}/twin").json()["view"]
        assert twin_view["layout"] == "1band+nadir" and twin_view["budget"]["source"] == "server"
        assert twin_view["wanted_pixels"] == view["wanted_pixels"] == view["pixels"]  # the budget to ask for
        server = httpx.post(f"{url}/twin/detect", content=sample, headers=jpeg, timeout=60)
        assert own.status_code == server.status_code == 200
        assert own.json()["detections"] and server.json()["detections"]
        assert own.json()["detections"] != server.json()["detections"]
        # over the limit, or below the smallest budget: refused, nothing written
        over = httpx.put(f"{url}/demo", json={**record, "max_view_pixels": 2_500_001})
        assert over.status_code == 422 and over.json()["error"]["code"] == "view_budget_over_limit"
        assert "2500000" in over.json()["error"]["message"]
        tiny = httpx.put(f"{url}/demo", json={**record, "max_view_pixels": 100})
        assert tiny.status_code == 422 and tiny.json()["error"]["code"] == "invalid_camera"
        assert httpx.get(f"{url}/demo").json()["max_view_pixels"] == 2_400_000
        # a record read back (view and all) is written back as it is
        again = httpx.get(f"{url}/demo").json()
        assert httpx.put(f"{url}/demo", json=again).json()["max_view_pixels"] == 2_400_000
    # the limit lowered since: the stored record is planned at the limit, and says so
    with LiveServer(settings_for(model=DEFAULT_MODEL_PATH, max_camera_view_pixels=1_000_000)) as live:
        view = httpx.get(f"{live.url}/v1/cameras/demo").json()["view"]
        assert view["budget"] == {"max_pixels": 1_000_000, "source": "camera"}
        assert view["layout"] == "1band+nadir" and "over this server's limit" in view["notes"][0]
