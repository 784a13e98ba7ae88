"""The outputs' tables on any database (SQLite here, PostgreSQL in tests/deploy): a registry made
before them is migrated, the history adds and rolls up, the outbox leases and logs."""

from __future__ import annotations

from sqlalchemy import inspect, select

from fisheye import load_camera
from models import DEMO_CAMERA_PATH
from service.cameras import CameraRegistry, registry_meta
from service.outputs.history import Bucket, Figure, HistoryStore
from service.outputs.tables import SCHEMA_KEY, SCHEMA_VERSION, migrate
from service.outputs.webhooks import DeliveryConfig, WebhookSpec, WebhookStore

T0 = 1_764_612_000  # a whole day (UTC midnight + 18 h is fine: only minutes matter)


def check_migration(url: str) -> CameraRegistry:
    registry = CameraRegistry(url)  # the registry as it was before the outputs
    registry.put(load_camera(DEMO_CAMERA_PATH))
    assert "history" not in inspect(registry.engine).get_table_names()
    migrate(registry.engine)
    migrate(registry.engine)  # again: nothing changes
    tables = set(inspect(registry.engine).get_table_names())
    assert {"webhooks", "webhook_outbox", "history", "cameras", "site_zones"} <= tables
    assert registry.ids() == ["demo"]
    with registry.engine.connect() as connection:
        version = connection.execute(select(registry_meta.c.value).where(registry_meta.c.key == SCHEMA_KEY))
        assert version.scalar_one() == SCHEMA_VERSION
    return registry


def check_history(store: HistoryStore) -> None:
    for k, people in enumerate([1, 3, 2, 0]):  # four minutes, the first three in one hour
        minute = Bucket(T0 - T0 % 60 + 60 * k)
        for value in (people, people + 1):
            minute.figure("people", "").sample(value)
            minute.figure("zone", "entrance").sample(value)
        minute.figures[("line", "door")] = Figure(total=k, peak=1)
        store.add_minute("hall", minute)
    store.add_minute("hall", Bucket(T0 - T0 % 60, {("line", "door"): Figure(total=5, peak=0)}))  # a 2nd part
    rows = store.query("hall", T0 - 3600, T0 + 3600, 60)
    assert [row["people_max"] for row in rows] == [2, 4, 3, 1]
    assert [row["people_mean"] for row in rows] == [1.5, 3.5, 2.5, 0.5]
    assert [row["lines"]["door"] for row in rows] == [{"in": 5, "out": 1}, {"in": 1, "out": 1},
                                                      {"in": 2, "out": 1}, {"in": 3, "out": 1}]
    day = store.query("hall", T0 - 86400, T0 + 86400, 86400)
    assert len(day) == 1 and day[0]["lines"]["door"] == {"in": 11, "out": 4}
    assert day[0]["people_max"] == 4 and day[0]["people_mean"] == 2.0
    assert day[0]["zones"]["entrance"] == {"mean": 2.0, "max": 4}
    assert store.query("other", T0 - 86400, T0 + 86400, 86400) == []


def check_outbox(store: WebhookStore) -> None:
    spec = WebhookSpec(url="http://127.0.0.1:9/", secret="s3cret-key", events=["line_crossing"])
    assert store.put("hall", "hook", spec) and not store.put("hall", "hook", spec)
    store.enqueue([{"site": "hall", "webhook": "hook", "event_id": f"e{k}", "event_type": "line_crossing",
                    "body": "{}"} for k in range(3)])
    claimed = store.claim_due(10, lease_s=60)
    assert [row[0] for row in claimed] == sorted(row[0] for row in claimed) and len(claimed) == 3
    assert store.claim_due(10, lease_s=60) == []  # leased: another deliverer skips them
    store.delivered(claimed[0][0], 200, keep=50)
    assert store.failed(claimed[1][0], 503, "HTTP 503", DeliveryConfig())
    log = store.log("hall", "hook")
    assert log["pending"] == 2 and [d["id"] for d in log["failures"]] == ["e1"]
    assert not store.failed(claimed[2][0], None, "ConnectError", DeliveryConfig(max_age_s=-1.0))  # given up
    assert store.log("hall", "hook")["pending"] == 1
    assert store.delete("hall", "hook") and store.log("hall", "hook")["deliveries"] == []
