"""The reference camera gateway: streams a source's frames to StreamDetect and writes the answers.

An `InterleavedSource` puts several cameras (e.g. the cameras of one site) on the one stream, each
frame with its camera id and capture time.

One stream per gateway; frames go out as they come (paced to `fps` when asked), answers come back
as JSON lines (the REST answer's shape plus `status`). When the connection fails, the gateway
reconnects with exponential backoff and goes on with the next frame; frames sent but never
answered on a broken stream are counted as `lost`, so sent = answered + dropped + lost.
"""

from __future__ import annotations

import asyncio
import json
import logging
import random
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field

import grpc

from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.gateway.frame_sources import FrameSource, SourceFrame
from service.grpc.convert import response_to_json

log = logging.getLogger(__name__)

Status = pb.DetectResponse.Status
MAX_MESSAGE_BYTES = 32 * 1024 * 1024
# What a broken connection raises from a stream call.
_STREAM_ERRORS = (grpc.aio.AioRpcError, grpc.aio.UsageError, ConnectionError, asyncio.InvalidStateError)


@dataclass(frozen=True)
class GatewayConfig:
    server: str
    camera_id: str
    fps: float | None = None          # None: the source's own rate (video files), else unpaced
    min_score: float | None = None
    max_backoff_s: float = 30.0
    max_reconnects: int | None = None  # None: forever


@dataclass
class GatewayCounts:
    sent: int = 0
    answered: int = 0   # OK or ERROR
    dropped: int = 0
    errors: int = 0     # the ERROR part of answered
    lost: int = 0       # sent on a stream that broke before answering
    reconnects: int = 0


def channel_options() -> list[tuple[str, int]]:
    return [
        ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
        ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
        ("grpc.keepalive_time_ms", 20_000),
        ("grpc.keepalive_timeout_ms", 10_000),
        ("grpc.keepalive_permit_without_calls", 1),
        ("grpc.http2.max_pings_without_data", 0),
    ]


def _next_or_none(frames: Iterator[SourceFrame]) -> SourceFrame | None:
    return next(frames, None)


@dataclass
class _Pacer:
    fps: float | None
    next_at: float = field(default_factory=time.monotonic)

    async def wait(self) -> None:
        if not self.fps:
            return
        delay = self.next_at - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        self.next_at = max(self.next_at, time.monotonic() - 1.0 / self.fps) + 1.0 / self.fps


class Gateway:
    """Streams one source for one camera; `run` returns the counts when the source ends."""

    def __init__(self, config: GatewayConfig, source: FrameSource,
                 write_line: Callable[[str], None]) -> None:
        self.config = config
        self.source = source
        self.write_line = write_line
        self.counts = GatewayCounts()
        self._frames: Iterator[SourceFrame] = iter(source.frames())
        self._exhausted = False
        self._carry: SourceFrame | None = None  # read but not sent when a stream broke

    def _request(self, frame: SourceFrame) -> pb.DetectRequest:
        request = pb.DetectRequest(camera_id=frame.camera_id or self.config.camera_id,
                                   frame_id=frame.frame_id, image=frame.jpeg)
        request.capture_time.FromNanoseconds(frame.capture_time_ns)
        if self.config.min_score is not None:
            request.min_score = self.config.min_score
        return request

    async def _next_frame(self) -> SourceFrame | None:
        if self._carry is not None:
            carried, self._carry = self._carry, None
            return carried
        if self._exhausted:
            return None
        frame = await asyncio.to_thread(_next_or_none, self._frames)
        self._exhausted = frame is None
        return frame

    def _answer(self, response: pb.DetectResponse, outstanding: set[tuple[str, str]]) -> None:
        outstanding.discard((response.camera_id, response.frame_id))
        if response.status == Status.DROPPED:
            self.counts.dropped += 1
        else:
            self.counts.answered += 1
            self.counts.errors += response.status == Status.ERROR
        self.write_line(json.dumps(response_to_json(response)))

    async def _stream_once(self, outstanding: set[tuple[str, str]]) -> None:
        """One StreamDetect call until the source ends (or the call fails)."""
        fps = self.config.fps if self.config.fps is not None else self.source.native_fps
        pacer = _Pacer(fps)
        async with grpc.aio.insecure_channel(self.config.server, options=channel_options()) as channel:
            call = pb_grpc.LocalizerStub(channel).StreamDetect()

            async def read() -> None:
                async for response in call:
                    self._answer(response, outstanding)

            reader = asyncio.create_task(read())
            try:
                while (frame := await self._next_frame()) is not None:
                    await pacer.wait()
                    if reader.done():  # the call ended early: surface its error
                        self._carry = frame
                        await reader
                        raise ConnectionError("the stream ended before the source did")
                    request = self._request(frame)
                    try:
                        await call.write(request)
                    except _STREAM_ERRORS:
                        self._carry = frame
                        raise
                    outstanding.add((request.camera_id, request.frame_id))
                    self.counts.sent += 1
                await call.done_writing()
                await reader
            finally:
                reader.cancel()

    async def run(self) -> GatewayCounts:
        backoff = 0.5
        while True:
            outstanding: set[tuple[str, str]] = set()
            answered_before = self.counts.answered + self.counts.dropped
            try:
                await self._stream_once(outstanding)
                return self.counts
            except _STREAM_ERRORS as error:
                self.counts.lost += len(outstanding)
                if self.counts.answered + self.counts.dropped > answered_before:
                    backoff = 0.5  # that connection worked for a while: start over
                detail = error.details() if isinstance(error, grpc.aio.AioRpcError) else str(error)
                if self._exhausted and self._carry is None:
                    return self.counts
                limit = self.config.max_reconnects
                if limit is not None and self.counts.reconnects >= limit:
                    raise
                self.counts.reconnects += 1
                delay = backoff * random.uniform(0.8, 1.2)  # jitter: gateways do not reconnect in step
                log.warning("stream to %s failed (%s); reconnecting in %.1f s",
                            self.config.server, detail, delay)
                await asyncio.sleep(delay)
                backoff = min(backoff * 2, self.config.max_backoff_s)

    def summary(self) -> str:
        return json.dumps(asdict(self.counts))
