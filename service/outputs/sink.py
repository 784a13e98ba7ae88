"""The interface of an output and the dispatcher that fans each site update out to every one.

A `Sink` takes `SiteUpdate`s (`publish`, awaited on the service's event loop) and reports its health.
The `Dispatcher` is what a tracker's host calls (`offer`, from any thread, never blocking): it derives
the update's events once (`service.outputs.events`), then hands the update to each sink through a
bounded queue of its own, so a slow or unreachable sink drops updates (counted in
`fishloc_output_dropped_total`) instead of slowing detection or the other sinks.
"""

from __future__ import annotations

import abc
import asyncio
import contextlib
import logging
from typing import Any

from prometheus_client import CollectorRegistry, Counter

from service.outputs.events import EventDeriver, Occupancy, SiteUpdate
from sites import SiteLayout

log = logging.getLogger(__name__)

QUEUE_SIZE = 1024


async def cancel(task: asyncio.Task[None] | None) -> None:
    """Cancel a background task and wait for it to end."""
    if task is not None:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


class OutputMetrics:
    """Counters of the outputs, on the service's registry."""

    def __init__(self, registry: CollectorRegistry) -> None:
        self.dropped = Counter("fishloc_output_dropped", "Updates or messages an output dropped (queue "
                               "full or not connected).", ["sink"], registry=registry)
        self.delivered = Counter("fishloc_output_delivered", "Messages an output delivered.", ["sink"],
                                 registry=registry)
        self.failures = Counter("fishloc_output_failures", "Failed deliveries or connections of an "
                                "output.", ["sink"], registry=registry)


class Sink(abc.ABC):
    """One output of site updates (MQTT, webhooks, history)."""

    name: str = "sink"

    async def start(self) -> None:  # noqa: B027 (a sink without background work keeps this)
        """Begin background work (connections, delivery loops)."""

    @abc.abstractmethod
    async def publish(self, update: SiteUpdate) -> None:
        """Take one site update (its events derived already)."""

    async def close(self) -> None:  # noqa: B027
        """Flush what can be flushed and stop."""

    def health(self) -> dict[str, Any]:
        """For `/readyz`: at least `ok` (a sink's trouble never makes the service unready)."""
        return {"ok": True}


class Dispatcher:
    """Fans site updates out to sinks (see the module docstring)."""

    def __init__(self, sinks: list[Sink], metrics: OutputMetrics, queue_size: int = QUEUE_SIZE) -> None:
        self.sinks = sinks
        self.metrics = metrics
        self.queue_size = queue_size
        self.deriver = EventDeriver()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._queues: list[asyncio.Queue[SiteUpdate]] = []
        self._tasks: list[asyncio.Task[None]] = []

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        for sink in self.sinks:
            await sink.start()
            queue: asyncio.Queue[SiteUpdate] = asyncio.Queue(maxsize=self.queue_size)
            self._queues.append(queue)
            self._tasks.append(asyncio.create_task(self._feed(sink, queue), name=f"output-{sink.name}"))

    def offer(self, site_id: str, occupancy: Occupancy, layout: SiteLayout) -> None:
        """An occupancy update of a site (any thread; returns at once)."""
        loop = self._loop
        if loop is None or not self.sinks:
            return
        update = self.deriver.derive(site_id, occupancy, layout)
        with contextlib.suppress(RuntimeError):  # the loop has closed: the service is stopping
            loop.call_soon_threadsafe(self._hand_out, update)

    def _hand_out(self, update: SiteUpdate) -> None:
        for sink, queue in zip(self.sinks, self._queues, strict=True):
            if queue.full():
                self.metrics.dropped.labels(sink.name).inc()
                continue
            queue.put_nowait(update)

    async def _feed(self, sink: Sink, queue: asyncio.Queue[SiteUpdate]) -> None:
        while True:
            update = await queue.get()
            try:
                await sink.publish(update)
            except Exception:  # a sink's fault must not end its feed
                log.exception("output %s failed on an update of site %s", sink.name, update.site)
            finally:
                queue.task_done()

    async def drain(self) -> None:
        """Wait until every sink has taken every update offered so far."""
        await asyncio.sleep(0)  # updates handed over with call_soon_threadsafe land first
        for queue in self._queues:
            await queue.join()

    async def close(self) -> None:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self.drain(), timeout=5.0)
        for task in self._tasks:
            await cancel(task)
        for sink in self.sinks:
            try:
                await sink.close()
            except Exception:
                log.exception("output %s failed to close", sink.name)
        self._tasks, self._queues = [], []

    def health(self) -> dict[str, dict[str, Any]]:
        return {sink.name: sink.health() for sink in self.sinks}
