"""Section 2: end to end over HTTP against a live `fishloc serve`: one client, then N at once.

A client posts the encoded frame as `image/jpeg` on a kept-alive connection and times the whole
exchange (upload, queueing, pipeline, JSON answer). The server's own `timing_ms.total` of each
answer is kept beside it, so the HTTP layer's share is visible.
"""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import dataclass

import httpx

from benchmarks.frames import FrameSet
from benchmarks.stats import Summary, summarize


@dataclass(frozen=True)
class Exchange:
    """One request: client-side latency, HTTP status, the server's pipeline total (ms, OK only)."""

    latency_ms: float
    status: int
    server_total_ms: float | None


@dataclass(frozen=True)
class HttpLoad:
    clients: int
    requests: int
    ok: int
    overloaded: int
    errors: int
    wall_s: float
    latency_ms: Summary | None
    server_total_ms: Summary | None

    @property
    def throughput_fps(self) -> float:
        return self.ok / self.wall_s if self.wall_s > 0 else 0.0

    def as_dict(self) -> dict[str, object]:
        return {
            "clients": self.clients, "requests": self.requests, "ok": self.ok,
            "overloaded_503": self.overloaded, "errors": self.errors, "wall_s": self.wall_s,
            "throughput_fps": self.throughput_fps,
            "latency_ms": None if self.latency_ms is None else self.latency_ms.as_dict(),
            "server_total_ms": None if self.server_total_ms is None else self.server_total_ms.as_dict(),
        }


def post_frame(client: httpx.Client, url: str, data: bytes) -> Exchange:
    start = time.perf_counter()
    response = client.post(url, content=data, headers={"Content-Type": "image/jpeg"})
    body = response.json() if response.status_code == 200 else None
    latency = (time.perf_counter() - start) * 1e3
    total = float(body["timing_ms"]["total"]) if body is not None else None
    return Exchange(latency, response.status_code, total)


def detect_url(base_url: str, camera_id: str) -> str:
    return f"{base_url}/v1/cameras/{camera_id}/detect"


def _load(exchanges: list[Exchange], clients: int, wall_s: float) -> HttpLoad:
    ok = [e for e in exchanges if e.status == 200]
    totals = [e.server_total_ms for e in ok if e.server_total_ms is not None]
    return HttpLoad(
        clients=clients, requests=len(exchanges), ok=len(ok),
        overloaded=sum(e.status == 503 for e in exchanges),
        errors=sum(e.status not in (200, 503) for e in exchanges), wall_s=wall_s,
        latency_ms=summarize([e.latency_ms for e in ok]) if ok else None,
        server_total_ms=summarize(totals) if totals else None,
    )


def single_client(base_url: str, camera_id: str, frames: FrameSet, runs: int, warmup: int,
                  timeout_s: float = 60.0) -> HttpLoad:
    """`warmup` untimed requests, then `runs` in sequence, frames in turn."""
    url = detect_url(base_url, camera_id)
    with httpx.Client(timeout=timeout_s) as client:
        for index in range(warmup):
            post_frame(client, url, frames.data[index % len(frames)])
        start = time.perf_counter()
        exchanges = [post_frame(client, url, frames.data[index % len(frames)]) for index in range(runs)]
        wall = time.perf_counter() - start
    return _load(exchanges, 1, wall)


def concurrent_clients(base_url: str, camera_id: str, frames: FrameSet, clients: int, requests: int,
                       timeout_s: float = 60.0) -> HttpLoad:
    """`clients` threads, each on its own connection, sending back to back until `requests` in all
    have been sent; each client starts on a different frame."""
    url = detect_url(base_url, camera_id)
    per_client = [requests // clients + (1 if i < requests % clients else 0) for i in range(clients)]
    results: list[list[Exchange]] = [[] for _ in range(clients)]
    failures: list[BaseException] = []
    barrier = threading.Barrier(clients + 1)

    def work(slot: int) -> None:
        try:
            with httpx.Client(timeout=timeout_s) as client:
                post_frame(client, url, frames.data[slot % len(frames)])  # opens the connection
                barrier.wait()
                for index in range(per_client[slot]):
                    results[slot].append(post_frame(client, url, frames.data[(slot + index) % len(frames)]))
        except BaseException as error:  # reported to the caller below
            failures.append(error)
            barrier.abort()

    threads = [threading.Thread(target=work, args=(slot,), daemon=True) for slot in range(clients)]
    for thread in threads:
        thread.start()
    with contextlib.suppress(threading.BrokenBarrierError):  # a failed client is reported below
        barrier.wait()
    start = time.perf_counter()
    for thread in threads:
        thread.join()
    wall = time.perf_counter() - start
    if failures:
        raise RuntimeError(f"an HTTP client failed: {failures[0]!r}") from failures[0]
    return _load([e for slot in results for e in slot], clients, wall)
