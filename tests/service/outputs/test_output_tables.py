"""The outputs' tables on SQLite (PostgreSQL: tests/deploy/test_deploy_outputs_postgres.py)."""

from __future__ import annotations

from pathlib import Path

from service.outputs.history import Bucket, Figure, HistoryStore
from service.outputs.webhooks import WebhookStore
from tests.service.outputs.output_tables_check import check_history, check_migration, check_outbox


def test_outputs_tables_on_sqlite(tmp_path: Path) -> None:
    registry = check_migration(str(tmp_path / "registry.db"))
    try:
        check_history(HistoryStore(registry.engine, retention_days=400))
        check_outbox(WebhookStore(registry.engine))
    finally:
        registry.close()


def test_history_keeps_only_the_retention_before_a_sites_newest_minute(tmp_path: Path) -> None:
    registry = check_migration(str(tmp_path / "registry.db"))
    store = HistoryStore(registry.engine, retention_days=1)
    hour = 1_764_612_000 - 1_764_612_000 % 3600
    try:
        for start in (hour - 3 * 86400, hour - 86400 + 60, hour):  # the last one, on the hour, prunes
            minute = Bucket(start)
            minute.figure("people", "").sample(1)
            store.add_minute("hall", minute)
            store.add_minute("other", Bucket(start - 10 * 86400, {("people", ""): Figure(1, 1, 1)}))
        rows = store.query("hall", hour - 5 * 86400, hour + 60, 3600)
        assert [row["time"] for row in rows] == [hour - 86400, hour]
        # Pruned on its own newest hour: the minute 13 days back goes, the days that hold the rest stay.
        assert [row["people_max"] for row in store.query("other", hour - 20 * 86400, hour, 86400)] == [1, 1]
        assert len(store.query("other", hour - 20 * 86400, hour, 3600)) == 2
    finally:
        registry.close()
