"""The outputs' tables (history, webhooks and their outbox) on a real PostgreSQL server, migrated
into a registry made before them."""

from __future__ import annotations

from service.outputs.history import HistoryStore
from service.outputs.webhooks import WebhookStore
from tests.service.outputs.output_tables_check import check_history, check_migration, check_outbox


def test_outputs_tables_on_postgres(postgres_url: str) -> None:
    registry = check_migration(postgres_url)
    try:
        check_history(HistoryStore(registry.engine, retention_days=400))
        check_outbox(WebhookStore(registry.engine))
    finally:
        registry.close()
