"""A real gRPC client for the reliability tests: one channel per call to a LiveServer's gRPC port,
over plain text or TLS, and the checks its answers share."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Sequence
from typing import TypeVar

import grpc
import numpy as np
from reliability_samples import PERSON_FLOOR_XY_M
from reliability_support import LiveServer

from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc

T = TypeVar("T")
Status = pb.DetectResponse.Status
Metadata = Sequence[tuple[str, str]]


def grpc_target(server: LiveServer) -> str:
    assert server.service is not None
    return f"127.0.0.1:{server.service.grpc_port}"


def on_channel(target: str, use: Callable[[grpc.aio.Channel], Awaitable[T]],
               credentials: grpc.ChannelCredentials | None = None) -> T:
    """Run `use(channel)` on a fresh channel (TLS when `credentials` are given) and close it."""

    async def run() -> T:
        if credentials is None:
            channel = grpc.aio.insecure_channel(target)
        else:
            channel = grpc.aio.secure_channel(target, credentials)
        async with channel:
            return await use(channel)

    return asyncio.run(run())


def localizer(target: str, use: Callable[[pb_grpc.LocalizerStub], Awaitable[T]],
              credentials: grpc.ChannelCredentials | None = None) -> T:
    """Run `use(stub)` with a Localizer stub on a fresh channel."""
    return on_channel(target, lambda channel: use(pb_grpc.LocalizerStub(channel)), credentials)


def refused(target: str, use: Callable[[pb_grpc.LocalizerStub], Awaitable[object]],
            credentials: grpc.ChannelCredentials | None = None) -> grpc.aio.AioRpcError:
    """The error a call must end with (AssertionError when it succeeds)."""
    try:
        localizer(target, use, credentials)
    except grpc.aio.AioRpcError as error:
        return error
    raise AssertionError("the call succeeded")


def stream_all(target: str, requests: list[pb.DetectRequest], metadata: Metadata = (),
               credentials: grpc.ChannelCredentials | None = None) -> list[pb.DetectResponse]:
    """Send `requests` on one StreamDetect call, then every answer until the server ends it."""

    async def use(stub: pb_grpc.LocalizerStub) -> list[pb.DetectResponse]:
        return [response async for response in stub.StreamDetect(iter(requests), metadata=metadata)]

    return localizer(target, use, credentials)


def stream_refusal(target: str, metadata: Metadata = (),
                   credentials: grpc.ChannelCredentials | None = None) -> grpc.StatusCode:
    """The status of a StreamDetect call that sends nothing: what the server answers from the call's
    metadata alone. (A grpcio asyncio client that writes after the server ended a stream may report
    INTERNAL "Internal error from Core" instead of the server's status, grpc/grpc#36066.)"""

    async def use(stub: pb_grpc.LocalizerStub) -> grpc.StatusCode:
        call = stub.StreamDetect(metadata=metadata, timeout=10)  # an open stream would wait forever
        code: grpc.StatusCode = await call.code()
        return code

    return localizer(target, use, credentials)


def assert_person(response: pb.DetectResponse) -> None:
    """An OK answer whose best detection stands at the person's floor position."""
    assert response.status == Status.OK, (Status.Name(response.status), response.error_message)
    best = max(response.detections, key=lambda detection: detection.score)
    position = best.position_m
    np.testing.assert_allclose([position.x, position.y], PERSON_FLOOR_XY_M, atol=0.01)
