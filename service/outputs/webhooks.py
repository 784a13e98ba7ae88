"""Webhooks of sites: signed JSON posts of a site's events, kept in a durable outbox until delivered.

A webhook (`PUT /v1/sites/{site}/webhooks/{id}`) names a URL, a secret and the events it wants:
`line_crossing` (each crossing of a counting line), `zone_threshold` (a zone's count reaching one of
its `zone_thresholds` from below, `up`, or falling under it, `down`) and `summary` (the site's counts
every `summary_every_s` of capture time). Each event is written to the `webhook_outbox` table of
the registry's database before anything is sent; the delivery loop posts due rows, signed
`X-FishLoc-Signature: sha256=<hex HMAC-SHA256 of the body with the secret>`, and retries errors and
timeouts with a doubling backoff, for at most a day. A restart finds the rows still pending and
sends them: delivery is at least once, and a receiver dedupes by the body's `id`.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
import json
import logging
import time
from dataclasses import dataclass
from typing import Any, Literal

import httpx
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from sqlalchemy import delete, func, insert, select, update
from sqlalchemy.engine import Engine

from service.outputs.events import SiteUpdate, summary_event, threshold_crossings
from service.outputs.sink import OutputMetrics, Sink, cancel
from service.outputs.tables import outbox_table as outbox
from service.outputs.tables import webhooks_table as hooks
from sites.layout import NAME_PATTERN

log = logging.getLogger(__name__)

EVENT_TYPES = ("line_crossing", "zone_threshold", "summary")
MAX_WEBHOOKS_PER_SITE = 16
SIGNATURE_HEADER = "X-FishLoc-Signature"


class WebhookError(ValueError):
    """An invalid webhook body; the message says what is wrong."""


class WebhookSpec(BaseModel):
    """A webhook as its PUT body gives it."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    url: str = Field(max_length=2048)
    secret: str = Field(min_length=8, max_length=256)
    events: list[Literal["line_crossing", "zone_threshold", "summary"]] = Field(min_length=1)
    zone_thresholds: dict[str, int] = Field(default_factory=dict)
    summary_every_s: float = Field(60.0, ge=1.0, le=86_400.0)

    @field_validator("url")
    @classmethod
    def _http_url(cls, value: str) -> str:
        try:
            url = httpx.URL(value)
        except (httpx.InvalidURL, TypeError) as error:
            raise ValueError(f"not a URL: {error}") from None
        if url.scheme not in ("http", "https") or not url.host:
            raise ValueError("the url must be http:// or https:// with a host")
        return value

    @field_validator("zone_thresholds")
    @classmethod
    def _thresholds(cls, value: dict[str, int]) -> dict[str, int]:
        import re

        for zone, threshold in value.items():
            if not re.fullmatch(NAME_PATTERN, zone):
                raise ValueError(f"zone id {zone!r} is not a valid id")
            if not 1 <= threshold <= 100_000:
                raise ValueError(f"threshold of zone {zone!r} must be a whole number from 1 to 100000")
        return value

    @model_validator(mode="after")
    def _thresholds_with_their_event(self) -> WebhookSpec:
        if "zone_threshold" in self.events and not self.zone_thresholds:
            raise ValueError("the zone_threshold event needs zone_thresholds, e.g. {\"entrance\": 5}")
        return self

    def public(self) -> dict[str, Any]:
        """The webhook as GET shows it (the secret never leaves)."""
        return {**self.model_dump(exclude={"secret"}), "secret": "(set)"}


def webhook_from_body(body: dict[str, Any]) -> WebhookSpec:
    try:
        return WebhookSpec.model_validate(body, strict=False)
    except ValidationError as error:
        problems = "; ".join(f"{'.'.join(str(p) for p in e['loc']) or 'body'}: {e['msg']}"
                             for e in error.errors())
        raise WebhookError(f"invalid webhook: {problems}") from None


def sign(secret: str, body: bytes) -> str:
    """The signature header's value for a body."""
    return "sha256=" + hmac.new(secret.encode("utf-8"), body, hashlib.sha256).hexdigest()


@dataclass(frozen=True)
class DeliveryConfig:
    """How the outbox is delivered."""

    timeout_s: float = 5.0        # a receiver slower than this is a failed attempt
    first_backoff_s: float = 1.0  # the wait after a first failure, doubling with each next one...
    max_backoff_s: float = 60.0   # ...up to this
    poll_s: float = 0.5           # how often the outbox is looked at when idle
    batch: int = 64               # rows taken per look
    keep_delivered: int = 50      # delivered rows kept per webhook, as its delivery log
    max_age_s: float = 86_400.0   # an event still undelivered this long after it happened is given up


class WebhookStore:
    """Webhooks and their outbox in the registry's database (synchronous)."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine

    # ----- webhooks

    def put(self, site: str, webhook_id: str, spec: WebhookSpec) -> bool:
        """Store a webhook; True when it is new."""
        record = spec.model_dump_json()
        key = (hooks.c.site == site) & (hooks.c.id == webhook_id)
        with self.engine.begin() as connection:
            if connection.execute(update(hooks).where(key).values(record=record)).rowcount:
                return False
            count = connection.execute(select(func.count()).where(hooks.c.site == site)).scalar_one()
            if count >= MAX_WEBHOOKS_PER_SITE:
                raise WebhookError(f"site {site!r} has {count} webhooks already; at most "
                                   f"{MAX_WEBHOOKS_PER_SITE}")
            connection.execute(insert(hooks).values(site=site, id=webhook_id, record=record))
        return True

    def get(self, site: str, webhook_id: str) -> WebhookSpec | None:
        with self.engine.connect() as connection:
            row = connection.execute(select(hooks.c.record).where(
                (hooks.c.site == site) & (hooks.c.id == webhook_id))).first()
        return None if row is None else WebhookSpec.model_validate_json(str(row[0]))

    def of_site(self, site: str) -> dict[str, WebhookSpec]:
        with self.engine.connect() as connection:
            rows = connection.execute(select(hooks.c.id, hooks.c.record).where(hooks.c.site == site)).all()
        return {str(row[0]): WebhookSpec.model_validate_json(str(row[1])) for row in rows}

    def delete(self, site: str, webhook_id: str) -> bool:
        """Remove a webhook and what its outbox still held."""
        with self.engine.begin() as connection:
            mine = (outbox.c.site == site) & (outbox.c.webhook == webhook_id)
            connection.execute(delete(outbox).where(mine))
            return bool(connection.execute(delete(hooks).where(
                (hooks.c.site == site) & (hooks.c.id == webhook_id))).rowcount)

    # ----- outbox

    def enqueue(self, rows: list[dict[str, Any]]) -> None:
        """Outbox rows (site, webhook, event_id, event_type, body) due now."""
        now = time.time()
        with self.engine.begin() as connection:
            connection.execute(insert(outbox), [{**row, "created_at": now, "attempts": 0, "next_at": now}
                                                for row in rows])

    def claim_due(self, limit: int, lease_s: float) -> list[tuple[int, str, str, str]]:
        """Due rows (seq, site, webhook, body), each leased for `lease_s` to this process (another
        process delivering the same outbox skips them)."""
        now = time.time()
        with self.engine.begin() as connection:
            rows = connection.execute(
                select(outbox.c.seq, outbox.c.site, outbox.c.webhook, outbox.c.body, outbox.c.next_at)
                .where(outbox.c.delivered_at.is_(None) & (outbox.c.next_at <= now))
                .order_by(outbox.c.seq).limit(limit)).all()
            claimed = []
            for seq, site, webhook, body, next_at in rows:
                taken = connection.execute(update(outbox).where(
                    (outbox.c.seq == seq) & (outbox.c.next_at == next_at)).values(next_at=now + lease_s))
                if taken.rowcount:
                    claimed.append((int(seq), str(site), str(webhook), str(body)))
        return claimed

    def delivered(self, seq: int, status: int, keep: int) -> None:
        with self.engine.begin() as connection:
            connection.execute(update(outbox).where(outbox.c.seq == seq).values(
                delivered_at=time.time(), last_status=status, attempts=outbox.c.attempts + 1))
            site, webhook = connection.execute(
                select(outbox.c.site, outbox.c.webhook).where(outbox.c.seq == seq)).one()
            old = connection.execute(
                select(outbox.c.seq).where((outbox.c.site == site) & (outbox.c.webhook == webhook)
                                           & outbox.c.delivered_at.is_not(None))
                .order_by(outbox.c.seq.desc()).offset(keep).limit(1)).first()
            if old is not None:
                connection.execute(delete(outbox).where(
                    (outbox.c.site == site) & (outbox.c.webhook == webhook)
                    & outbox.c.delivered_at.is_not(None) & (outbox.c.seq <= old[0])))

    def failed(self, seq: int, status: int | None, error: str, config: DeliveryConfig) -> bool:
        """Count a failed attempt and set the next one; False when the event is given up (deleted:
        older than `max_age_s`), or gone with its webhook."""
        with self.engine.begin() as connection:
            row = connection.execute(
                select(outbox.c.attempts, outbox.c.created_at).where(outbox.c.seq == seq)).first()
            if row is None:  # the webhook was deleted meanwhile
                return False
            attempts, created_at = row
            if time.time() - float(created_at) > config.max_age_s:
                connection.execute(delete(outbox).where(outbox.c.seq == seq))
                return False
            wait = min(config.first_backoff_s * 2 ** int(attempts), config.max_backoff_s)
            connection.execute(update(outbox).where(outbox.c.seq == seq).values(
                attempts=outbox.c.attempts + 1, next_at=time.time() + wait, last_status=status,
                last_error=error[:500]))
        return True

    def drop(self, seq: int) -> None:
        with self.engine.begin() as connection:
            connection.execute(delete(outbox).where(outbox.c.seq == seq))

    def log(self, site: str, webhook_id: str, limit: int = 20) -> dict[str, Any]:
        """The webhook's newest outbox rows, pending count and failed-attempt count."""
        key = (outbox.c.site == site) & (outbox.c.webhook == webhook_id)
        with self.engine.connect() as connection:
            rows = connection.execute(
                select(outbox.c.event_id, outbox.c.event_type, outbox.c.created_at, outbox.c.attempts,
                       outbox.c.delivered_at, outbox.c.last_status, outbox.c.last_error, outbox.c.next_at)
                .where(key).order_by(outbox.c.seq.desc()).limit(limit)).all()
            pending = connection.execute(
                select(func.count()).where(key & outbox.c.delivered_at.is_(None))).scalar_one()
        deliveries = [{"id": r[0], "type": r[1], "created_at": r[2], "attempts": r[3], "delivered_at": r[4],
                       "last_status": r[5], "last_error": r[6],
                       "next_attempt_at": None if r[4] is not None else r[7]} for r in rows]
        failures = [d for d in deliveries if d["last_error"] is not None or (d["attempts"] or 0) > 1]
        return {"pending": int(pending), "deliveries": deliveries, "failures": failures}


class WebhookSink(Sink):
    """Puts each site update's events for its webhooks in the outbox and delivers the outbox."""

    name = "webhooks"

    def __init__(self, store: WebhookStore, metrics: OutputMetrics,
                 config: DeliveryConfig | None = None, refresh_s: float = 1.0) -> None:
        self.store = store
        self.metrics = metrics
        self.config = config or DeliveryConfig()
        self.refresh_s = refresh_s
        self._hooks: dict[str, tuple[float, dict[str, WebhookSpec]]] = {}
        self._last_summary: dict[tuple[str, str], float] = {}
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._last_error: str | None = None
        self._failing: set[str] = set()

    def changed(self, site: str) -> None:
        """A webhook of the site was written or deleted through this process."""
        self._hooks.pop(site, None)

    async def start(self) -> None:
        self._task = asyncio.create_task(self._deliver_forever(), name="webhook-delivery")

    async def publish(self, update: SiteUpdate) -> None:
        hooks_now = await self._site_hooks(update.site)
        rows = []
        for webhook_id, spec in hooks_now.items():
            for event in self._events_for(update, webhook_id, spec):
                rows.append({"site": update.site, "webhook": webhook_id, "event_id": event["id"],
                             "event_type": event["type"],
                             "body": json.dumps(event, separators=(",", ":"), sort_keys=True)})
        if rows:
            await asyncio.to_thread(self.store.enqueue, rows)
            self._wake.set()

    def _events_for(self, update: SiteUpdate, webhook_id: str, spec: WebhookSpec) -> list[dict[str, Any]]:
        events: list[dict[str, Any]] = []
        if "line_crossing" in spec.events:
            events += update.of_type("line_crossing")
        if "zone_threshold" in spec.events:
            events += threshold_crossings(update, spec.zone_thresholds)
        if "summary" in spec.events:
            key = (update.site, webhook_id)
            last = self._last_summary.setdefault(key, update.time)
            if update.time - last >= spec.summary_every_s:
                self._last_summary[key] = update.time
                events.append(summary_event(update))
        return events

    async def _site_hooks(self, site: str) -> dict[str, WebhookSpec]:
        cached = self._hooks.get(site)
        if cached is not None and time.monotonic() - cached[0] < self.refresh_s:
            return cached[1]
        found = await asyncio.to_thread(self.store.of_site, site)
        self._hooks[site] = (time.monotonic(), found)
        return found

    # ----- delivery

    async def _deliver_forever(self) -> None:
        async with httpx.AsyncClient(timeout=self.config.timeout_s) as client:
            while True:
                try:
                    sent = await self.deliver_due(client)
                except Exception as error:  # the database is away: try again later
                    self._last_error = f"outbox: {type(error).__name__}: {error}"
                    log.warning("webhook outbox unreadable: %s", error)
                    sent = 0
                if not sent:
                    self._wake.clear()
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(self._wake.wait(), self.config.poll_s)

    async def deliver_due(self, client: httpx.AsyncClient) -> int:
        """Post every due outbox row once; the number of rows tried."""
        lease_s = self.config.timeout_s + 5.0
        due = await asyncio.to_thread(self.store.claim_due, self.config.batch, lease_s)
        specs: dict[tuple[str, str], WebhookSpec | None] = {}
        for seq, site, webhook_id, body in due:
            if (site, webhook_id) not in specs:
                specs[site, webhook_id] = await asyncio.to_thread(self.store.get, site, webhook_id)
            spec = specs[site, webhook_id]
            if spec is None:
                await asyncio.to_thread(self.store.drop, seq)
                continue
            await self._post(client, seq, f"{site}/{webhook_id}", spec, body.encode("utf-8"))
        return len(due)

    async def _post(self, client: httpx.AsyncClient, seq: int, name: str, spec: WebhookSpec,
                    body: bytes) -> None:
        headers = {"Content-Type": "application/json", SIGNATURE_HEADER: sign(spec.secret, body),
                   "User-Agent": "fishloc-webhooks"}
        status: int | None = None
        try:
            response = await client.post(spec.url, content=body, headers=headers)
            status = response.status_code
            if 200 <= status < 300:
                await asyncio.to_thread(self.store.delivered, seq, status, self.config.keep_delivered)
                self.metrics.delivered.labels(self.name).inc()
                self._failing.discard(name)
                return
            error = f"HTTP {status}"
        except httpx.HTTPError as failure:
            error = f"{type(failure).__name__}: {failure}" if str(failure) else type(failure).__name__
        self.metrics.failures.labels(self.name).inc()
        self._failing.add(name)
        self._last_error = f"{name}: {error}"
        if not await asyncio.to_thread(self.store.failed, seq, status, error, self.config):
            self.metrics.dropped.labels(self.name).inc()

    async def close(self) -> None:
        await cancel(self._task)
        self._task = None

    def health(self) -> dict[str, Any]:
        answer: dict[str, Any] = {"ok": not self._failing}
        if self._failing:
            answer["failing"] = sorted(self._failing)
        if self._last_error is not None:
            answer["last_error"] = self._last_error
        return answer
