"""Occupancy out, end to end: a rendered sequence played through `fishloc serve` (the shipped model)
with a real mosquitto broker and a real webhook receiver that refuses for its first 20 s, the server
restarted halfway. At the end the retained MQTT counts equal `/occupancy`, the MQTT and webhook
crossing events and the history's minute rows add up to the line totals of both runs, the Home
Assistant discovery configs carry what Home Assistant needs, and every webhook event arrived once."""

from __future__ import annotations

import csv
import io
import json
import urllib.parse
from pathlib import Path
from typing import Any

import httpx
import pytest
from output_peers import Receiver, Subscriber, fishloc_serve, mosquitto, wait_for
from site_sequences import render_sequence

from evaluation.sequence_data import Sequence, read_sequence
from evaluation.track_playback import ServerClient, install

STEPS = 36
SECRET = "a-webhook-secret"
REFUSE_S = 20.0
HA_REQUIRED = ("name", "state_topic", "unique_id", "device", "availability_topic", "unit_of_measurement",
               "state_class")


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Sequence:
    return read_sequence(render_sequence(tmp_path_factory.mktemp("outputs-sequence"), STEPS, seed=27))


def play(url: str, sequence: Sequence, steps: range) -> dict[str, Any]:
    """Post the frames of `steps`; the site's occupancy after them."""
    client = ServerClient(url)
    try:
        for index in steps:
            step = sequence.steps[index]
            for frame in step.frames:
                query = urllib.parse.urlencode({"capture_time": repr(step.capture_time)})
                client.request("POST", f"/v1/cameras/{frame.camera_id}/detect?{query}",
                               frame.path.read_bytes(), "image/jpeg")
        _, occupancy = client.request("GET", f"/v1/sites/{sequence.site_id}/occupancy")
    finally:
        client.close()
    answer: dict[str, Any] = occupancy
    return answer


def crossings(lines: dict[str, dict[str, int]]) -> int:
    return sum(tally["in"] + tally["out"] for tally in lines.values())


def test_a_sequence_through_fishloc_serve_reaches_mqtt_webhooks_and_history(
        sequence: Sequence, tmp_path: Path) -> None:
    site, half = sequence.site_id, STEPS // 2
    database = tmp_path / "registry.db"
    env = {"FISHLOC_WEBHOOK_MAX_BACKOFF_S": "2"}
    receiver = Receiver(SECRET, refuse_s=REFUSE_S)
    hook = {"url": receiver.url, "secret": SECRET, "events": ["line_crossing", "zone_threshold", "summary"],
            "zone_thresholds": dict.fromkeys(sequence.zones, 1), "summary_every_s": 2}
    with mosquitto(tmp_path) as broker, receiver.running(), Subscriber(broker.port) as heard:
        with fishloc_serve(database, "--mqtt", broker.url, env=env, log=tmp_path / "serve-1.log") as url:
            client = ServerClient(url)
            install(client, sequence)
            client.put_json(f"/v1/sites/{site}/webhooks/building", hook)
            client.close()
            first = play(url, sequence, range(half))
        # Stopped while the receiver still refuses: the events wait in the outbox.
        assert not receiver.accepted and receiver.refused > 0
        assert heard.latest.get("fishloc/status") == "offline"
        with fishloc_serve(database, "--mqtt", broker.url, env=env, log=tmp_path / "serve-2.log") as url:
            last = play(url, sequence, range(half, STEPS))
            log = wait_for(lambda: (answer := httpx.get(f"{url}/v1/sites/{site}/webhooks/building").json())
                           ["pending"] == 0 and answer, 90, "the outbox to empty", every_s=0.5)
            start, end = sequence.steps[0].capture_time, sequence.steps[-1].capture_time
            query = {"from": str(int(start) - 60), "to": str(int(end) + 60), "step": "60"}
            history = httpx.get(f"{url}/v1/sites/{site}/history", params=query).json()
            table = httpx.get(f"{url}/v1/sites/{site}/history", params=query,
                              headers={"Accept": "text/csv"})
            ready = httpx.get(f"{url}/readyz").json()
            count_topic = f"fishloc/{site}/count"
            wait_for(lambda: heard.latest.get(count_topic) == str(last["count"]), 10, "the count on MQTT")
        with Subscriber(broker.port) as later:  # what a client connecting now finds retained
            wait_for(lambda: len(later.retained) >= len(heard.latest) - 1, 10, "the retained topics")

    totals = crossings(first["lines"]) + crossings(last["lines"])
    assert totals > 0  # the sequence has people walking through the doors

    # MQTT: the retained counts are the routes' answer.
    retained = later.retained
    assert retained[f"fishloc/{site}/count"] == str(last["count"])
    for zone, value in last["zones"].items():
        assert retained[f"fishloc/{site}/zones/{zone}/count"] == str(value["count"])
    for line, tally in last["lines"].items():
        assert json.loads(retained[f"fishloc/{site}/lines/{line}"]) == tally
    # Availability: online while each run was up, offline when it stopped.
    assert retained["fishloc/status"] == "offline"
    assert [p for t, p in heard.messages if t == "fishloc/status"] == ["online", "offline"] * 2
    events = heard.events(f"fishloc/{site}/events")
    assert len([e for e in events if e["type"] == "line_crossing"]) == totals
    assert {e["type"] for e in events} <= {"line_crossing", "zone_enter", "zone_leave"}
    assert any(e["type"] == "zone_enter" for e in events)
    assert ready["outputs"]["mqtt"]["connected"] is True

    # Home Assistant discovery: a sensor per site count, zone and line direction, with what HA needs.
    configs = {topic: json.loads(payload) for topic, payload in retained.items()
               if topic.startswith("homeassistant/sensor/") and payload}
    assert len(configs) == 1 + len(sequence.zones) + 2 * len(sequence.lines)
    for topic, config in configs.items():
        assert all(config.get(key) for key in HA_REQUIRED), topic
        assert topic == f"homeassistant/sensor/{config['unique_id']}/config"
        assert config["device"]["identifiers"] and config["availability_topic"] == "fishloc/status"
        assert config["state_topic"] in retained
    assert len({config["unique_id"] for config in configs.values()}) == len(configs)

    # Webhooks: every event once, signed, after 20 s of refusals and a restart.
    assert receiver.bad_signatures == 0
    assert set(receiver.accepted_times.values()) == {1}
    assert len(receiver.of_type("line_crossing")) == totals
    assert receiver.of_type("summary") and receiver.of_type("zone_threshold")
    for event in receiver.accepted.values():
        assert event["site"] == site and isinstance(event["time"], float)
    assert log["failures"] and all(d["last_error"] == "HTTP 503" and d["last_status"] == 200
                                   for d in log["failures"])

    # History: the minute rows add up to both runs' line totals; the CSV says the same.
    rows = history["rows"]
    assert history["step_s"] == 60 and rows
    assert sum(crossings(row["lines"]) for row in rows) == totals
    assert max(row["people_max"] for row in rows) >= max(first["count"], last["count"])
    assert table.headers["content-type"].startswith("text/csv")
    parsed = list(csv.DictReader(io.StringIO(table.text)))
    assert [int(r["time"]) for r in parsed] == [row["time"] for row in rows]
    line_columns = [c for c in parsed[0] if c.startswith("line:")]
    assert sum(int(r[c]) for r in parsed for c in line_columns if r[c]) == totals
