"""Sites over REST on a real server: registry routes and their validation, tracking through detect,
capture_time, the pose fit, the read token, metrics, and a registry that survives a restart."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
from service_live_server import LiveServer
from service_sites import (
    SITE,
    T0,
    detect,
    frame_of,
    put_site_cameras,
    site_camera_record,
    walk,
)

from fisheye import FisheyeCamera
from service.cameras import CameraRegistry
from service.core.config import Settings

SQUARE = [[-3.0, -1.0], [-1.0, -1.0], [-1.0, 1.0], [-3.0, 1.0]]


@pytest.fixture
def client(live_server: LiveServer) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=live_server.url, timeout=30) as http:
        yield http


def _error(answer: httpx.Response, status: int, code: str) -> dict[str, Any]:
    assert answer.status_code == status, answer.text
    error: dict[str, Any] = answer.json()["error"]
    assert error["code"] == code
    return error


def test_zones_and_lines_need_a_site_that_a_camera_names(client: httpx.Client,
                                                         demo_camera: FisheyeCamera) -> None:
    _error(client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE}), 404, "site_not_found")
    _error(client.get(f"/v1/sites/{SITE}"), 404, "site_not_found")
    assert client.get("/v1/sites").json() == {"sites": []}
    put_site_cameras(client, demo_camera)
    assert client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE}).status_code == 201
    assert client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE}).status_code == 200
    line = client.put(f"/v1/sites/{SITE}/lines/door", json={"from_m": [0, -3], "to_m": [0, 3]})
    assert line.status_code == 201
    assert line.json() == {"id": "door", "from_m": [0.0, -3.0], "to_m": [0.0, 3.0]}
    assert client.get("/v1/sites").json() == {
        "sites": [{"id": SITE, "cameras": ["cam-a", "cam-b"], "zones": ["entrance"]}]}
    site = client.get(f"/v1/sites/{SITE}").json()
    assert [camera["id"] for camera in site["cameras"]] == ["cam-a", "cam-b"]
    assert site["cameras"][1]["site_pose"] == {"x_m": 2.0, "y_m": 0.0, "yaw_deg": 90.0}
    assert site["zones"] == [{"id": "entrance", "polygon_m": SQUARE, "in_view": True}]
    assert site["lines"] == [{"id": "door", "from_m": [0.0, -3.0], "to_m": [0.0, 3.0]}]
    assert site["notes"] == []


@pytest.mark.parametrize(("path", "body", "status", "code"), [
    ("zones/z", {"polygon_m": [[0, 0], [1, 1], [1, 0], [0, 1]]}, 422, "invalid_zone"),   # self-intersecting
    ("zones/z", {"polygon_m": [[0, 0], [1, 0], [2, 0]]}, 422, "invalid_zone"),           # degenerate
    ("zones/z", {"polygon_m": [[0, 0], [1, 0]]}, 422, "invalid_zone"),
    ("zones/z", {"polygon_m": "all of it"}, 422, "invalid_zone"),
    ("zones/z", {"polygon": SQUARE}, 422, "invalid_zone"),
    ("zones/z", [1, 2, 3], 422, "invalid_zone"),
    ("lines/l", {"from_m": [1, 1], "to_m": [1, 1]}, 422, "invalid_line"),                # zero length
    ("lines/l", {"from_m": [1, 1]}, 422, "invalid_line"),
    ("lines/l", {"from_m": [1, 1], "to_m": [1, "x"]}, 422, "invalid_line"),
    ("zones/bad%20id", {"polygon_m": SQUARE}, 422, "invalid_request"),
])
def test_invalid_zone_and_line_bodies_are_refused_and_change_nothing(
        client: httpx.Client, demo_camera: FisheyeCamera, path: str, body: Any, status: int,
        code: str) -> None:
    put_site_cameras(client, demo_camera)
    before = client.get(f"/v1/sites/{SITE}").json()
    error = _error(client.put(f"/v1/sites/{SITE}/{path}", json=body), status, code)
    assert error["message"]
    assert client.get(f"/v1/sites/{SITE}").json() == before


def test_a_body_that_is_not_json_is_a_400(client: httpx.Client, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    answer = client.put(f"/v1/sites/{SITE}/zones/z", content=b"{not json",
                        headers={"Content-Type": "application/json"})
    _error(answer, 400, "bad_json")


def test_a_zone_out_of_every_view_is_kept_and_reported(client: httpx.Client,
                                                       demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    far = [[500.0, 500.0], [502.0, 500.0], [502.0, 502.0]]
    assert client.put(f"/v1/sites/{SITE}/zones/far", json={"polygon_m": far}).status_code == 201
    site = client.get(f"/v1/sites/{SITE}").json()
    assert site["zones"][0]["in_view"] is False
    assert len(site["notes"]) == 1 and "'far'" in site["notes"][0]


def test_deleting_zones_and_lines(client: httpx.Client, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE})
    assert client.delete(f"/v1/sites/{SITE}/zones/entrance").status_code == 204
    _error(client.delete(f"/v1/sites/{SITE}/zones/entrance"), 404, "zone_not_found")
    _error(client.delete(f"/v1/sites/{SITE}/lines/door"), 404, "line_not_found")
    _error(client.delete("/v1/sites/nowhere/lines/door"), 404, "site_not_found")


def test_detect_tracks_one_person_across_two_cameras_and_counts_the_door(
        client: httpx.Client, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    client.put(f"/v1/sites/{SITE}/lines/door", json={"from_m": [0, -3], "to_m": [0, 3]})
    client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE})
    ids = walk(client, demo_camera, start=(-2.0, 0.5), velocity=(1.0, 0.0), steps=20)
    assert ids[:2] == [None] * 2  # tentative until seen at two capture times (TrackerConfig.min_hits)
    assert set(ids[2:]) == {f"{SITE}:1"}
    occupancy = client.get(f"/v1/sites/{SITE}/occupancy").json()
    assert occupancy["count"] == 1 and occupancy["time"] == pytest.approx(T0 + 19 / 5)
    person = occupancy["people"][0]
    assert person["cameras"] == ["cam-a", "cam-b"]
    assert person["position_m"] == pytest.approx([1.8, 0.5], abs=0.1)
    # x in [-2.0, -1.0]: dwell counts from the first frame, the track's tentative part included
    assert person["dwell_s"]["entrance"] == pytest.approx(1.0, abs=0.21)
    assert occupancy["zones"] == {"entrance": {"count": 0}}
    assert occupancy["lines"] == {"door": {"in": 1, "out": 0}}
    metrics = client.get("/metrics").text
    assert f'fishloc_site_people{{site="{SITE}"}} 1.0' in metrics
    assert f'fishloc_zone_people{{site="{SITE}",zone="entrance"}} 0.0' in metrics
    assert f'fishloc_line_crossings_total{{direction="in",line="door",site="{SITE}"}} 1.0' in metrics


@pytest.mark.parametrize("value", ["yesterday", "nan", "inf", "-5", "1e20", "2025-13-01T00:00:00Z",
                                   "2025-12-01T00:00:00", "2025-12-01", ""])
def test_invalid_capture_times_are_a_422(client: httpx.Client, demo_camera: FisheyeCamera,
                                         value: str) -> None:
    put_site_cameras(client, demo_camera)
    answer = detect(client, "cam-a", frame_of(demo_camera, "cam-a", (-2.0, 0.3)), value)
    _error(answer, 422, "invalid_capture_time")
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["time"] is None


def test_rfc3339_and_unix_capture_times_are_one_clock(client: httpx.Client,
                                                      demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    frame = frame_of(demo_camera, "cam-a", (-2.0, 0.3))
    assert detect(client, "cam-a", frame, "2025-12-01T18:05:45.5+01:00").status_code == 200
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["time"] == 1764608745.5
    assert detect(client, "cam-a", frame, "1764608746").status_code == 200
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["time"] == 1764608746.0


def test_a_frame_too_late_is_dropped_and_counted(client: httpx.Client, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    walk(client, demo_camera, start=(-2.0, 0.5), velocity=(0.0, 0.0), steps=5, cameras=("cam-a",))
    late = detect(client, "cam-b", frame_of(demo_camera, "cam-b", (2.0, 0.3)), T0 - 10)
    assert late.status_code == 200 and late.json()["detections"][0]["track_id"] is None
    metrics = client.get("/metrics").text
    assert f'fishloc_site_frames_total{{site="{SITE}",use="dropped_late"}} 1.0' in metrics
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["count"] == 1


def test_a_camera_moved_to_another_site_ends_its_tracks(client: httpx.Client,
                                                        demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    ids = walk(client, demo_camera, start=(-2.0, 0.5), velocity=(0.0, 0.0), steps=5, cameras=("cam-a",))
    assert ids[-1] == f"{SITE}:1"
    moved = site_camera_record(demo_camera, "cam-a", site="annex")
    assert client.put("/v1/cameras/cam-a", json=moved).status_code == 200
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["count"] == 0
    assert [site["id"] for site in client.get("/v1/sites").json()["sites"]] == ["annex", SITE]
    answer = detect(client, "cam-a", frame_of(demo_camera, "cam-a", (-2.0, 0.5)), T0 + 2)
    assert answer.json()["detections"][0]["track_id"] is None  # a new, tentative track of the annex
    assert client.get("/v1/sites/annex/occupancy").json()["time"] == T0 + 2


def test_the_site_pose_fit_places_a_camera(client: httpx.Client, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    points = [{"floor_m": [0.0, 0.0], "site_m": [5.0, 1.0]}, {"floor_m": [4.0, 0.0], "site_m": [5.0, 5.0]},
              {"pixel": [1030.0, 1017.0], "site_m": [5.0, 1.0]}]
    fit = client.post("/v1/cameras/cam-a/site-pose/fit", json={"points": points})
    assert fit.status_code == 200, fit.text
    body = fit.json()
    assert body["site_pose"] == pytest.approx({"x_m": 5.0, "y_m": 1.0, "yaw_deg": 90.0}, abs=1e-3)
    assert body["rms_m"] < 0.01 and body["saved"] is False
    assert client.get("/v1/cameras/cam-a").json()["site_pose"] == {"x_m": -2.0, "y_m": 0.0, "yaw_deg": 0.0}
    saved = client.post("/v1/cameras/cam-a/site-pose/fit", json={"points": points, "save": True})
    assert saved.json()["saved"] is True
    assert client.get("/v1/cameras/cam-a").json()["site_pose"]["x_m"] == pytest.approx(5.0, abs=1e-3)
    one = client.post("/v1/cameras/cam-a/site-pose/fit", json={"points": points[:1]})
    _error(one, 422, "invalid_request")
    both = [{"floor_m": [0, 0], "pixel": [1, 1], "site_m": [0, 0]}, points[1]]
    _error(client.post("/v1/cameras/cam-a/site-pose/fit", json={"points": both}), 422, "invalid_points")
    _error(client.post("/v1/cameras/nobody/site-pose/fit", json={"points": points}), 404, "camera_not_found")


def test_site_reads_need_the_read_token(settings_for: Callable[..., Settings],
                                        demo_camera: FisheyeCamera) -> None:
    settings = settings_for(read_token="reader", api_token="writer")
    with LiveServer(settings) as server, httpx.Client(base_url=server.url, timeout=30) as client:
        writer = {"Authorization": "Bearer writer"}
        for camera_id in ("cam-a", "cam-b"):
            record = site_camera_record(demo_camera, camera_id)
            assert client.put(f"/v1/cameras/{camera_id}", json=record, headers=writer).status_code == 201
        zone = {"polygon_m": SQUARE}
        _error(client.put(f"/v1/sites/{SITE}/zones/z", json=zone, headers={"Authorization": "Bearer reader"}),
               401, "unauthorized")
        assert client.put(f"/v1/sites/{SITE}/zones/z", json=zone, headers=writer).status_code == 201
        for path in ("/v1/sites", f"/v1/sites/{SITE}", f"/v1/sites/{SITE}/occupancy",
                     f"/v1/sites/{SITE}/events", "/v1/cameras/cam-a/latest", "/v1/cameras/cam-a/latest.jpg"):
            _error(client.get(path), 401, "unauthorized")
            _error(client.get(path, headers={"Authorization": "Bearer wrong"}), 401, "unauthorized")
        for headers in ({"Authorization": "Bearer reader"}, writer):
            assert client.get(f"/v1/sites/{SITE}/occupancy", headers=headers).status_code == 200
        assert client.get(f"/v1/sites/{SITE}", params={"access_token": "reader"}).status_code == 200
        # Detection stays open (no detect token), and the camera list is not a site read.
        assert client.get("/v1/cameras").status_code == 200


def test_zones_and_lines_survive_a_restart(settings_for: Callable[..., Settings],
                                           demo_camera: FisheyeCamera) -> None:
    settings = settings_for()
    with LiveServer(settings) as server, httpx.Client(base_url=server.url, timeout=30) as client:
        put_site_cameras(client, demo_camera)
        client.put(f"/v1/sites/{SITE}/zones/entrance", json={"polygon_m": SQUARE})
        client.put(f"/v1/sites/{SITE}/lines/door", json={"from_m": [0, -3], "to_m": [0, 3]})
        before = client.get(f"/v1/sites/{SITE}").json()
    with LiveServer(settings) as server, httpx.Client(base_url=server.url, timeout=30) as client:
        assert client.get(f"/v1/sites/{SITE}").json() == before
        occupancy = client.get(f"/v1/sites/{SITE}/occupancy").json()
        assert occupancy["zones"] == {"entrance": {"count": 0}}
        assert occupancy["lines"] == {"door": {"in": 0, "out": 0}}


def test_a_camera_that_leaves_its_site_through_another_process_ends_its_tracks_with_its_next_frame(
        client: httpx.Client, live_server: LiveServer, demo_camera: FisheyeCamera) -> None:
    put_site_cameras(client, demo_camera)
    walk(client, demo_camera, start=(-2.0, 0.5), velocity=(0.0, 0.0), steps=5, cameras=("cam-a",))
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["count"] == 1
    # Another process shares the database: its write reaches this one only through the next frame.
    other = CameraRegistry(live_server.settings.database)
    record = {k: v for k, v in site_camera_record(demo_camera, "cam-a").items() if k != "site"}
    other.put_record("cam-a", record)
    other.close()
    answer = detect(client, "cam-a", frame_of(demo_camera, "cam-a", (-2.0, 0.5)), T0 + 2)
    assert answer.json()["detections"][0]["track_id"] is None
    assert client.get(f"/v1/sites/{SITE}/occupancy").json()["count"] == 0
