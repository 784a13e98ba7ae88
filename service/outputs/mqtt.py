"""MQTT out: each site's counts as retained topics, its events as messages, Home Assistant discovery.

Topics (prefix `fishloc` by default), retained: `<prefix>/<site>/count` (people now),
`<prefix>/<site>/zones/<zone>/count`, `<prefix>/<site>/lines/<line>` (`{"in": N, "out": M}`).
`<prefix>/<site>/events` gets one JSON message per line crossing and zone enter or leave;
`<prefix>/status` is `online` while the service is connected, `offline` (its last will) otherwise.
Home Assistant finds a sensor per site count, zone count and line direction from the retained
configs under `homeassistant/sensor/...`.

Publishing never waits on the broker: the sink keeps the newest value of every retained topic (sent
again whole after each reconnection) and a bounded queue of events; events that find the queue full
are dropped and counted (`fishloc_output_dropped_total{sink="mqtt"}`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
import ssl
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

from service.outputs.events import SiteUpdate
from service.outputs.sink import OutputMetrics, Sink, cancel

log = logging.getLogger(__name__)

EVENT_QUEUE_SIZE = 1024
_TOPIC_SAFE = re.compile(r"[^A-Za-z0-9_-]")


class MqttUrlError(ValueError):
    """An MQTT URL that is not `mqtt://[user:pass@]host[:port]` or `mqtts://...`."""


@dataclass(frozen=True)
class MqttConfig:
    """Where and how to publish."""

    host: str
    port: int = 1883
    tls: bool = False
    username: str | None = None
    password: str | None = None
    prefix: str = "fishloc"
    discovery_prefix: str = "homeassistant"
    ca_file: Path | None = None     # broker CA for mqtts:// (default: the system's)
    cert_file: Path | None = None   # client certificate, when the broker asks for one
    key_file: Path | None = None
    client_id: str = "fishloc"
    keepalive_s: int = 30

    @classmethod
    def from_url(cls, url: str, **options: Any) -> MqttConfig:
        parts = urlsplit(url)
        if parts.scheme not in ("mqtt", "mqtts") or not parts.hostname:
            raise MqttUrlError("the MQTT broker must be mqtt://[user:pass@]HOST[:PORT] or mqtts://...")
        try:
            port = parts.port or (8883 if parts.scheme == "mqtts" else 1883)
        except ValueError:
            raise MqttUrlError(f"the MQTT URL's port is not a port: {url!r}") from None
        username = unquote(parts.username) if parts.username else None
        password = unquote(parts.password) if parts.password else None
        return cls(parts.hostname, port, parts.scheme == "mqtts", username, password, **options)

    def tls_context(self) -> ssl.SSLContext | None:
        if not self.tls:
            return None
        context = ssl.create_default_context(cafile=str(self.ca_file) if self.ca_file else None)
        if self.cert_file is not None:
            context.load_cert_chain(str(self.cert_file), str(self.key_file) if self.key_file else None)
        return context


def object_id(*parts: str) -> str:
    """An id Home Assistant accepts ([A-Za-z0-9_-]) from site, zone and line ids."""
    return "_".join(_TOPIC_SAFE.sub("_", part) for part in parts)


class Topics:
    """The topic names and payloads of one configuration."""

    def __init__(self, config: MqttConfig) -> None:
        self.config = config
        self.status = f"{config.prefix}/status"

    def count(self, site: str) -> str:
        return f"{self.config.prefix}/{site}/count"

    def zone(self, site: str, zone: str) -> str:
        return f"{self.config.prefix}/{site}/zones/{zone}/count"

    def line(self, site: str, line: str) -> str:
        return f"{self.config.prefix}/{site}/lines/{line}"

    def events(self, site: str) -> str:
        return f"{self.config.prefix}/{site}/events"

    def discovery(self, unique_id: str) -> str:
        return f"{self.config.discovery_prefix}/sensor/{unique_id}/config"

    def sensors(self, site: str, zones: list[str], lines: list[str]) -> dict[str, dict[str, Any]]:
        """Home Assistant discovery configs (by their topic) of a site's sensors."""
        device = {"identifiers": [object_id("fishloc", site)], "name": f"FishLoc {site}",
                  "manufacturer": "FishLoc", "model": "overhead fisheye people counter"}
        common = {"availability_topic": self.status, "payload_available": "online",
                  "payload_not_available": "offline", "device": device, "icon": "mdi:account-group"}
        configs: dict[str, dict[str, Any]] = {}

        def add(unique_id: str, name: str, state_topic: str, state_class: str, template: str | None) -> None:
            config = {**common, "name": name, "unique_id": unique_id, "object_id": unique_id,
                      "state_topic": state_topic, "unit_of_measurement": "people",
                      "state_class": state_class}
            if template is not None:
                config["value_template"] = template
            configs[self.discovery(unique_id)] = config

        add(object_id("fishloc", site, "count"), f"{site} people", self.count(site), "measurement", None)
        for zone in zones:
            add(object_id("fishloc", site, "zone", zone, "count"), f"{zone} people", self.zone(site, zone),
                "measurement", None)
        for line in lines:
            for direction in ("in", "out"):
                add(object_id("fishloc", site, "line", line, direction), f"{line} {direction}",
                    self.line(site, line), "total_increasing", f"{{{{ value_json['{direction}'] }}}}")
        return configs


class MqttSink(Sink):
    """Publishes site updates to an MQTT broker (see the module docstring)."""

    name = "mqtt"

    def __init__(self, config: MqttConfig, metrics: OutputMetrics, retry_s: float = 1.0,
                 max_retry_s: float = 30.0) -> None:
        self.config = config
        self.topics = Topics(config)
        self.metrics = metrics
        self.retry_s, self.max_retry_s = retry_s, max_retry_s
        self._retained: dict[str, str] = {}   # newest payload of every retained topic ("" clears)
        self._dirty: dict[str, None] = {}     # retained topics changed since they were last sent
        self._events: asyncio.Queue[tuple[str, str]] = asyncio.Queue(maxsize=EVENT_QUEUE_SIZE)
        self._sites: dict[str, tuple[list[str], list[str]]] = {}
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self.connected = False
        self._client: Any = None
        self._error: str | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="mqtt")

    async def publish(self, update: SiteUpdate) -> None:
        site, occupancy = update.site, update.occupancy
        zones, lines = sorted(update.zones), sorted(update.lines)
        if self._sites.get(site) != (zones, lines):
            self._follow_layout(site, zones, lines)
        self._retain(self.topics.count(site), str(int(occupancy.get("count", 0))))
        for zone, count in update.zones.items():
            self._retain(self.topics.zone(site, zone), str(count))
        for line, tally in update.lines.items():
            self._retain(self.topics.line(site, line), json.dumps({"in": tally["in"], "out": tally["out"]}))
        for event in update.of_type("line_crossing", "zone_enter", "zone_leave"):
            if self._events.full():
                self.metrics.dropped.labels(self.name).inc()
                continue
            self._events.put_nowait((self.topics.events(site), json.dumps(event, separators=(",", ":"))))
        self._wake.set()

    def _follow_layout(self, site: str, zones: list[str], lines: list[str]) -> None:
        """Discovery configs for the site's sensors now; configs and topics of gone ones cleared."""
        old_zones, old_lines = self._sites.get(site, ([], []))
        old = self.topics.sensors(site, old_zones, old_lines)
        new = self.topics.sensors(site, zones, lines)
        for topic in old.keys() - new.keys():
            self._retain(topic, "")
        for zone in set(old_zones) - set(zones):
            self._retain(self.topics.zone(site, zone), "")
        for line in set(old_lines) - set(lines):
            self._retain(self.topics.line(site, line), "")
        for topic, config in new.items():
            self._retain(topic, json.dumps(config, sort_keys=True))
        self._sites[site] = (zones, lines)

    def _retain(self, topic: str, payload: str) -> None:
        if self._retained.get(topic) != payload:
            self._retained[topic] = payload
            self._dirty[topic] = None

    # ----- the connection

    async def _run(self) -> None:
        import aiomqtt  # only a service told to publish loads the client

        wait = self.retry_s
        config = self.config
        while True:
            will = aiomqtt.Will(self.topics.status, "offline", qos=1, retain=True)
            try:
                async with aiomqtt.Client(
                    config.host, config.port, username=config.username, password=config.password,
                    identifier=config.client_id, will=will, keepalive=config.keepalive_s,
                    tls_context=config.tls_context(), timeout=10,
                ) as client:
                    self._client = client
                    await client.publish(self.topics.status, "online", qos=1, retain=True)
                    self.connected, self._error, wait = True, None, self.retry_s
                    self._dirty = dict.fromkeys(self._retained)  # a new session: send everything again
                    log.info("MQTT connected to %s:%d", config.host, config.port)
                    await self._send_forever(client)
            except asyncio.CancelledError:
                raise
            except Exception as error:  # aiomqtt.MqttError, ssl and OS errors: retry with backoff
                if self.connected or self._error is None:
                    log.warning("MQTT broker %s:%d unreachable: %s", config.host, config.port, error)
                self.connected, self._client = False, None
                self._error = f"{type(error).__name__}: {error}"
                self.metrics.failures.labels(self.name).inc()
                await asyncio.sleep(wait)
                wait = min(wait * 2, self.max_retry_s)

    async def _send_forever(self, client: Any) -> None:
        while True:
            while self._dirty:
                topic = next(iter(self._dirty))
                payload = self._retained[topic]
                await client.publish(topic, payload, qos=1, retain=True)
                if self._retained.get(topic) == payload:  # unchanged while it was sent
                    self._dirty.pop(topic, None)
                self.metrics.delivered.labels(self.name).inc()
            while not self._events.empty():
                topic, payload = self._events.get_nowait()
                await client.publish(topic, payload, qos=1)
                self.metrics.delivered.labels(self.name).inc()
            if not self._dirty and self._events.empty():
                self._wake.clear()
                await self._wake.wait()

    @property
    def pending(self) -> int:
        """Retained topics and events not sent yet."""
        return len(self._dirty) + self._events.qsize()

    async def flushed(self) -> None:
        """Wait until everything published so far has gone to the broker."""
        while self.pending:
            await asyncio.sleep(0.05)

    async def close(self) -> None:
        """Send what is waiting, then `offline` (a clean disconnection sends no last will)."""
        if self.connected and self._client is not None:
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self.flushed(), 2.0)
                await asyncio.wait_for(self._client.publish(self.topics.status, "offline", qos=1,
                                                            retain=True), 2.0)
        await cancel(self._task)
        self._task = None

    def health(self) -> dict[str, Any]:
        answer: dict[str, Any] = {"ok": self.connected, "connected": self.connected,
                                  "broker": f"{self.config.host}:{self.config.port}"}
        if self._error is not None:
            answer["error"] = self._error
        return answer
