"""StreamDetect's backpressure on its own: bounded reading, newest frame wins, shutdown answers."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

from protos.fishloc.v1 import localizer_pb2 as pb
from service.grpc.convert import response_for
from service.grpc.stream import FrameStream

Status = pb.DetectResponse.Status


class Source:
    """An endless gateway: yields frames of `cameras` in turn as fast as they are read."""

    def __init__(self, cameras: tuple[str, ...] = ("cam",), limit: int | None = None) -> None:
        self.cameras = cameras
        self.limit = limit
        self.sent = 0

    async def frames(self) -> AsyncIterator[pb.DetectRequest]:
        while self.limit is None or self.sent < self.limit:
            camera = self.cameras[self.sent % len(self.cameras)]
            self.sent += 1
            yield pb.DetectRequest(camera_id=camera, frame_id=str(self.sent - 1))
            await asyncio.sleep(0)


async def _settle() -> None:
    for _ in range(200):
        await asyncio.sleep(0)


def test_a_gateway_that_never_stops_is_read_only_up_to_the_bound() -> None:
    async def scenario() -> None:
        gate = asyncio.Event()
        source = Source(("a", "b"))

        async def process(request: pb.DetectRequest) -> pb.DetectResponse:
            await gate.wait()
            return response_for(request, Status.OK)

        stream = FrameStream(source.frames(), process, asyncio.Event(), max_unanswered=16)
        responses = stream.responses()
        first = asyncio.ensure_future(anext(responses))
        await _settle()
        # Processing is stuck, so nothing can be sent; reading stopped at the bound.
        assert not first.done() and source.sent == 16 and stream.counts.received == 16
        gate.set()
        answers = [await first] + [await anext(responses) for _ in range(199)]
        await responses.aclose()
        per_camera: dict[str, list[int]] = {"a": [], "b": []}
        for answer in answers:
            per_camera[answer.camera_id].append(int(answer.frame_id))
        for ids in per_camera.values():
            assert ids == sorted(ids)  # each camera's order is kept
        assert stream.counts.received <= 200 + 16  # never more than the bound ahead of the answers
        assert {a.status for a in answers} <= {Status.OK, Status.DROPPED}

    asyncio.run(scenario())


def test_every_frame_is_answered_exactly_once() -> None:
    async def scenario() -> None:
        source = Source(("a", "b", "c"), limit=300)

        async def process(request: pb.DetectRequest) -> pb.DetectResponse:
            await asyncio.sleep(0.001)
            if request.frame_id.endswith("7"):
                return response_for(request, Status.ERROR, "bad_image", "broken")
            return response_for(request, Status.OK)

        stream = FrameStream(source.frames(), process, asyncio.Event(), max_unanswered=32)
        answers = [answer async for answer in stream.responses()]
        assert sorted(int(a.frame_id) for a in answers) == list(range(300))
        dropped = sum(a.status == Status.DROPPED for a in answers)
        assert stream.counts.received == 300 == stream.counts.answered + stream.counts.dropped
        assert dropped == stream.counts.dropped
        assert stream._lanes == {}  # finished cameras leave no state behind

    asyncio.run(scenario())


def test_shutdown_answers_in_flight_frames_and_drops_waiting_ones() -> None:
    async def scenario() -> None:
        gate = asyncio.Event()
        stopping = asyncio.Event()
        source = Source(("cam",))

        async def process(request: pb.DetectRequest) -> pb.DetectResponse:
            await gate.wait()
            return response_for(request, Status.OK)

        stream = FrameStream(source.frames(), process, stopping, max_unanswered=4)
        collected: list[pb.DetectResponse] = []

        async def collect() -> None:
            async for answer in stream.responses():
                collected.append(answer)

        task = asyncio.create_task(collect())
        await _settle()
        stopping.set()
        await _settle()
        gate.set()
        await asyncio.wait_for(task, 5)
        assert [a.frame_id for a in collected] == [str(i) for i in range(len(collected))]
        assert len(collected) == stream.counts.received == source.sent
        assert collected[0].status == Status.OK
        assert collected[-1].status == Status.DROPPED and collected[-1].error_code == "shutting_down"

    asyncio.run(scenario())
