"""Real processes of a scaled-out site: `fishloc serve --sites-bus` replicas and `fishloc sites`
workers (and `redis-server`, `benchmarks.redis_process`), on free loopback ports, their logs kept."""

from __future__ import annotations

import re
import time
from pathlib import Path

import redis
from service_live_server import free_port, wait_until_ready
from service_processes import FishlocProcess

from benchmarks.redis_process import RedisProcess
from models import DEFAULT_MODEL_PATH
from service.sites import bus

_WORKER_RE = re.compile(r"sites worker (\S+) started")


class Replica(FishlocProcess):
    """`fishloc serve --sites-bus URL` of the shipped model on a free port."""

    def __init__(self, bus_url: str, database: Path, wait_s: float, model: Path = DEFAULT_MODEL_PATH,
                 grpc: bool = False) -> None:
        self.port = free_port()
        self.grpc_port = free_port() if grpc else -1
        super().__init__(["serve", "--model", str(model), "--database", str(database), "--host", "127.0.0.1",
                          "--http-port", str(self.port), "--grpc-port", str(self.grpc_port), "--threads", "1",
                          "--no-demo-camera", "--sites-bus", bus_url],
                         env={"FISHLOC_SITES_BUS_WAIT_S": repr(wait_s)})

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout_s: float = 120) -> Replica:
        super().start()
        try:
            wait_until_ready(self.url, self.process, timeout_s)
        except (RuntimeError, TimeoutError) as error:
            self.stop()
            raise RuntimeError(f"the replica did not become ready ({error}):\n{self.log[-3000:]}") from None
        return self


class Worker(FishlocProcess):
    """`fishloc sites --bus URL`; `worker_id` once it has started."""

    def __init__(self, bus_url: str, database: Path) -> None:
        super().__init__(["sites", "--bus", bus_url, "--database", str(database)])
        self.worker_id = ""

    def start(self) -> Worker:
        super().start()
        self.worker_id = self.wait_for_line(_WORKER_RE).group(1)
        return self


def lease_owners(client: redis.Redis, partitions: int = bus.PARTITIONS) -> list[str | None]:
    """The worker id holding each partition's lease (None: free)."""
    owners = client.mget([bus.lease_key(p) for p in range(partitions)])
    return [None if owner is None else owner.decode() for owner in owners]


def wait_for_leases(client: redis.Redis, workers: int, timeout_s: float = 60) -> list[str | None]:
    """Until every partition is leased and `workers` distinct workers hold them."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        owners = lease_owners(client)
        if None not in owners and len(set(owners)) == workers:
            return owners
        time.sleep(0.1)
    raise TimeoutError(f"the partitions were not shared by {workers} workers: {lease_owners(client)}")


__all__ = ["FishlocProcess", "RedisProcess", "Replica", "Worker", "lease_owners", "wait_for_leases"]
