"""The sites bus: what detection replicas and `fishloc sites` workers share in Redis, and its names.

Keys (every one under the prefix `fishloc:`):

| key | type | written by | what |
|---|---|---|---|
| `obs:{p}` | stream | replicas | partition p's entries: a frame's observation of a site, or a change notice |
| `lease:{p}` | string, TTL | workers | the worker that owns partition p (SET NX PX, renewed) |
| `worker:{id}` | string, TTL | workers | a live worker (how many share the partitions) |
| `snap:{p}` | hash | workers | per site of p its tracker state, and `position`: the last entry it covers |
| `occupancy` | hash | workers | per site its occupancy answer now |
| `occupancy` | channel | workers | each occupancy update as it is made |
| `reply:{replica}` | stream, TTL | workers | the track ids of each frame a replica published, by request id |

A site goes to partition `crc32(site) % PARTITIONS`: stable across processes, machines and versions.
Redis is reached with redis-py's asyncio client; `connect` checks the URL and that Redis answers,
so a bad `--sites-bus` is a one-line error at start.
"""

from __future__ import annotations

import urllib.parse
import zlib
from typing import Any

PARTITIONS = 16
GROUP = "fishloc-sites"
PREFIX = "fishloc:"
OCCUPANCY = f"{PREFIX}occupancy"
REPLY_TTL_S = 60
REPLY_MAXLEN = 1000


class BusError(RuntimeError):
    """The bus URL is not a Redis URL, or Redis does not answer at it."""


def partition_of(site_id: str, partitions: int = PARTITIONS) -> int:
    return zlib.crc32(site_id.encode("utf-8")) % partitions


def stream_key(partition: int) -> str:
    return f"{PREFIX}obs:{partition}"


def lease_key(partition: int) -> str:
    return f"{PREFIX}lease:{partition}"


def snapshot_key(partition: int) -> str:
    return f"{PREFIX}snap:{partition}"


def worker_key(worker_id: str) -> str:
    return f"{PREFIX}worker:{worker_id}"


def reply_key(replica_id: str) -> str:
    return f"{PREFIX}reply:{replica_id}"


def shown_url(url: str) -> str:
    """The URL without its password, for messages and logs."""
    parts = urllib.parse.urlsplit(url)
    if parts.password is None:
        return url
    netloc = f"{parts.username or ''}:***@{parts.hostname}" + (f":{parts.port}" if parts.port else "")
    return urllib.parse.urlunsplit(parts._replace(netloc=netloc))


def check_url(url: str) -> None:
    """BusError unless `url` is redis://HOST[:PORT][/DB] or rediss://…"""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme not in ("redis", "rediss") or not parts.hostname:
        raise BusError(f"the sites bus must be a redis://HOST:PORT/DB URL, got {shown_url(url)!r}")
    try:
        parts.port  # noqa: B018 (a port that is not a number raises here)
    except ValueError as error:
        raise BusError(f"the sites bus URL {shown_url(url)!r} has a bad port: {error}") from None
    db = parts.path.strip("/")
    if db and not db.isdigit():
        raise BusError(f"the sites bus URL {shown_url(url)!r} names database {db!r}: expected a number")


def client(url: str, timeout_s: float = 2.0) -> Any:
    """A redis-py asyncio client of `url` (BusError for a bad URL, ImportError's hint without redis-py).

    Short timeouts: a Redis that does not answer must not hold detection up for long."""
    check_url(url)
    try:
        import redis.asyncio as aioredis
    except ImportError:
        raise BusError("the sites bus needs redis-py: pip install 'fishloc[redis]'") from None
    return aioredis.Redis.from_url(url, socket_connect_timeout=timeout_s, socket_timeout=timeout_s,
                                   health_check_interval=5, decode_responses=False)


async def connect(url: str, timeout_s: float = 2.0) -> Any:
    """A client that has answered PING (BusError with the reason otherwise)."""
    import redis.exceptions

    bus = client(url, timeout_s)
    try:
        await bus.ping()
    except (redis.exceptions.RedisError, OSError) as error:
        await bus.aclose()
        raise BusError(f"the sites bus at {shown_url(url)} does not answer: {error}") from None
    return bus
