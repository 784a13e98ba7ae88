"""Section 3: camera gateways over gRPC: C cameras, each on its own `StreamDetect` stream, each
sending F frames per second whatever the answers (as a camera does), for a fixed duration.

Per frame: latency from sending to its answer; status OK, DROPPED (a newer frame of the camera won:
the service's backpressure) or ERROR. Throughput is the OK answers per second of the measured window.
Frames sent during the first `warmup_s` seconds are left out of every figure. Cameras start evenly
staggered within one frame period, as unsynchronised cameras would.
"""

from __future__ import annotations

import asyncio
import importlib
import time
from dataclasses import dataclass, field
from typing import Any

from benchmarks.frames import FrameSet
from benchmarks.stats import Summary, summarize

_MESSAGE_LIMIT = 64 * 1024 * 1024


def grpc_unavailable_reason() -> str | None:
    """Why the gRPC section cannot run in this checkout, or None when it can."""
    try:
        _proto_modules()
    except ImportError as error:
        return (f"the gRPC API (fishloc.v1.Localizer, issue 7) is not in this checkout ({error}); "
                "the section runs once protos/fishloc/v1 and the gRPC server are on main")
    return None


def _proto_modules() -> tuple[Any, Any]:
    """The generated messages and stubs of fishloc.v1 (imported by name: they arrive with issue 7)."""
    return (importlib.import_module("protos.fishloc.v1.localizer_pb2"),
            importlib.import_module("protos.fishloc.v1.localizer_pb2_grpc"))


@dataclass
class _Camera:
    camera_id: str
    sent_at: dict[str, float] = field(default_factory=dict)
    measured: set[str] = field(default_factory=set)
    latencies_ms: list[float] = field(default_factory=list)
    statuses: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class GrpcLoad:
    cameras: int
    fps_per_camera: float
    duration_s: float
    warmup_s: float
    sent: int
    ok: int
    dropped: int
    errors: int
    unanswered: int
    latency_ms: Summary | None
    per_camera_ok: dict[str, int]

    @property
    def window_s(self) -> float:
        return self.duration_s - self.warmup_s

    @property
    def throughput_fps(self) -> float:
        return self.ok / self.window_s if self.window_s > 0 else 0.0

    @property
    def dropped_fraction(self) -> float:
        return self.dropped / self.sent if self.sent else 0.0

    def as_dict(self) -> dict[str, object]:
        return {
            "available": True, "cameras": self.cameras, "fps_per_camera": self.fps_per_camera,
            "offered_fps": self.cameras * self.fps_per_camera, "duration_s": self.duration_s,
            "warmup_s": self.warmup_s, "sent": self.sent, "ok": self.ok, "dropped": self.dropped,
            "errors": self.errors, "unanswered": self.unanswered, "throughput_fps": self.throughput_fps,
            "dropped_fraction": self.dropped_fraction,
            "latency_ms": None if self.latency_ms is None else self.latency_ms.as_dict(),
            "per_camera_ok": self.per_camera_ok,
        }


async def _run_camera(target: str, camera: _Camera, frames: FrameSet, fps: float, duration_s: float,
                      warmup_s: float, start_at: float, offset_s: float) -> None:
    import grpc

    pb, pb_grpc = _proto_modules()
    timestamp: Any = importlib.import_module("google.protobuf.timestamp_pb2")

    options = [("grpc.max_send_message_length", _MESSAGE_LIMIT),
               ("grpc.max_receive_message_length", _MESSAGE_LIMIT)]
    async with grpc.aio.insecure_channel(target, options=options) as channel:
        stub: Any = pb_grpc.LocalizerStub(channel)
        call = stub.StreamDetect()

        async def send() -> None:
            count = int(duration_s * fps)
            for index in range(count):
                due = start_at + offset_s + index / fps
                delay = due - time.perf_counter()
                if delay > 0:
                    await asyncio.sleep(delay)
                frame_id = str(index)
                stamp = timestamp.Timestamp()
                stamp.GetCurrentTime()
                request = pb.DetectRequest(camera_id=camera.camera_id, frame_id=frame_id, capture_time=stamp,
                                           image=frames.data[index % len(frames)])
                camera.sent_at[frame_id] = time.perf_counter()
                if offset_s + index / fps >= warmup_s:
                    camera.measured.add(frame_id)
                await call.write(request)
            await call.done_writing()

        async def receive() -> None:
            while True:
                response = await call.read()
                if response is grpc.aio.EOF:
                    return
                received = time.perf_counter()
                camera.statuses[response.frame_id] = int(response.status)
                if response.status == pb.DetectResponse.OK and response.frame_id in camera.measured:
                    camera.latencies_ms.append((received - camera.sent_at[response.frame_id]) * 1e3)

        await asyncio.gather(send(), receive())


async def _run_all(target: str, camera_ids: list[str], frames: FrameSet, fps: float, duration_s: float,
                   warmup_s: float) -> list[_Camera]:
    cameras = [_Camera(camera_id) for camera_id in camera_ids]
    start_at = time.perf_counter() + 0.2
    await asyncio.gather(*(
        _run_camera(target, camera, frames, fps, duration_s, warmup_s, start_at,
                    offset_s=index / (len(cameras) * fps))
        for index, camera in enumerate(cameras)
    ))
    return cameras


def stream_cameras(target: str, camera_ids: list[str], frames: FrameSet, fps: float, duration_s: float,
                   warmup_s: float) -> GrpcLoad:
    """Run the streams against `target` (host:port) and summarise the measured window."""
    pb, _ = _proto_modules()
    if fps <= 0 or duration_s <= warmup_s:
        raise ValueError("need fps > 0 and a duration longer than the warm-up")
    cameras = asyncio.run(_run_all(target, camera_ids, frames, fps, duration_s, warmup_s))
    ok_code, dropped_code, error_code = (pb.DetectResponse.OK, pb.DetectResponse.DROPPED,
                                         pb.DetectResponse.ERROR)
    sent = ok = dropped = errors = unanswered = 0
    latencies: list[float] = []
    per_camera: dict[str, int] = {}
    for camera in cameras:
        statuses = [camera.statuses.get(frame_id) for frame_id in camera.measured]
        sent += len(statuses)
        camera_ok = sum(s == ok_code for s in statuses)
        ok += camera_ok
        dropped += sum(s == dropped_code for s in statuses)
        errors += sum(s == error_code for s in statuses)
        unanswered += sum(s is None for s in statuses)
        latencies += camera.latencies_ms
        per_camera[camera.camera_id] = camera_ok
    return GrpcLoad(
        cameras=len(cameras), fps_per_camera=fps, duration_s=duration_s, warmup_s=warmup_s, sent=sent,
        ok=ok, dropped=dropped, errors=errors, unanswered=unanswered,
        latency_ms=summarize(latencies) if latencies else None, per_camera_ok=per_camera,
    )
