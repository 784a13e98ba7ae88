"""`fishloc synth --sequence`: one world seen by a site's cameras in step, people with tracks."""

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from detector.data.rays import posed_grid, ray_grid
from detector.data.sequence import SequenceConfig, SequenceRenderer
from detector.data.sequence_writer import write_sequence
from detector.data.site_world import default_plan, load_plan
from detector.data.walkers import sample_walkers
from fisheye import camera_to_dict, load_camera
from service.cli import main

SIZE = 256
CONFIG = SequenceConfig(plan=default_plan(), steps=6, fps=5.0, seed=11, size=SIZE)


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    folder = tmp_path_factory.mktemp("sequence")
    return folder, write_sequence(folder, CONFIG, workers=1)


def _inside_box(uv: np.ndarray, box: list[float], principal_point: tuple[float, float],
                margin_px: float) -> bool:
    """Is pixel `uv` inside the radius-aligned box (cx, cy, w, h), grown by `margin_px`?"""
    cx, cy, w, h = box
    radial = np.array([cx - principal_point[0], cy - principal_point[1]])
    radial /= max(float(np.hypot(*radial)), 1e-9)
    offset = uv - np.array([cx, cy])
    along = abs(float(offset @ radial))
    across = abs(float(offset @ np.array([-radial[1], radial[0]])))
    return along <= h / 2 + margin_px and across <= w / 2 + margin_px


def test_a_posed_grid_looks_at_the_world_from_its_pose() -> None:
    camera = default_plan().cameras[1].scaled_to((64, 64))
    local = ray_grid(camera)
    posed = posed_grid(local, (3.25, -0.3), np.radians(35.0))
    assert np.array_equal(posed.valid, local.valid)
    rays = posed.directions[posed.valid].astype(np.float64)
    points_world = posed.origin + 2.5 * rays
    local_rays = local.directions[local.valid].astype(np.float64)
    points_camera = np.array([0.0, 0.0, camera.altitude_m]) + 2.5 * local_rays
    assert np.allclose(posed.world_to_camera(points_world), points_camera, atol=1e-5)
    unposed = posed_grid(local, (0.0, 0.0), 0.0)
    assert np.array_equal(unposed.directions, local.directions)
    assert np.array_equal(unposed.origin, local.origin)


def test_frames_and_records_follow_the_sequence_format(sequence: tuple[Path, dict[str, Any]]) -> None:
    folder, document = sequence
    assert json.loads((folder / "annotations.json").read_text()) == document
    cameras = [c.id for c in CONFIG.plan.cameras]
    assert len(document["images"]) == CONFIG.steps * len(cameras)
    times: dict[int, set[float]] = defaultdict(set)
    for image in document["images"]:
        assert (folder / image["file_name"]).is_file()
        assert image["file_name"].split("/")[0] == image["camera"]["id"] in cameras
        assert image["camera"]["site"] == "synth-hall" and "site_pose" in image["camera"]
        times[image["step"]].add(image["capture_time"])
    # Every camera of a step shares its capture time; steps are 1 / fps apart.
    assert all(len(t) == 1 for t in times.values())
    stamps = [times[s].pop() for s in range(CONFIG.steps)]
    assert np.allclose(np.diff(stamps), 1 / CONFIG.fps)
    site = document["site"]
    assert set(site["zones"]) == {"entrance", "middle", "counter"}
    assert all(set(body) == {"polygon_m"} for body in site["zones"].values())
    assert all(set(body) == {"from_m", "to_m"} for body in site["lines"].values())
    assert document["info"]["people"] == len(site["tracks"]) >= 10
    for record in document["annotations"]:
        assert isinstance(record["track_id"], int) and len(record["site_location_m"]) == 2


def test_a_persons_site_position_lands_in_their_box_in_every_camera(
        sequence: tuple[Path, dict[str, Any]]) -> None:
    _, document = sequence
    images = {image["id"]: image for image in document["images"]}
    checked = 0
    seen_by: dict[tuple[int, int], set[str]] = defaultdict(set)
    for record in document["annotations"]:
        image = images[record["image_id"]]
        camera = load_camera({k: v for k, v in image["camera"].items() if k != "site"})
        assert camera.site_pose is not None
        local = camera.site_pose.site_to_floor(np.array([record["site_location_m"]]))
        assert np.allclose(local[0], record["location_m"], atol=1e-4)
        if record["visible_fraction"] < 0.95:
            continue  # a hidden part (the feet behind a bench) leaves the floor point outside the box
        uv = camera.floor_to_pixels(local)[0]
        assert _inside_box(uv, record["rotated_box"], camera.principal_point, margin_px=2.0), record
        seen_by[(image["step"], record["track_id"])].add(camera.id)
        checked += 1
    assert checked > 20
    # The cameras overlap: many people are in both views at once.
    assert sum(len(c) == 2 for c in seen_by.values()) > len(seen_by) / 2


def test_the_same_seed_renders_the_same_sequence_and_another_seed_does_not() -> None:
    small = SequenceConfig(plan=default_plan(), steps=30, fps=5.0, seed=11, size=96)
    first, again = SequenceRenderer(small), SequenceRenderer(small)
    other = SequenceRenderer(SequenceConfig(plan=default_plan(), steps=30, fps=5.0, seed=12, size=96))
    for step, camera in ((0, 0), (29, 1)):
        a, b, c = first.render(step, camera), again.render(step, camera), other.render(step, camera)
        assert a.jpeg == b.jpeg and a.people == b.people
        assert a.jpeg != c.jpeg
    assert len(first.walkers) == len(again.walkers)
    assert all(np.array_equal(w.positions_m, v.positions_m, equal_nan=True)
               for w, v in zip(first.walkers, again.walkers, strict=True))


def test_people_walk_at_walking_speed_and_keep_apart() -> None:
    renderer = SequenceRenderer(SequenceConfig(plan=default_plan(), steps=300, fps=5.0, seed=5, size=96))
    walkers = sample_walkers(renderer.world, 300, 5.0, 5)
    assert len(walkers) >= 10
    entering = 0
    for walker in walkers:
        inside = np.isfinite(walker.positions_m[:, 0])
        steps = np.flatnonzero(inside[1:] & inside[:-1])
        speeds = np.hypot(*np.diff(walker.positions_m, axis=0)[steps].T) * 5.0
        moving = speeds[speeds > 0.5]
        assert moving.size == 0 or moving.max() <= 1.5 + 1e-6
        entering += int(not inside[0] and inside.any())
    assert entering >= 5  # most come in through a door during the sequence
    positions = np.stack([w.positions_m for w in walkers])  # (P, T, 2)
    gaps = np.linalg.norm(positions[:, None] - positions[None], axis=3)  # (P, P, T)
    gaps[np.arange(len(walkers)), np.arange(len(walkers))] = np.inf
    assert np.nanmin(gaps) >= 0.5


def test_a_site_file_gives_the_plan(tmp_path: Path) -> None:
    plan = default_plan()
    document = {
        "id": "lobby",
        "room_m": [-6, -4, 6, 4],
        "cameras": [{**camera_to_dict(c), "site": "lobby"} for c in plan.cameras],
        "doors": [{"wall": "south", "at_m": 1.0, "width_m": 1.0}],
        "zones": {"desk": [[0, 0], [2, 0], [2, 2]]},
        "lines": {"door": {"from_m": [0.5, -3], "to_m": [1.5, -3]}},
    }
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(document))
    loaded = load_plan(path)
    assert (loaded.site_id, loaded.room_m, loaded.doors[0].wall) == ("lobby", (-6, -4, 6, 4), "south")
    assert loaded.cameras == plan.cameras
    assert loaded.to_dict()["lines"] == {"door": {"from_m": [0.5, -3], "to_m": [1.5, -3]}}
    frame = SequenceRenderer(SequenceConfig(plan=loaded, steps=2, seed=1, size=64)).render(1, 0)
    assert frame.camera.site_pose == plan.cameras[0].site_pose


def test_the_command_writes_a_sequence(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "seq"
    assert main(["synth", "--sequence", "--out", str(out), "--seconds", "0.4", "--fps", "5", "--size", "64",
                 "--seed", "2", "--workers", "2", "--quiet"]) == 0
    assert "2 steps x 2 cameras = 4 frames" in capsys.readouterr().out
    assert sorted(p.name for p in (out / "hall-west").iterdir()) == ["000001.jpg", "000002.jpg"]
    assert main(["synth", "--sequence", "--out", str(tmp_path / "few"), "--seconds", "0.2", "--size", "32",
                 "--people", "4", "--workers", "1", "--quiet"]) == 0
    assert json.loads((tmp_path / "few" / "annotations.json").read_text())["info"]["people"] == 4
    assert main(["synth", "--sequence", "--out", str(out), "--people", "3-5"]) == 2
    assert main(["synth", "--sequence", "--images", "3", "--out", str(out)]) == 2
    assert main(["synth", "--sequence", "--out", str(out), "--fps", "0"]) == 2
