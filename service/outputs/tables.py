"""The outputs' tables in the registry's database, and the migration that adds them.

A registry made before the outputs existed holds only the camera and site tables; `migrate` creates
the tables below where they are missing (SQLAlchemy `create_all` never touches existing ones) and
records the schema version in `registry_meta`, so a later version knows what it finds.
"""

from __future__ import annotations

from sqlalchemy import (
    Column,
    Float,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    insert,
    select,
    update,
)
from sqlalchemy.engine import Engine
from sqlalchemy.exc import IntegrityError

from service.cameras import create_tables, registry_meta

SCHEMA_KEY = "outputs_schema"
SCHEMA_VERSION = "1"

metadata = MetaData()
# Webhooks of sites: one JSON record each (url, secret, events, zone_thresholds, summary_every_s).
webhooks_table = Table(
    "webhooks", metadata,
    Column("site", String(64), primary_key=True),
    Column("id", String(64), primary_key=True),
    Column("record", Text, nullable=False),
)
# The durable outbox: one row per event and webhook, kept until delivered (and a while after, as the
# webhook's delivery log).
outbox_table = Table(
    "webhook_outbox", metadata,
    Column("seq", Integer, primary_key=True, autoincrement=True),
    Column("site", String(64), nullable=False),
    Column("webhook", String(64), nullable=False),
    Column("event_id", String(64), nullable=False),
    Column("event_type", String(32), nullable=False),
    Column("body", Text, nullable=False),
    Column("created_at", Float, nullable=False),
    Column("attempts", Integer, nullable=False, default=0),
    Column("next_at", Float, nullable=False),
    Column("delivered_at", Float, nullable=True),
    Column("last_status", Integer, nullable=True),
    Column("last_error", Text, nullable=True),
    Index("ix_webhook_outbox_due", "delivered_at", "next_at"),
    Index("ix_webhook_outbox_hook", "site", "webhook", "seq"),
)
# Counts history: per site, resolution (60, 900, 3600 or 86400 s) and bucket start, one row per figure:
# kind `people` (key ""), `zone` (key: zone id), `line` (key: line id). People and zones keep the sum
# of their samples, the sample count and the peak; lines keep their crossings in (`total`) and out
# (`peak`) within the bucket.
history_table = Table(
    "history", metadata,
    Column("site", String(64), primary_key=True),
    Column("step_s", Integer, primary_key=True),
    Column("start", Integer, primary_key=True),
    Column("kind", String(8), primary_key=True),
    Column("key", String(64), primary_key=True),
    Column("total", Float, nullable=False),
    Column("peak", Float, nullable=False),
    Column("samples", Integer, nullable=False),
)


def migrate(engine: Engine) -> None:
    """Create the outputs' tables where missing and record the schema version."""
    create_tables(engine, metadata)
    with engine.begin() as connection:
        key = registry_meta.c.key == SCHEMA_KEY
        if connection.execute(select(registry_meta.c.value).where(key)).first() is None:
            try:
                with connection.begin_nested():
                    connection.execute(insert(registry_meta).values(key=SCHEMA_KEY, value=SCHEMA_VERSION))
            except IntegrityError:  # another replica recorded it at the same moment
                pass
        else:
            connection.execute(update(registry_meta).where(key).values(value=SCHEMA_VERSION))
