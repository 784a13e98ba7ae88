"""The camera registry: calibrations in a real database, validated by the geometry package.

SQLite file by default; any SQLAlchemy URL (e.g. `postgresql+psycopg://...`) works the same way.
Each row holds one camera-file record as JSON and a revision number that every write bumps. Reads go
to the database on every frame, so a change takes effect on the next frame, in every process that
shares the database; the parsed camera is cached per (id, record) so validation is paid once.
Cameras are immutable objects: a detection that started before a PUT or DELETE finishes with the
calibration it read.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sqlalchemy import (
    Column,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    create_engine,
    event,
    insert,
    select,
    update,
)
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError, ProgrammingError
from sqlalchemy.pool import StaticPool

from fisheye import CalibrationError, FisheyeCamera, camera_from_dict, camera_to_dict, load_camera

log = logging.getLogger(__name__)

_metadata = MetaData()
cameras_table = Table(
    "cameras", _metadata,
    Column("id", String(64), primary_key=True),
    Column("record", Text, nullable=False),
    Column("revision", Integer, nullable=False),
)
# Zones and counting lines of sites (`sites.layout`), one JSON record each; service.sites.store reads them.
site_zones_table = Table(
    "site_zones", _metadata,
    Column("site", String(64), primary_key=True),
    Column("id", String(64), primary_key=True),
    Column("record", Text, nullable=False),
)
site_lines_table = Table(
    "site_lines", _metadata,
    Column("site", String(64), primary_key=True),
    Column("id", String(64), primary_key=True),
    Column("record", Text, nullable=False),
)
# One-off facts about the database, e.g. that the demo camera was seeded once (so deleting it sticks).
registry_meta = Table(
    "registry_meta", _metadata,
    Column("key", String(64), primary_key=True),
    Column("value", Text, nullable=False),
)


def database_url(url_or_path: str | Path) -> str:
    """A SQLAlchemy URL from a URL or a plain file path (-> SQLite file)."""
    text = str(url_or_path)
    if "://" in text:
        return text
    return f"sqlite:///{Path(text).expanduser().resolve()}"


def _engine(url: str) -> Engine:
    if not url.startswith("sqlite"):
        return create_engine(url, pool_pre_ping=True)
    in_memory = url in ("sqlite://", "sqlite:///:memory:")
    if not in_memory:
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(
        url,
        connect_args={"check_same_thread": False, "timeout": 10},
        poolclass=StaticPool if in_memory else None,
    )

    @event.listens_for(engine, "connect")
    def _sqlite_pragmas(connection: Any, _record: Any) -> None:
        cursor = connection.cursor()
        if not in_memory:
            cursor.execute("PRAGMA journal_mode=WAL")  # readers never wait for a writer
        cursor.execute("PRAGMA busy_timeout=10000")
        cursor.close()

    return engine


def create_tables(engine: Engine, metadata: MetaData = _metadata, attempts: int = 5) -> None:
    """Create the registry's tables (or those of `metadata`) unless they exist. Replicas starting
    together on a new database race to create them; the losers (IntegrityError or ProgrammingError
    on PostgreSQL) look again and find them made."""
    for attempt in range(attempts):
        try:
            metadata.create_all(engine)
            return
        except (IntegrityError, ProgrammingError):
            if attempt == attempts - 1:
                raise
            time.sleep(0.05 * (attempt + 1))


@dataclass(frozen=True)
class PutOutcome:
    """What a write did: the stored camera and whether it was new."""

    camera: FisheyeCamera
    created: bool


class CameraRegistry:
    """Cameras by id, stored in a SQLAlchemy database."""

    def __init__(self, url_or_path: str | Path) -> None:
        self.url = database_url(url_or_path)
        self.engine = _engine(self.url)
        create_tables(self.engine)
        self._cache: dict[str, tuple[str, FisheyeCamera]] = {}
        self._cache_lock = threading.Lock()

    def close(self) -> None:
        self.engine.dispose()

    # ----- reads

    def get(self, camera_id: str) -> FisheyeCamera | None:
        """The camera with this id as the database holds it now, or None."""
        with self.engine.connect() as connection:
            columns = select(cameras_table.c.record, cameras_table.c.revision)
            row = connection.execute(columns.where(cameras_table.c.id == camera_id)).first()
        if row is None:
            return None
        # Keyed by the stored record, not the revision: a camera deleted and made again through
        # another process starts again at revision 1.
        record = str(row[0])
        with self._cache_lock:
            cached = self._cache.get(camera_id)
        if cached is not None and cached[0] == record:
            return cached[1]
        camera = camera_from_dict(json.loads(record))
        with self._cache_lock:
            self._cache[camera_id] = (record, camera)
        return camera

    def all(self) -> list[FisheyeCamera]:
        """Every camera, by id."""
        with self.engine.connect() as connection:
            rows = connection.execute(select(cameras_table.c.record).order_by(cameras_table.c.id)).all()
        return [camera_from_dict(json.loads(str(row[0]))) for row in rows]

    def ids(self) -> list[str]:
        with self.engine.connect() as connection:
            rows = connection.execute(select(cameras_table.c.id).order_by(cameras_table.c.id)).all()
        return [str(row[0]) for row in rows]

    # ----- writes

    def put(self, camera: FisheyeCamera) -> PutOutcome:
        """Insert or replace a camera (validated already, being a FisheyeCamera)."""
        record = json.dumps(camera_to_dict(camera), sort_keys=True)
        with self.engine.begin() as connection:
            changed = connection.execute(
                update(cameras_table).where(cameras_table.c.id == camera.id)
                .values(record=record, revision=cameras_table.c.revision + 1)
            ).rowcount
            if changed:
                return PutOutcome(camera, created=False)
        try:
            with self.engine.begin() as connection:
                connection.execute(insert(cameras_table).values(id=camera.id, record=record, revision=1))
            return PutOutcome(camera, created=True)
        except IntegrityError:  # another writer inserted it between our update and insert
            return PutOutcome(self.put(camera).camera, created=False)

    def put_record(self, camera_id: str, record: Mapping[str, Any]) -> PutOutcome:
        """Validate a camera-file dict for `camera_id` and store it; CalibrationError if invalid."""
        body = dict(record)
        if "id" in body and body["id"] != camera_id:
            raise CalibrationError(
                f"invalid camera: id {body['id']!r} in the body differs from {camera_id!r}"
            )
        body["id"] = camera_id
        return self.put(camera_from_dict(body))

    def delete(self, camera_id: str) -> bool:
        """Remove a camera; False when there was none."""
        with self.engine.begin() as connection:
            statement = cameras_table.delete().where(cameras_table.c.id == camera_id)
            removed = connection.execute(statement).rowcount
        with self._cache_lock:
            self._cache.pop(camera_id, None)
        return bool(removed)

    # ----- seeding at start

    def seed(self, cameras: Iterable[FisheyeCamera], source: str) -> None:
        """Write cameras given at start (a camera file or folder): the file wins for the ids it names."""
        for camera in cameras:
            current = self.get(camera.id)
            if current == camera:
                continue
            self.put(camera)
            log.info("camera %s %s from %s", camera.id, "updated" if current else "added", source,
                     extra={"camera_id": camera.id})

    def seed_once(self, key: str, camera_path: str | Path) -> bool:
        """Add the camera of `camera_path` the first time this database is opened with `key`
        (so a deleted demo camera stays deleted); True when it was added now."""
        camera = load_camera(camera_path)  # a bad file fails before anything is recorded
        try:
            with self.engine.begin() as connection:
                query = select(registry_meta.c.value).where(registry_meta.c.key == key)
                done = connection.execute(query).first()
                if done is not None:
                    return False
                connection.execute(insert(registry_meta).values(key=key, value="seeded"))
        except IntegrityError:  # another process seeded it at the same moment
            return False
        if self.get(camera.id) is None:
            self.put(camera)
            log.info("camera %s added from %s", camera.id, camera_path, extra={"camera_id": camera.id})
            return True
        return False
