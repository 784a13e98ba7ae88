"""The camera registry on a real SQLite file: CRUD, validation, persistence, seeding, concurrency."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from fisheye import CalibrationError, FisheyeCamera, camera_from_dict, camera_to_dict, save_camera
from models import DEMO_CAMERA_PATH
from service.cameras import CameraRegistry, database_url


def _camera(camera_id: str, altitude_m: float = 3.0) -> FisheyeCamera:
    return camera_from_dict({
        "id": camera_id, "altitude_m": altitude_m, "image_size": [1000, 1000],
        "principal_point": [499.5, 499.5], "focal_px": [320.0, 320.0], "kb": [1.0, -0.01],
    })


@pytest.fixture
def registry(tmp_path: Path) -> CameraRegistry:
    return CameraRegistry(tmp_path / "cameras.db")


def test_database_url() -> None:
    assert database_url("postgresql+psycopg://u@h/db") == "postgresql+psycopg://u@h/db"
    assert database_url("/tmp/x.db") == "sqlite:////tmp/x.db"


def test_crud(registry: CameraRegistry) -> None:
    assert registry.all() == [] and registry.get("a") is None
    assert registry.put(_camera("b")).created
    assert registry.put(_camera("a")).created
    assert [c.id for c in registry.all()] == ["a", "b"] == registry.ids()
    replaced = registry.put(_camera("a", altitude_m=4.5))
    assert not replaced.created
    a = registry.get("a")
    assert a is not None and a.altitude_m == 4.5
    assert registry.delete("a") and not registry.delete("a")
    assert registry.get("a") is None and registry.ids() == ["b"]


def test_put_record_validates_with_the_geometry_package(registry: CameraRegistry) -> None:
    record = camera_to_dict(_camera("x"))
    del record["id"]
    assert registry.put_record("x", record).camera.id == "x"
    with pytest.raises(CalibrationError, match="differs"):
        registry.put_record("x", {**record, "id": "y"})
    with pytest.raises(CalibrationError, match="strictly increasing"):
        registry.put_record("x", {**record, "kb": [1.0, -0.5]})
    with pytest.raises(CalibrationError, match="altitude_m"):
        registry.put_record("x", {**record, "altitude_m": -1})


def test_changes_survive_reopening(tmp_path: Path) -> None:
    first = CameraRegistry(tmp_path / "r.db")
    first.put(_camera("kept", altitude_m=2.5))
    first.put(_camera("gone"))
    first.delete("gone")
    first.close()
    second = CameraRegistry(tmp_path / "r.db")
    kept = second.get("kept")
    assert kept is not None and kept.altitude_m == 2.5 and second.ids() == ["kept"]


def test_a_write_elsewhere_is_seen_on_the_next_read(tmp_path: Path) -> None:
    """Two registries on one database stand for two processes: the cache follows the revision."""
    reader, writer = CameraRegistry(tmp_path / "r.db"), CameraRegistry(tmp_path / "r.db")
    writer.put(_camera("c", altitude_m=3.0))
    first = reader.get("c")
    assert first is not None and first.altitude_m == 3.0
    assert reader.get("c") is first  # cached while the revision is unchanged
    writer.put(_camera("c", altitude_m=3.3))
    second = reader.get("c")
    assert second is not None and second.altitude_m == 3.3
    writer.delete("c")
    assert reader.get("c") is None


def test_seed_from_file_wins_and_demo_is_seeded_once(tmp_path: Path, registry: CameraRegistry) -> None:
    assert registry.seed_once("seeded:demo", DEMO_CAMERA_PATH)
    assert registry.ids() == ["demo"]
    registry.delete("demo")
    assert not registry.seed_once("seeded:demo", DEMO_CAMERA_PATH)  # a deleted demo stays deleted
    assert registry.ids() == []
    folder = tmp_path / "cams"
    folder.mkdir()
    save_camera(_camera("lobby", altitude_m=3.1), folder / "lobby.yaml")
    save_camera(_camera("hall"), folder / "hall.json")
    registry.put(_camera("lobby", altitude_m=9.0))
    from fisheye import load_cameras

    registry.seed(load_cameras(folder), str(folder))
    lobby = registry.get("lobby")
    assert registry.ids() == ["hall", "lobby"] and lobby is not None and lobby.altitude_m == 3.1


def test_concurrent_reads_and_writes(registry: CameraRegistry) -> None:
    registry.put(_camera("busy"))
    errors: list[BaseException] = []
    seen: set[float | None] = set()

    def reader() -> None:
        try:
            for _ in range(150):
                camera = registry.get("busy")
                seen.add(None if camera is None else camera.altitude_m)
        except BaseException as error:
            errors.append(error)

    def writer() -> None:
        try:
            for i in range(60):
                if i % 3 == 2:
                    registry.delete("busy")
                else:
                    registry.put(_camera("busy", altitude_m=2.0 + (i % 2)))
        except BaseException as error:
            errors.append(error)

    threads = [threading.Thread(target=reader) for _ in range(3)] + [threading.Thread(target=writer)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert seen <= {None, 2.0, 3.0}
