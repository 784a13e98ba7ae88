"""The live site map (/site) in a real headless Chromium against a real server: the frames of a
short rendered sequence are posted while the page listens to the site's events, and what it draws
(people with their track ids and trails, zone counts, line tallies, camera views) is compared with
the service's occupancy answer."""

from __future__ import annotations

import urllib.parse
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from service_live_server import LiveServer
from site_sequences import render_sequence, shipped_model_server
from viewer_browser import chromium_driver, console_errors, save_screenshot, wait_for

from evaluation.sequence_data import Sequence, read_sequence
from evaluation.track_playback import ServerClient, install
from service.core.config import Settings

STEPS = 12

MAP_STATE_JS = """
const all = (selector) => [...document.querySelectorAll(selector)];
const map = document.getElementById('live-map');
return {
  state: document.body.dataset.state || null,
  updates: Number(document.body.dataset.updates || 0),
  time: map.dataset.time ? Number(map.dataset.time) : null,
  count: Number(map.dataset.count || 0),
  dots: all('#live-map circle.person').map((c) => ({
    track: c.dataset.track, x: Number(c.getAttribute('cx')), y: -Number(c.getAttribute('cy'))})),
  labels: all('#live-map text.person-label').map((t) => t.textContent),
  trails: all('#live-map polyline.trail').map((p) => ({
    track: p.dataset.track, points: p.getAttribute('points').trim().split(' ').length})),
  zones: Object.fromEntries(all('#live-map polygon.zone').map(
    (z) => [z.dataset.zone, Number(z.dataset.count)])),
  zoneList: Object.fromEntries(all('#zone-list li').map(
    (li) => [li.dataset.zone, li.querySelector('b').textContent])),
  lines: Object.fromEntries(all('#live-map line.count-line').map(
    (l) => [l.dataset.line, {in: Number(l.dataset.in), out: Number(l.dataset.out)}])),
  views: all('#live-map polygon.fov.view').map((p) => p.dataset.camera).sort(),
  rows: all('#tracks tbody tr').map((r) => r.dataset.track),
  live: document.getElementById('live').dataset.live,
};
"""


HISTORY_STATE_JS = """
const chart = document.getElementById('history-chart');
return {
  state: chart.dataset.state || null, rows: Number(chart.dataset.rows || -1),
  crossings: Number(chart.dataset.crossings || -1), peopleMax: Number(chart.dataset.peopleMax || -1),
  bars: chart.querySelectorAll('rect.crossings').length,
  meanPoints: (chart.querySelector('polyline.people-mean')?.getAttribute('points') || '').trim().split(' ')
    .filter(Boolean).length,
  csv: document.getElementById('history-csv').getAttribute('href'),
};
"""


@pytest.fixture(scope="module")
def driver() -> Iterator[Any]:
    with chromium_driver() as chromium:
        yield chromium


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> Sequence:
    return read_sequence(render_sequence(tmp_path_factory.mktemp("site-map-sequence"), STEPS, seed=31))


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    with shipped_model_server(tmp_path_factory.mktemp("site-map")) as live:
        yield live


def map_state(driver: Any) -> dict[str, Any]:
    state: dict[str, Any] = driver.execute_script(MAP_STATE_JS)
    return state


def post_steps(client: ServerClient, sequence: Sequence, steps: range) -> None:
    for index in steps:
        step = sequence.steps[index]
        for frame in step.frames:
            query = urllib.parse.urlencode({"capture_time": repr(step.capture_time)})
            client.request("POST", f"/v1/cameras/{frame.camera_id}/detect?{query}", frame.path.read_bytes(),
                           "image/jpeg")


def test_the_map_follows_the_site_live(driver: Any, server: LiveServer, sequence: Sequence,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    client = ServerClient(server.url)
    try:
        install(client, sequence)
        driver.get(f"{server.url}/site#/{sequence.site_id}")
        wait_for(lambda: map_state(driver)["state"] == "live", "the page to listen to the site's events")
        assert map_state(driver)["views"] == ["hall-east", "hall-west"]
        post_steps(client, sequence, range(STEPS))
    finally:
        client.close()
    occupancy = httpx.get(f"{server.url}/v1/sites/{sequence.site_id}/occupancy").json()
    assert occupancy["time"] == sequence.steps[-1].capture_time and occupancy["count"] > 0
    state = wait_for(lambda: (s := map_state(driver))["time"] == occupancy["time"] and s,
                     "the page to show the last step")
    people = {p["track_id"]: p["position_m"] for p in occupancy["people"]}
    assert {dot["track"] for dot in state["dots"]} == set(people) and state["count"] == occupancy["count"]
    for dot in state["dots"]:
        assert (dot["x"], dot["y"]) == pytest.approx(people[dot["track"]], abs=1e-6)
    assert all(any(label.startswith(f"{track} ") for label in state["labels"]) for track in people)
    assert set(state["rows"]) == set(people)
    zones = {name: body["count"] for name, body in occupancy["zones"].items()}
    assert state["zones"] == zones and state["zoneList"] == {k: str(v) for k, v in zones.items()}
    assert state["lines"] == occupancy["lines"]
    # Tracks seen over several updates leave trails; only tracks there now have one.
    assert state["updates"] > 1 and state["trails"]
    assert {t["track"] for t in state["trails"]} <= set(people)
    assert max(t["points"] for t in state["trails"]) > 2
    assert state["live"] == "on"
    # The history chart: the site's minutes (the open one from memory), its crossings the line totals.
    history = httpx.get(f"{server.url}/v1/sites/{sequence.site_id}/history", params={
        "from": str(occupancy["time"] - 3600), "to": str(occupancy["time"] + 60)}).json()["rows"]
    driver.execute_script("document.getElementById('history-refresh').click()")
    chart = wait_for(lambda: (c := driver.execute_script(HISTORY_STATE_JS))["state"] == "drawn"
                     and c["rows"] == len(history) and c["crossings"] == sum(
                         t["in"] + t["out"] for t in occupancy["lines"].values()) and c,
                     "the history chart to hold the sequence")
    assert history and chart["bars"] == len(history) and chart["meanPoints"] == len(history)
    assert chart["peopleMax"] == max(row["people_max"] for row in history)
    assert chart["csv"].endswith("format=csv")
    csv_text = httpx.get(f"{server.url}{chart['csv']}").text
    assert csv_text.startswith("time,people_mean,people_max")
    save_screenshot(driver, "site_map.png", capsys)
    # Framing the cameras' whole views widens the map to hold each view's outline.
    narrow = driver.execute_script("return JSON.parse(document.getElementById('live-map').dataset.bounds)")
    driver.execute_script("const s = document.getElementById('map-extent'); s.value = 'views';"
                          "s.dispatchEvent(new Event('change'));")
    wide = driver.execute_script("return JSON.parse(document.getElementById('live-map').dataset.bounds)")
    assert wide["xmax"] - wide["xmin"] > narrow["xmax"] - narrow["xmin"] + 10
    assert console_errors(driver) == []


def test_the_viewer_links_the_map_and_a_server_without_sites_says_so(
        driver: Any, settings_for: Callable[..., Settings], tmp_path: Path) -> None:
    with LiveServer(settings_for()) as empty:
        driver.get(f"{empty.url}/")
        link = "return document.getElementById('live-site-link')"
        wait_for(lambda: driver.execute_script(link), "the viewer")
        assert driver.execute_script(f"{link}.getAttribute('href')") == "/site"
        driver.get(f"{empty.url}/site")
        wait_for(lambda: map_state(driver)["state"] == "empty", "the page to find no site")
        status = driver.execute_script("return document.getElementById('status').textContent")
        assert "No site yet" in status
        assert console_errors(driver) == []


def test_a_guarded_site_asks_for_the_read_token_and_then_follows(
        driver: Any, settings_for: Callable[..., Settings], sequence: Sequence) -> None:
    with LiveServer(settings_for(read_token="let-me-see", api_token="let-me-write")) as guarded:
        client = ServerClient(guarded.url, token="let-me-write")
        try:
            install(client, sequence)
            driver.get(f"{guarded.url}/site")
            wait_for(lambda: map_state(driver)["state"] == "token", "the page to ask for the read token")
            assert driver.execute_script("return document.getElementById('token-field').hidden") is False
            field = driver.find_element("id", "read-token")
            field.send_keys("let-me-see")
            driver.execute_script("arguments[0].dispatchEvent(new Event('change'))", field)
            wait_for(lambda: map_state(driver)["state"] == "live", "the page to follow the guarded site")
            post_steps(client, sequence, range(2))
        finally:
            client.close()
        last = sequence.steps[1].capture_time
        wait_for(lambda: map_state(driver)["time"] == last, "the events of the guarded site")
        driver.execute_script("sessionStorage.clear()")
        errors = console_errors(driver)  # only the refused first look, before the token
        assert all("/v1/sites - Failed to load resource" in e and "401" in e for e in errors)
