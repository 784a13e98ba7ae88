"""The shipped default model on the shipped sample frames, served as users run it.

`fishloc serve` with no model or camera flags must find the people of `samples/` and place them on
the floor near their true `location_m` (`samples/annotations.json`). The README's curl example is
run as written (only the port is changed, so the test never collides with a server on 8000).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from numpy.typing import NDArray
from service_live_server import free_port, wait_until_ready

from fisheye import load_camera
from models import DEFAULT_MODEL_PATH, DEMO_CAMERA_PATH

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
# Floor-position match radius. A perfect box's foot point misses the ankle midpoint by a median
# 0.2 m (p90 0.42 m) on these renders (README, "Foot point versus floor truth"), so 0.6 m is a match.
MATCH_M = 0.6
# Of the annotated (non-ignore) people over the three frames, at the model's own operating point.
# The shipped model 0.5.0 places 22 of 29 within 0.6 m with 1 detection farther than that from
# everyone (0.4.0 and 0.3.2: 21 and 2; 0.3.1: 20 and 3; 0.3.0, the same boxes at NMS 0.6 without fused feet:
# 20 and 7; 0.2.0, its boxes placed by their near sides: 22 and 5; the 0.1.0 model placed 17). This
# guards that level.
MIN_RECALL = 0.4
MAX_FALSE_PER_FRAME = 2  # detections farther than MATCH_M from every person, ignore regions included


def _annotations() -> dict[str, Any]:
    return dict(json.loads((SAMPLES / "annotations.json").read_text(encoding="utf-8")))


def _truth(annotations: dict[str, Any], image_id: int, crowd: bool) -> NDArray[np.float64]:
    rows = [a["location_m"] for a in annotations["annotations"]
            if a["image_id"] == image_id and bool(a.get("iscrowd", 0)) == crowd]
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2)


def _greedy_matches(truth_xy: NDArray[np.float64], found_xy: NDArray[np.float64], radius_m: float
                    ) -> tuple[int, NDArray[np.bool_]]:
    """(people matched, mask of detections used): nearest pairs first, each used once."""
    used = np.zeros(len(found_xy), dtype=bool)
    if len(truth_xy) == 0 or len(found_xy) == 0:
        return 0, used
    distance = np.linalg.norm(truth_xy[:, None, :] - found_xy[None, :, :], axis=2)
    matched_people: set[int] = set()
    for flat in np.argsort(distance, axis=None):
        person, detection = np.unravel_index(flat, distance.shape)
        if distance[person, detection] > radius_m:
            break
        if int(person) in matched_people or used[detection]:
            continue
        matched_people.add(int(person))
        used[detection] = True
    return len(matched_people), used


@pytest.fixture(scope="module")
def default_serve(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """`fishloc serve` with no model or camera flags, its registry under a fresh XDG_DATA_HOME."""
    home = tmp_path_factory.mktemp("serve-home")
    http_port = free_port()
    env = {**os.environ, "XDG_DATA_HOME": str(home), "FISHLOC_THREADS": "1"}
    log = home / "serve.log"
    with log.open("w") as log_file:  # a file: a pipe nobody reads could fill and stall the server
        process = subprocess.Popen(
            [sys.executable, "-m", "service.cli", "serve", "--http-port", str(http_port),
             "--grpc-port", "-1"],
            cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=log_file)
    url = f"http://127.0.0.1:{http_port}"
    try:
        try:
            wait_until_ready(url, process)
        except (RuntimeError, TimeoutError) as error:
            raise RuntimeError(f"{error}: {log.read_text()[-2000:]}") from None
        yield url
    finally:
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=60)


def test_samples_are_frames_of_the_demo_camera() -> None:
    demo = load_camera(DEMO_CAMERA_PATH)
    for image in _annotations()["images"]:
        camera = load_camera(image["camera"])
        assert camera.image_size == demo.image_size
        np.testing.assert_allclose(camera.principal_point, demo.principal_point)
        np.testing.assert_allclose(camera.focal_px, demo.focal_px)
        np.testing.assert_allclose(camera.kb, demo.kb)
        assert camera.altitude_m == demo.altitude_m


def test_default_model_is_trained() -> None:
    import onnx

    metadata = {p.key: p.value for p in onnx.load(str(DEFAULT_MODEL_PATH)).metadata_props}
    assert "untrained" not in metadata["fishloc.trained_on"].lower(), metadata


def test_default_serve_finds_and_places_the_sample_people(default_serve: str) -> None:
    annotations = _annotations()
    people = matched = false_positives = 0
    for image in annotations["images"]:
        frame = (SAMPLES / image["file_name"]).read_bytes()
        answer = httpx.post(f"{default_serve}/v1/cameras/demo/detect", content=frame,
                            headers={"Content-Type": "image/jpeg"}, timeout=60)
        assert answer.status_code == 200, answer.text
        found = np.asarray([d["position_m"] for d in answer.json()["detections"] if d["position_m"]],
                           dtype=np.float64).reshape(-1, 2)
        truth = _truth(annotations, image["id"], crowd=False)
        hits, used = _greedy_matches(truth, found, MATCH_M)
        people += len(truth)
        matched += hits
        # A detection of a person kept as an ignore region (mostly hidden) is not a false one.
        _, on_crowd = _greedy_matches(_truth(annotations, image["id"], crowd=True), found[~used], MATCH_M)
        false_positives += int((~used).sum() - on_crowd.sum())
    assert people > 0
    assert matched / people >= MIN_RECALL, f"{matched}/{people} people found within {MATCH_M} m"
    assert false_positives <= MAX_FALSE_PER_FRAME * len(annotations["images"]), false_positives


def test_readme_curl_works_as_written(default_serve: str) -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    pattern = r"^(curl -s --data-binary @samples/\S+ .*\\\n\s+localhost:8000/v1/cameras/demo/detect)$"
    match = re.search(pattern, readme, flags=re.MULTILINE)
    assert match, "the README's detect example is not where this test looks for it"
    port = default_serve.rsplit(":", 1)[1]
    command = match.group(1).replace("localhost:8000", f"127.0.0.1:{port}")
    done = subprocess.run(["bash", "-c", command], cwd=ROOT, capture_output=True, text=True, timeout=60,
                          check=False)
    assert done.returncode == 0, done.stderr
    answer = json.loads(done.stdout)
    assert answer["camera_id"] == "demo" and answer["detections"], answer
