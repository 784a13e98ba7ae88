"""StreamDetect's backpressure: per camera, newest frame wins, and every frame is answered once.

Per camera on a stream (a *lane*): one frame is processed at a time and at most one waits. A newer
frame replaces the waiting one, which is answered DROPPED. Answers leave in each camera's frame
order: every frame gets a slot in its lane's queue when it arrives, and a slot is sent once it and
all slots before it are resolved. The frames read but not yet answered are capped; at the cap the
stream stops reading (HTTP/2 flow control then slows the sender), so memory stays bounded. Only the
frames being processed or waiting hold image bytes (two per camera).
"""

from __future__ import annotations

import asyncio
import collections
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field

from protos.fishloc.v1 import localizer_pb2 as pb
from service.grpc.convert import response_for

Status = pb.DetectResponse.Status
Process = Callable[[pb.DetectRequest], Awaitable[pb.DetectResponse]]

# Frames read but not yet sent back, per stream; beyond it the stream stops reading.
MAX_UNANSWERED = 256
_ANSWERED = pb.DetectRequest()


@dataclass
class _Slot:
    """One frame's place in its camera's answer order."""

    request: pb.DetectRequest
    response: pb.DetectResponse | None = None


@dataclass
class _Lane:
    """One camera on one stream."""

    order: collections.deque[_Slot] = field(default_factory=collections.deque)
    waiting: _Slot | None = None
    busy: bool = False


@dataclass
class StreamCounts:
    received: int = 0
    answered: int = 0
    dropped: int = 0


class FrameStream:
    """Runs one StreamDetect call: reads requests, processes them per lane, yields responses."""

    def __init__(self, requests: AsyncIterator[pb.DetectRequest], process: Process,
                 stopping: asyncio.Event, on_drop: Callable[[str], None] | None = None,
                 max_unanswered: int = MAX_UNANSWERED) -> None:
        self._requests = requests
        self._process = process
        self._stopping = stopping
        self._on_drop = on_drop
        self._max_unanswered = max_unanswered
        self._lanes: dict[str, _Lane] = {}
        self._ready: asyncio.Queue[pb.DetectResponse] = asyncio.Queue()
        self._unanswered = 0
        self._room = asyncio.Event()
        self._room.set()
        self._tasks: set[asyncio.Task[None]] = set()
        self.counts = StreamCounts()

    # ----- answering in order

    def _resolve(self, lane: _Lane, slot: _Slot, response: pb.DetectResponse) -> None:
        slot.response = response
        slot.request = _ANSWERED  # the image bytes are not needed any more
        while lane.order and lane.order[0].response is not None:
            ready = lane.order.popleft().response
            assert ready is not None
            self._ready.put_nowait(ready)

    def _drop(self, lane: _Lane, slot: _Slot, code: str, message: str) -> None:
        self.counts.dropped += 1
        if self._on_drop is not None:
            self._on_drop(slot.request.camera_id)
        self._resolve(lane, slot, response_for(slot.request, Status.DROPPED, code, message))

    # ----- processing, one frame per lane at a time

    async def _work(self, camera_id: str, lane: _Lane, slot: _Slot) -> None:
        current: _Slot | None = slot
        while current is not None:
            try:
                response = await self._process(current.request)
            except Exception as error:  # a frame's failure must not end the stream
                response = response_for(current.request, Status.ERROR, "internal", str(error))
            self._resolve(lane, current, response)
            current, lane.waiting = lane.waiting, None
            if current is not None and self._stopping.is_set():
                self._drop(lane, current, "shutting_down", "the server is shutting down")
                current = None
        lane.busy = False
        if not lane.order and self._lanes.get(camera_id) is lane:
            del self._lanes[camera_id]  # a stream may name many cameras over its life

    def _admit(self, request: pb.DetectRequest) -> None:
        lane = self._lanes.setdefault(request.camera_id, _Lane())
        slot = _Slot(request)
        lane.order.append(slot)
        if self._stopping.is_set():  # read in the same instant as the stop: answered, not processed
            self._drop(lane, slot, "shutting_down", "the server is shutting down")
            return
        if not lane.busy:
            lane.busy = True
            task = asyncio.create_task(self._work(request.camera_id, lane, slot))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return
        if lane.waiting is not None:
            self._drop(lane, lane.waiting, "newer_frame", "a newer frame of this camera arrived first")
        lane.waiting = slot

    async def _read(self) -> None:
        stop = asyncio.create_task(self._stopping.wait())
        try:
            iterator = aiter(self._requests)
            while not self._stopping.is_set():
                await self._room.wait()
                if self._stopping.is_set():
                    break
                next_request = asyncio.ensure_future(anext(iterator))
                done, _ = await asyncio.wait({next_request, stop}, return_when=asyncio.FIRST_COMPLETED)
                if next_request not in done:
                    next_request.cancel()
                    break
                try:
                    request = next_request.result()
                except StopAsyncIteration:
                    break
                self.counts.received += 1
                self._unanswered += 1
                if self._unanswered >= self._max_unanswered:
                    self._room.clear()
                self._admit(request)
        finally:
            stop.cancel()
        # Answer what is in flight; the waiting frames too, unless the server is stopping.
        while self._tasks:
            await asyncio.gather(*list(self._tasks))

    async def responses(self) -> AsyncIterator[pb.DetectResponse]:
        """Every answer, as soon as it may be sent; ends after the last frame is answered."""
        reader = asyncio.create_task(self._read())
        try:
            while True:
                if self._ready.empty() and reader.done():
                    await reader  # re-raise a read error (e.g. the client went away)
                    return
                getter = asyncio.ensure_future(self._ready.get())
                await asyncio.wait({getter, reader}, return_when=asyncio.FIRST_COMPLETED)
                if not getter.done():
                    getter.cancel()
                    continue
                response = getter.result()
                self.counts.answered += response.status != Status.DROPPED
                yield response
                self._unanswered -= 1
                if self._unanswered < self._max_unanswered:
                    self._room.set()
        finally:
            reader.cancel()
            for task in list(self._tasks):
                task.cancel()
