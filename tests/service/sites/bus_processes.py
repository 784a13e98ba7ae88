"""Real processes of a scaled-out site: `fishloc serve --sites-bus` replicas and `fishloc sites`
workers (and `redis-server`, `benchmarks.redis_process`), on free loopback ports, their logs kept."""

from __future__ import annotations

import collections
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import redis
from service_live_server import free_port, wait_until_ready

from benchmarks.redis_process import RedisProcess
from models import DEFAULT_MODEL_PATH
from service.sites import bus

REPO_ROOT = Path(__file__).resolve().parents[3]
_WORKER_RE = re.compile(r"sites worker (\S+) started")


class FishlocProcess:
    """`fishloc <args>` in a child process, its log lines kept."""

    def __init__(self, args: list[str], env: dict[str, str] | None = None) -> None:
        self.args = args
        self.env = env or {}
        self.lines: collections.deque[str] = collections.deque(maxlen=400)
        self.process: subprocess.Popen[str] | None = None
        self._reader: threading.Thread | None = None

    def start(self) -> FishlocProcess:
        env = {**os.environ, "PYTHONPATH": str(REPO_ROOT), "FISHLOC_LOG_JSON": "true", **self.env}
        self.process = subprocess.Popen([sys.executable, "-m", "service.cli", *self.args], cwd=REPO_ROOT,
                                        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        return self

    def _read(self) -> None:
        assert self.process is not None and self.process.stderr is not None
        for line in self.process.stderr:
            self.lines.append(line)

    @property
    def pid(self) -> int:
        assert self.process is not None
        return self.process.pid

    @property
    def log(self) -> str:
        return "".join(self.lines)

    def wait_for_line(self, pattern: re.Pattern[str], timeout_s: float = 60) -> re.Match[str]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for line in list(self.lines):
                found = pattern.search(line)
                if found:
                    return found
            assert self.process is not None
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        self.stop()
        raise RuntimeError(f"fishloc {self.args[0]} did not log {pattern.pattern!r}:\n{self.log[-3000:]}")

    def kill(self) -> None:
        """SIGKILL: no shutdown code runs."""
        assert self.process is not None
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(30)
        self._close_pipe()

    def stop(self) -> int:
        assert self.process is not None
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(60)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait(30)
        self._close_pipe()
        return code

    def _close_pipe(self) -> None:
        if self._reader is not None:
            self._reader.join(10)
        if self.process is not None and self.process.stderr is not None:
            self.process.stderr.close()


class Replica(FishlocProcess):
    """`fishloc serve --sites-bus URL` of the shipped model on a free port."""

    def __init__(self, bus_url: str, database: Path, wait_s: float, model: Path = DEFAULT_MODEL_PATH) -> None:
        self.port = free_port()
        super().__init__(["serve", "--model", str(model), "--database", str(database), "--host", "127.0.0.1",
                          "--http-port", str(self.port), "--grpc-port", "-1", "--threads", "1",
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
