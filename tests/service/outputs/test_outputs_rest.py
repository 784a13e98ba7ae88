"""The outputs' routes on a real server (the test double): webhook writes and their refusals, the
history route and its refusals, `/readyz` and metrics with an unreachable broker and receiver."""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from output_peers import Receiver, free_port, mosquitto, wait_for
from service_live_server import LiveServer
from service_sites import SITE, T0, put_site_cameras, walk

from fisheye import FisheyeCamera
from service.core.config import Settings

HOOK = {"url": "http://127.0.0.1:9/hook", "secret": "s3cret-key", "events": ["line_crossing"]}
DOOR = {"from_m": [0.0, -3.0], "to_m": [0.0, 3.0]}


@pytest.fixture
def client(live_server: LiveServer, demo_camera: FisheyeCamera) -> Iterator[httpx.Client]:
    with httpx.Client(base_url=live_server.url, timeout=30) as http:
        put_site_cameras(http, demo_camera)
        yield http


def _error(answer: httpx.Response, status: int, code: str) -> dict[str, Any]:
    assert answer.status_code == status, answer.text
    error: dict[str, Any] = answer.json()["error"]
    assert error["code"] == code and error["message"]
    return error


@pytest.mark.parametrize("body", [
    {**HOOK, "url": "ftp://127.0.0.1/x"},
    {**HOOK, "url": "not a url"},
    {**HOOK, "url": "http://"},
    {k: v for k, v in HOOK.items() if k != "secret"},
    {**HOOK, "secret": "short"},
    {**HOOK, "events": []},
    {**HOOK, "events": ["everything"]},
    {**HOOK, "events": ["zone_threshold"]},                               # no thresholds
    {**HOOK, "events": ["zone_threshold"], "zone_thresholds": {"entrance": 0}},
    {**HOOK, "events": ["zone_threshold"], "zone_thresholds": {"entrance": -2}},
    {**HOOK, "events": ["zone_threshold"], "zone_thresholds": {"entrance": "many"}},
    {**HOOK, "events": ["zone_threshold"], "zone_thresholds": {"bad zone!": 3}},
    {**HOOK, "summary_every_s": 0},
    {**HOOK, "colour": "blue"},
])
def test_invalid_webhooks_are_refused_and_change_nothing(client: httpx.Client, body: dict[str, Any]) -> None:
    _error(client.put(f"/v1/sites/{SITE}/webhooks/hook-1", json=body), 422, "invalid_webhook")
    _error(client.get(f"/v1/sites/{SITE}/webhooks/hook-1"), 404, "webhook_not_found")


def test_webhook_writes(client: httpx.Client) -> None:
    path = f"/v1/sites/{SITE}/webhooks/hook-1"
    _error(client.put("/v1/sites/nowhere/webhooks/hook-1", json=HOOK), 404, "site_not_found")
    _error(client.put(path, content=b"{", headers={"Content-Type": "application/json"}), 400, "bad_json")
    assert client.put(path, json=HOOK).status_code == 201
    answer = client.put(path, json={**HOOK, "events": ["summary"], "summary_every_s": 30})
    assert answer.status_code == 200 and answer.json()["events"] == ["summary"]
    shown = client.get(path).json()
    assert shown["secret"] == "(set)" and HOOK["secret"] not in str(shown)
    assert shown["summary_every_s"] == 30 and shown["pending"] == 0 and shown["deliveries"] == []
    assert client.delete(path).status_code == 204
    _error(client.delete(path), 404, "webhook_not_found")


def test_webhook_writes_need_the_token(settings_for: Callable[..., Settings],
                                       demo_camera: FisheyeCamera) -> None:
    with LiveServer(settings_for(api_token="t0ken")) as live, httpx.Client(base_url=live.url) as http:
        http.headers["Authorization"] = "Bearer t0ken"
        put_site_cameras(http, demo_camera)
        path = f"/v1/sites/{SITE}/webhooks/hook-1"
        _error(httpx.put(live.url + path, json=HOOK), 401, "unauthorized")
        assert http.put(path, json=HOOK).status_code == 201
        _error(httpx.delete(live.url + path), 401, "unauthorized")


@pytest.mark.parametrize("query", [
    {"from": "yesterday"},
    {"to": "1e30"},
    {"from": str(T0 + 100), "to": str(T0)},
    {"from": str(T0), "to": str(T0 + 3600), "step": "90"},
    {"from": str(T0), "to": str(T0 + 3600), "step": "0"},
    {"from": str(T0), "to": str(T0 + 3600), "step": "-60"},
    {"from": str(T0), "to": str(T0 + 3600), "step": "sixty"},
    {"from": str(T0), "to": str(T0 + 3600), "step": str(32 * 86400)},
    {"from": str(T0 - 365 * 86400), "to": str(T0), "step": "60"},  # half a million rows
])
def test_invalid_history_queries_are_refused(client: httpx.Client, query: dict[str, str]) -> None:
    answer = client.get(f"/v1/sites/{SITE}/history", params=query)
    assert answer.status_code == 422, answer.text
    assert answer.json()["error"]["code"] in ("invalid_history_query", "invalid_request")


def test_history_of_a_walk_through_a_door(client: httpx.Client, live_server: LiveServer,
                                          demo_camera: FisheyeCamera) -> None:
    _error(client.get("/v1/sites/nowhere/history"), 404, "site_not_found")
    assert client.put(f"/v1/sites/{SITE}/lines/door", json=DOOR).status_code == 201
    # 90 s of capture time: the walker crosses the door in the first minute, stands in the second.
    walk(client, demo_camera, start=(-2.0, 0.5), velocity=(1.0, 0.0), steps=20)
    walk(client, demo_camera, start=(1.0, 0.5), velocity=(0.0, 0.0), steps=5, t0=T0 + 70)
    totals = client.get(f"/v1/sites/{SITE}/occupancy").json()["lines"]["door"]
    assert totals == {"in": 1, "out": 0}
    query = {"from": str(T0 - 120), "to": str(T0 + 300)}
    for step in (60, 3600, 86400):
        rows = client.get(f"/v1/sites/{SITE}/history", params={**query, "step": step}).json()["rows"]
        assert sum(row["lines"]["door"]["in"] for row in rows) == 1, step
        assert all(row["time"] % step == 0 for row in rows)
        assert max(row["people_max"] for row in rows) == 1
    minutes = client.get(f"/v1/sites/{SITE}/history", params={**query, "step": 60}).json()["rows"]
    assert len(minutes) == 2  # the open minute is answered from memory
    iso = {"from": "2025-12-01T17:58:00Z", "to": "2025-12-01T18:05:00+00:00", "step": "60"}
    assert client.get(f"/v1/sites/{SITE}/history", params=iso).json()["rows"] == minutes
    text = client.get(f"/v1/sites/{SITE}/history", params={**query, "step": 60},
                      headers={"Accept": "text/csv"}).text
    parsed = list(csv.DictReader(io.StringIO(text)))
    assert [int(row["time"]) for row in parsed] == [row["time"] for row in minutes]
    assert sum(int(row["line:door:in"]) for row in parsed) == 1


def test_an_unreachable_broker_and_receiver_show_in_readyz_and_metrics(
        settings_for: Callable[..., Settings], demo_camera: FisheyeCamera, tmp_path: Path) -> None:
    dead_port = free_port()  # nothing listens there
    settings = settings_for(mqtt=f"mqtt://127.0.0.1:{dead_port}", webhook_max_backoff_s=1)
    with LiveServer(settings) as live, httpx.Client(base_url=live.url, timeout=30) as http:
        put_site_cameras(http, demo_camera)
        assert http.put(f"/v1/sites/{SITE}/lines/door", json=DOOR).status_code == 201
        hook = {**HOOK, "url": f"http://127.0.0.1:{dead_port}/hook"}
        assert http.put(f"/v1/sites/{SITE}/webhooks/hook-1", json=hook).status_code == 201
        walk(http, demo_camera, start=(-2.0, 0.5), velocity=(1.0, 0.0), steps=20)  # detection goes on
        assert http.get(f"/v1/sites/{SITE}/occupancy").json()["lines"]["door"] == {"in": 1, "out": 0}

        def troubled() -> dict[str, Any] | None:
            ready = http.get("/readyz")
            outputs: dict[str, Any] = ready.json()["outputs"]
            failing = not outputs["mqtt"]["ok"] and not outputs["webhooks"]["ok"]
            return outputs if ready.status_code == 200 and failing else None

        outputs = wait_for(troubled, 20, "the outputs to report their trouble")
        assert outputs["mqtt"]["connected"] is False and outputs["mqtt"]["error"]
        assert outputs["webhooks"]["failing"] == [f"{SITE}/hook-1"] and outputs["history"]["ok"]
        log = http.get(f"/v1/sites/{SITE}/webhooks/hook-1").json()
        assert log["pending"] == 1 and log["failures"][0]["last_error"]
        metrics = http.get("/metrics").text
        assert 'fishloc_output_failures_total{sink="mqtt"}' in metrics
        assert 'fishloc_output_failures_total{sink="webhooks"}' in metrics
        # The broker comes up: the retained state is sent; the receiver comes up: the event is delivered.
        receiver = Receiver(HOOK["secret"], port=dead_port)
        with receiver.running():
            wait_for(lambda: receiver.of_type("line_crossing"), 20, "the pending crossing")
        with mosquitto(tmp_path, port=dead_port):
            wait_for(lambda: http.get("/readyz").json()["outputs"]["mqtt"]["connected"], 40,
                     "the MQTT reconnection")
