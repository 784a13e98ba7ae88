"""`fishloc eval --tracks`: a short sequence rendered here, played through a real server (and the
same server in process, and the tracker alone), scored against its truth."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from service_live_server import LiveServer
from site_sequences import render_sequence, shipped_model_server

from evaluation.sequence_data import read_sequence
from evaluation.track_playback import ServerClient, play_through_server
from models import DEFAULT_MODEL_PATH
from service.cli import main

STEPS = 15


@pytest.fixture(scope="module")
def sequence_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_sequence(tmp_path_factory.mktemp("track-sequence"), STEPS, seed=21)


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    with shipped_model_server(tmp_path_factory.mktemp("track-server")) as live:
        yield live


def _figures(path: Path) -> dict[str, Any]:
    figures: dict[str, Any] = json.loads(path.read_text())
    return figures


def test_the_tracker_alone_follows_the_true_positions(sequence_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "gt.json"
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--ground-truth-detections",
                 "--json", str(out), "--quiet"]) == 0
    figures = _figures(out)
    assert figures["mode"] == "ground_truth_detections"
    assert (figures["steps"], figures["frames"]) == (STEPS, 2 * STEPS)
    # Exact positions: no false people, no duplicates, no switches; only the first steps of a new
    # track (before it is confirmed) are missed.
    assert (figures["false_positives"], figures["duplicates"], figures["id_switches"]) == (0, 0, 0)
    assert figures["mota"] > 0.75 and figures["idf1"] > 0.85
    assert figures["detections"] is None  # no detector ran
    for line in figures["lines"].values():
        assert all(line[d]["reported"] == line[d]["true"] for d in ("in", "out"))


def test_playback_through_a_server_installs_the_site_and_tracks_in_capture_time(
        sequence_file: Path, server: LiveServer) -> None:
    sequence = read_sequence(sequence_file)
    client = ServerClient(server.url)
    try:
        reported = play_through_server(client, sequence)
    finally:
        client.close()
    # Tracking time is the frames' capture time, whatever the wall clock.
    assert reported.times == [step.capture_time for step in sequence.steps]
    site = httpx.get(f"{server.url}/v1/sites/synth-hall").json()
    assert sorted(c["id"] for c in site["cameras"]) == ["hall-east", "hall-west"]
    assert {z["id"]: z["polygon_m"] for z in site["zones"]} == {
        name: body["polygon_m"] for name, body in sequence.zones.items()}
    assert {line["id"] for line in site["lines"]} == set(sequence.lines)
    assert sum(len(people) for people in reported.people) > 0


def test_the_command_against_a_server_and_in_process_agree(sequence_file: Path, server: LiveServer,
                                                           tmp_path: Path) -> None:
    remote, local = tmp_path / "server.json", tmp_path / "model.json"
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--server", server.url,
                 "--json", str(remote), "--quiet"]) == 0
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--model", str(DEFAULT_MODEL_PATH),
                 "--threads", "1", "--json", str(local), "--quiet"]) == 0
    a, b = _figures(remote), _figures(local)
    assert (a["mode"], b["mode"]) == ("server", "model")
    # The same frames through the same model and tracker: the same figures (a replay starts afresh).
    same = ("mota", "idf1", "id_switches", "duplicates", "false_positives", "misses", "zones", "lines")
    assert {k: a[k] for k in same} == {k: b[k] for k in same}
    assert a["recall"] > 0.5 and 0 <= a["duplicate_rate"] <= 1
    # What the detector fed the tracker: every frame, most people found, cameras agreeing roughly.
    detections = a["detections"]
    assert detections == b["detections"] and detections["frames"] == 2 * STEPS
    assert detections["recall"] > 0.5 and detections["camera_spread_m"]["p50"] < 0.75
    # A threshold no score reaches: nobody detected, nobody reported.
    strict = tmp_path / "strict.json"
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--server", server.url,
                 "--min-score", "1", "--json", str(strict), "--quiet"]) == 0
    figures = _figures(strict)
    assert figures["min_score"] == 1.0
    assert (figures["detections"]["recall"], figures["reported_people_steps"]) == (0, 0)


def test_bad_arguments_and_files_are_refused(sequence_file: Path, tmp_path: Path) -> None:
    not_a_sequence = tmp_path / "plain.json"
    not_a_sequence.write_text(json.dumps({"images": [{"id": 1}], "annotations": []}))
    out = str(tmp_path / "out.json")
    assert main(["eval", "--tracks", "--data", str(not_a_sequence), "--ground-truth-detections",
                 "--json", out]) == 2
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--ground-truth-detections",
                 "--noise-m", "-1", "--json", out]) == 2
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--server", "http://127.0.0.1:1",
                 "--min-score", "2", "--json", out]) == 2
    with pytest.raises(SystemExit):  # --server, --model and --ground-truth-detections exclude each other
        main(["eval", "--tracks", "--data", str(sequence_file), "--server", "http://127.0.0.1:1",
              "--ground-truth-detections", "--json", out])
    assert main(["eval", "--tracks", "--data", str(sequence_file), "--server", "http://127.0.0.1:1",
                 "--json", out, "--quiet"]) == 1  # nothing listens there
