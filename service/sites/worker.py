"""The tracking role behind a sites bus (`fishloc sites --bus redis://…`): partitions of sites, leased.

Several workers share the `PARTITIONS` partition streams (`service.sites.bus`). Each live worker
announces itself (`worker:{id}`, a TTL key) and holds at most its share of the partitions, each by a
lease (`lease:{p}`: SET NX PX, renewed every `renew_s`; a dead worker's leases lapse after `lease_s`
and a live one takes them). It reads its partitions with a consumer group and applies each entry
(a frame's observation, or a camera or layout change notice) to its site's tracker, publishes the
site's occupancy (the `occupancy` hash, then the channel), then answers the frame's track ids on the
replica's reply stream.

Recovery: every `snapshot_every_s` (1 s) each partition with new entries is snapshotted (every tracker
changed since, `sites.snapshot`, and `position`: the last entry applied), through a script that
writes only while the lease is still this worker's, so a worker that lost its lease (a long pause)
can never overwrite its successor's state. Then, and only then, the entries are acknowledged and the
stream is trimmed to the position. A worker taking a partition over loads its snapshot and replays
the stream after `position` (answering the frames a replica may still wait for), then reads on: an entry
at or before the last one applied is acknowledged, never applied twice. The tracker is a function of
the entries in stream order, so the state after a kill -9 and a takeover is the state the dead worker
would have had: no track lost, no id changed, no crossing counted twice.

Any Redis error drops every partition (their leases may lapse meanwhile) and retries; taking them
again is the same recovery. Zones and lines come from the shared registry (`--database`), re-read
on a layout notice and at most `layout_refresh_s` after a change.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import os
import socket
import time
import uuid
from collections.abc import Callable
from typing import Any

import redis.exceptions

from service.core.metrics import ServiceMetrics
from service.sites import bus
from service.sites.bus_hub import BUS_ERRORS
from service.sites.hub import layout_key
from service.sites.interface import Listeners, Occupancy, OccupancyListener
from service.sites.store import SiteStore
from sites import SiteTracker, TrackerConfig
from sites.snapshot import observation_from_json, tracker_from_state, tracker_to_state

log = logging.getLogger(__name__)

# KEYS: lease, snapshot hash, stream. ARGV: worker id, position, then field/value pairs.
# Writes only while the lease is ours; trims the stream to the position it covers.
_SNAPSHOT_SCRIPT = """
if redis.call('GET', KEYS[1]) ~= ARGV[1] then return 0 end
local args = {'position', ARGV[2]}
for i = 3, #ARGV do args[#args + 1] = ARGV[i] end
redis.call('HSET', KEYS[2], unpack(args))
redis.call('XTRIM', KEYS[3], 'MINID', ARGV[2])
return 1
"""
# KEYS: lease. ARGV: worker id, lease ms. Renew (1), or 0 when the lease is no longer ours.
_RENEW_SCRIPT = """
if redis.call('GET', KEYS[1]) ~= ARGV[1] then return 0 end
redis.call('PEXPIRE', KEYS[1], ARGV[2])
return 1
"""
_RELEASE_SCRIPT = """
if redis.call('GET', KEYS[1]) == ARGV[1] then redis.call('DEL', KEYS[1]) end
return 1
"""
_ACK_CHUNK = 500


@dataclasses.dataclass(frozen=True)
class WorkerConfig:
    lease_s: float = 3.0           # a dead worker's partitions are taken over after at most this
    renew_s: float = 0.5           # leases and the worker's own key are renewed this often
    snapshot_every_s: float = 1.0  # a partition's trackers are snapshotted this often (when changed)
    batch: int = 128               # entries read at once
    block_ms: int = 100            # how long a read waits for entries
    layout_refresh_s: float = 1.0  # zones and lines re-read at most this long after a change
    partitions: int = bus.PARTITIONS


def _entry_key(entry_id: bytes | str) -> tuple[int, int]:
    text = entry_id.decode() if isinstance(entry_id, bytes) else entry_id
    ms, _, seq = text.partition("-")
    return int(ms), int(seq or 0)


@dataclasses.dataclass
class _Site:
    tracker: SiteTracker
    layout_read_at: float
    cameras: set[str] = dataclasses.field(default_factory=set)


@dataclasses.dataclass
class _Partition:
    number: int
    sites: dict[str, _Site] = dataclasses.field(default_factory=dict)
    position: str = "0-0"            # the last entry applied
    unacked: list[bytes] = dataclasses.field(default_factory=list)
    changed: set[str] = dataclasses.field(default_factory=set)   # sites to snapshot
    removed: set[str] = dataclasses.field(default_factory=set)   # sites whose snapshot to empty

    @property
    def stream(self) -> str:
        return bus.stream_key(self.number)


@dataclasses.dataclass
class _Outbox:
    """What one batch of entries publishes: occupancy updates in order, replies by reply stream."""

    updates: list[Occupancy] = dataclasses.field(default_factory=list)
    replies: dict[str, list[tuple[str, list[str | None]]]] = dataclasses.field(default_factory=dict)


class SitesWorker:
    """One `fishloc sites` process (see the module docstring)."""

    def __init__(self, redis: Any, store: SiteStore, metrics: ServiceMetrics,
                 config: WorkerConfig | None = None, tracker_config: TrackerConfig | None = None) -> None:
        self.redis = redis
        self.store = store
        self.metrics = metrics
        self.config = config or WorkerConfig()
        self.tracker_config = tracker_config or TrackerConfig()
        self.worker_id = f"{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:6]}"
        self._owned: dict[int, _Partition] = {}
        self._listeners = Listeners()
        self._renewed_at = -math.inf
        self._snapshot_at = time.monotonic()
        self._snapshot = redis.register_script(_SNAPSHOT_SCRIPT)
        self._renew = redis.register_script(_RENEW_SCRIPT)
        self._release = redis.register_script(_RELEASE_SCRIPT)

    @property
    def partitions(self) -> list[int]:
        return sorted(self._owned)

    def listen(self, listener: OccupancyListener) -> Callable[[], None]:
        """Call `listener(update)` after every occupancy update this worker makes (not replays)."""
        return self._listeners.add(listener)

    # ----- the loop

    async def run(self, stop: asyncio.Event) -> None:
        """Track until `stop` is set; then snapshot, release the leases and leave."""
        log.info("sites worker %s started", self.worker_id)
        failing = False
        while not stop.is_set():
            try:
                await self.step()
                if failing:
                    log.info("sites bus reachable again")
                failing = False
            except BUS_ERRORS as error:
                if not failing:
                    log.warning("sites bus unreachable (%s): partitions dropped, retrying", error)
                failing = True
                self._drop_all()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(stop.wait(), 0.5)
        with contextlib.suppress(*BUS_ERRORS, TimeoutError):  # a Redis that is away cannot hold us
            await asyncio.wait_for(self.leave(), 2 * self.config.lease_s)

    async def step(self) -> None:
        """One round: leases when due, one read of the owned partitions, snapshots when due."""
        if time.monotonic() - self._renewed_at >= self.config.renew_s:
            await self._keep_leases()
        if not self._owned:
            await asyncio.sleep(self.config.block_ms / 1000)
            return
        streams = {p.stream: ">" for p in self._owned.values()}
        # COUNT is per stream: the batch is shared, so one step stays far shorter than a lease.
        count = max(1, self.config.batch // len(streams))
        batches = await self.redis.xreadgroup(bus.GROUP, self.worker_id, streams, count=count,
                                              block=self.config.block_ms)
        outbox = _Outbox()
        for stream, entries in batches or []:
            partition = self._owned.get(int(stream.decode().rsplit(":", 1)[1]))
            if partition is None:
                continue
            for entry_id, fields in entries:
                self._apply(partition, entry_id, fields, outbox, live=True)
        await self._publish(outbox)
        if time.monotonic() - self._snapshot_at >= self.config.snapshot_every_s:
            await self.snapshot_all()

    async def leave(self) -> None:
        """Snapshot and release every partition (a graceful stop: a successor starts at once)."""
        for number in list(self._owned):
            await self._give_up(number)
        await self.redis.delete(bus.worker_key(self.worker_id))

    # ----- leases

    async def _renew_leases(self, taking: int | None = None) -> bool:
        """Renew this worker's key and the leases it holds (and that of the partition it is taking
        over); drop the partitions whose lease lapsed. Whether `taking`'s lease is still held."""
        self._renewed_at = time.monotonic()
        lease_ms = int(self.config.lease_s * 1000)
        await self.redis.set(bus.worker_key(self.worker_id), "1", px=lease_ms)
        held = True
        for number in [*self._owned, *([] if taking is None else [taking])]:
            if not await self._renew(keys=[bus.lease_key(number)], args=[self.worker_id, lease_ms]):
                log.warning("lease of partition %d lost: dropping it", number)
                self._drop(number)
                held = held and number != taking
        return held

    async def _keep_leases(self) -> None:
        await self._renew_leases()
        lease_ms = int(self.config.lease_s * 1000)
        workers = [key async for key in self.redis.scan_iter(match=bus.worker_key("*"), count=100)]
        share = math.ceil(self.config.partitions / max(len(workers), 1))
        if len(self._owned) > share:  # a worker joined: hand one partition over per round
            await self._give_up(max(self._owned))
            return
        for number in range(self.config.partitions):
            if len(self._owned) >= share:
                break
            if number in self._owned:
                continue
            if await self.redis.set(bus.lease_key(number), self.worker_id, nx=True, px=lease_ms):
                await self._take_over(number)

    async def _give_up(self, number: int) -> None:
        partition = self._owned.get(number)
        if partition is not None:
            await self._snapshot_partition(partition)
        await self._release(keys=[bus.lease_key(number)], args=[self.worker_id])
        self._drop(number)
        log.info("partition %d handed over", number)

    def _drop(self, number: int) -> None:
        """Forget a partition (its successor reports its sites' figures from now on)."""
        partition = self._owned.pop(number, None)
        for site_id in [] if partition is None else partition.sites:
            self.metrics.forget_site(site_id)
        self.metrics.bus_partitions.set(len(self._owned))

    def _drop_all(self) -> None:
        for number in list(self._owned):
            self._drop(number)
        self._renewed_at = -math.inf

    async def _take_over(self, number: int) -> None:
        """Load partition `number`'s snapshot and replay its stream after the snapshot's position."""
        partition = _Partition(number)
        with contextlib.suppress(redis.exceptions.ResponseError):  # BUSYGROUP: it exists
            await self.redis.xgroup_create(partition.stream, bus.GROUP, id="0", mkstream=True)
        snapshot = await self.redis.hgetall(bus.snapshot_key(number))
        partition.position = snapshot.pop(b"position", b"0-0").decode()
        for field, value in snapshot.items():
            if value:
                site_id = field.decode().removeprefix("site:")
                layout = await asyncio.to_thread(self.store.layout, site_id)
                saved = json.loads(value)
                tracker = tracker_from_state(saved["tracker"], self.tracker_config, layout)
                partition.sites[site_id] = _Site(tracker, time.monotonic(), set(saved["cameras"]))
        replayed = 0
        outbox = _Outbox()
        while True:
            entries = await self.redis.xrange(partition.stream, min=f"({partition.position}", max="+",
                                              count=self.config.batch)
            if not entries:
                break
            # A long replay keeps the leases (this one's too) alive as it goes.
            due = time.monotonic() - self._renewed_at >= self.config.renew_s
            if due and not await self._renew_leases(number):
                return
            for entry_id, fields in entries:
                self._apply(partition, entry_id, fields, outbox, live=False)
            replayed += len(entries)
        # Readers need the state now, not each step of the replay; a replica still waiting for one of
        # the replayed frames gets its answer.
        latest = {update["site"]: update for update in outbox.updates}
        await self._publish(_Outbox(list(latest.values()), outbox.replies))
        self._owned[number] = partition
        self.metrics.bus_partitions.set(len(self._owned))
        log.info("partition %d taken over: %d sites from the snapshot at %s, %d entries replayed", number,
                 len(snapshot), partition.position, replayed)

    # ----- entries

    def _apply(self, partition: _Partition, entry_id: bytes, fields: dict[bytes, bytes], outbox: _Outbox,
               live: bool) -> None:
        partition.unacked.append(entry_id)
        if _entry_key(entry_id) <= _entry_key(partition.position):
            return  # replayed already
        partition.position = entry_id.decode()
        self.metrics.bus_entries.labels(how="live" if live else "replayed").inc()
        kind = fields.get(b"kind", b"").decode()
        try:
            if kind == "obs":
                self._apply_observation(partition, fields, outbox, live)
            elif kind == "camera":
                self._apply_camera(partition, fields[b"camera"].decode(), fields[b"site"].decode(), outbox)
            elif kind == "layout":
                site = partition.sites.get(fields[b"site"].decode())
                if site is not None:
                    site.layout_read_at = -math.inf
        except (KeyError, ValueError) as error:  # an entry this version cannot read is skipped, not fatal
            log.warning("bus entry %s of partition %d skipped: %r", entry_id, partition.number, error)

    def _site(self, partition: _Partition, site_id: str) -> _Site:
        site = partition.sites.get(site_id)
        if site is None:
            tracker = SiteTracker(site_id, self.tracker_config, self.store.layout(site_id))
            site = _Site(tracker, time.monotonic())
            partition.sites[site_id] = site
        elif time.monotonic() - site.layout_read_at >= self.config.layout_refresh_s:
            site.layout_read_at = time.monotonic()
            layout = self.store.layout(site_id)
            if layout_key(layout) != layout_key(site.tracker.layout):
                site.tracker.set_layout(layout)
                self.metrics.follow_layout(site_id, layout)
        return site

    def _apply_observation(self, partition: _Partition, fields: dict[bytes, bytes], outbox: _Outbox,
                           live: bool) -> None:
        site_id = fields[b"site"].decode()
        observation = observation_from_json(fields[b"obs"])
        site = self._site(partition, site_id)
        started = time.perf_counter()
        site.cameras.add(observation.camera_id)
        before = site.tracker.line_totals()
        outcome = site.tracker.update(observation)
        partition.changed.add(site_id)
        occupancy = site.tracker.occupancy() if outcome.use != "dropped_late" else None
        self.metrics.observe_site(site_id, outcome.use, before, site.tracker.line_totals(), occupancy,
                                  time.perf_counter() - started)
        if occupancy is not None:
            outbox.updates.append(occupancy)
        if b"reply" in fields:
            outbox.replies.setdefault(fields[b"reply"].decode(), []).append(
                (fields[b"rid"].decode(), list(outcome.track_ids)))

    def _apply_camera(self, partition: _Partition, camera_id: str, new_site: str, outbox: _Outbox) -> None:
        """A camera was written or deleted: the sites of this partition it left end its tracks; a
        site no camera names any more is forgotten."""
        named = None
        for site_id, site in list(partition.sites.items()):
            if camera_id not in site.cameras or site_id == new_site:
                continue
            ended = site.tracker.remove_camera(camera_id)
            site.cameras.discard(camera_id)
            log.info("camera %s left site %s: %d tracks ended", camera_id, site_id, ended)
            named = self.store.site_cameras() if named is None else named
            if site_id in named:
                partition.changed.add(site_id)
                outbox.updates.append(site.tracker.occupancy())
            else:
                del partition.sites[site_id]
                partition.removed.add(site_id)
                partition.changed.discard(site_id)
                outbox.updates.append({"site": site_id, "closed": True})
                self.metrics.forget_site(site_id)

    async def _publish(self, outbox: _Outbox) -> None:
        """Occupancy first (hash, then channel), then the replies: a replica answered its frame only
        once every replica can read the state holding it."""
        if not outbox.updates and not outbox.replies:
            return
        texts = [json.dumps(update, separators=(",", ":")) for update in outbox.updates]
        latest: dict[str, tuple[Occupancy, str]] = {}
        for update, text in zip(outbox.updates, texts, strict=True):
            latest[update["site"]] = (update, text)
        async with self.redis.pipeline(transaction=False) as pipe:
            for site_id, (update, text) in latest.items():
                if update.get("closed"):
                    pipe.hdel(bus.OCCUPANCY, site_id)
                else:
                    pipe.hset(bus.OCCUPANCY, site_id, text)
            for text in texts:
                pipe.publish(bus.OCCUPANCY, text)
            for reply_stream, answers in outbox.replies.items():
                for request_id, track_ids in answers:
                    pipe.xadd(reply_stream, {"rid": request_id, "ids": json.dumps(track_ids)},
                              maxlen=bus.REPLY_MAXLEN, approximate=True)
                pipe.expire(reply_stream, bus.REPLY_TTL_S)
            await pipe.execute()
        for update in outbox.updates:
            if not update.get("closed"):
                self._listeners.notify(update)

    # ----- snapshots

    async def snapshot_all(self) -> None:
        self._snapshot_at = time.monotonic()
        for partition in list(self._owned.values()):
            await self._snapshot_partition(partition)

    async def _snapshot_partition(self, partition: _Partition) -> None:
        if not partition.unacked and not partition.changed and not partition.removed:
            return
        values: list[str] = []
        for site_id in sorted(partition.changed):
            site = partition.sites[site_id]
            saved = {"cameras": sorted(site.cameras), "tracker": tracker_to_state(site.tracker)}
            values += [f"site:{site_id}", json.dumps(saved, separators=(",", ":"))]
        for site_id in sorted(partition.removed):
            values += [f"site:{site_id}", ""]
        keys = [bus.lease_key(partition.number), bus.snapshot_key(partition.number), partition.stream]
        written = await self._snapshot(keys=keys, args=[self.worker_id, partition.position, *values])
        if not written:
            log.warning("partition %d: lease lost before its snapshot; dropping it", partition.number)
            self._drop(partition.number)
            return
        acks, partition.unacked = partition.unacked, []
        for start in range(0, len(acks), _ACK_CHUNK):
            await self.redis.xack(partition.stream, bus.GROUP, *acks[start:start + _ACK_CHUNK])
        partition.changed.clear()
        partition.removed.clear()
