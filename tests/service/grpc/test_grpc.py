"""The gRPC front end against a real grpc.aio server on a loopback port, with real clients.

The model is the plumbing test double (see service_doubles).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import cv2
import grpc
import httpx
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection_pb2, reflection_pb2_grpc
from service_frames import encode, person_frame
from service_live_server import LiveServer

from fisheye import FisheyeCamera, camera_to_dict
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.config import Settings
from service.gateway.client import channel_options
from service.grpc.convert import response_to_json

Status = pb.DetectResponse.Status
TOKEN = "grpc-test-token"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory, double_model_path: object,
           demo_camera: FisheyeCamera) -> Iterator[LiveServer]:
    folder = tmp_path_factory.mktemp("grpc")
    settings = Settings(model=double_model_path, database=str(folder / "cameras.db"), http_port=0,
                        grpc_port=0, host="127.0.0.1", threads=1, api_token=TOKEN)
    with LiveServer(settings) as live:
        tall = camera_to_dict(demo_camera) | {"id": "tall", "altitude_m": 6.4}
        headers = {"Authorization": f"Bearer {TOKEN}"}
        assert httpx.put(f"{live.url}/v1/cameras/tall", json=tall, headers=headers).status_code == 201
        yield live


@pytest.fixture(scope="module")
def frames(demo_camera: FisheyeCamera) -> list[bytes]:
    spots = [(1.0, 0.5), (-1.5, 2.0), (0.3, -2.2), (2.5, 1.0)]
    return [encode(person_frame(demo_camera, xy, (1024, 1024), disk_radius_px=20).bgr) for xy in spots]


def target(server: LiveServer) -> str:
    assert server.service is not None
    return f"127.0.0.1:{server.service.grpc_port}"


def run(coroutine: Any) -> Any:
    return asyncio.run(coroutine)


def rest_answer(server: LiveServer, camera_id: str, data: bytes, frame_id: str) -> dict[str, Any]:
    response = httpx.post(f"{server.url}/v1/cameras/{camera_id}/detect", content=data,
                          headers={"content-type": "image/jpeg"}, params={"frame_id": frame_id})
    assert response.status_code == 200
    return dict(response.json())


def without_timing(answer: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in answer.items() if k not in ("timing_ms", "status", "capture_time")}


def request(camera_id: str, frame_id: str, image: bytes, **fields: Any) -> pb.DetectRequest:
    message = pb.DetectRequest(camera_id=camera_id, frame_id=frame_id, image=image, **fields)
    message.capture_time.FromNanoseconds(1_700_000_000_000_000_000 + int(frame_id.split("-")[-1] or 0))
    return message


async def stream(server: LiveServer, requests: list[pb.DetectRequest]) -> list[pb.DetectResponse]:
    async with grpc.aio.insecure_channel(target(server)) as channel:
        stub = pb_grpc.LocalizerStub(channel)
        return [response async for response in stub.StreamDetect(iter(requests))]


# ----- unary


def test_unary_detect_equals_rest(server: LiveServer, frames: list[bytes]) -> None:
    async def call() -> pb.DetectResponse:
        async with grpc.aio.insecure_channel(target(server)) as channel:
            return await pb_grpc.LocalizerStub(channel).Detect(request("demo", "f-1", frames[0]))

    response = run(call())
    assert response.status == Status.OK and response.capture_time.ToNanoseconds() == 1_700_000_000_000_000_001
    answer = response_to_json(response)
    assert without_timing(answer) == without_timing(rest_answer(server, "demo", frames[0], "f-1"))
    assert len(answer["detections"]) == 2 and answer["timing_ms"]["total"] > 0


GRPC_DEFAULT_MAX_MESSAGE = 4 * 1024 * 1024


@pytest.fixture(scope="module")
def large_frame() -> bytes:
    """A full-resolution 2952x2952 frame of noise at JPEG quality 100: far past gRPC's default
    4 MiB message limit, within the 32 MiB the server and the gateway allow."""
    noise = np.random.default_rng(7).integers(0, 256, (2952, 2952, 3), dtype=np.uint8)
    ok, data = cv2.imencode(".jpg", noise, [cv2.IMWRITE_JPEG_QUALITY, 100])
    assert ok
    assert len(data) > 3 * GRPC_DEFAULT_MAX_MESSAGE
    return bytes(data.tobytes())


def test_a_frame_over_the_default_message_limit_is_answered(server: LiveServer, large_frame: bytes) -> None:
    async def calls() -> tuple[pb.DetectResponse, list[pb.DetectResponse]]:
        async with grpc.aio.insecure_channel(target(server), options=channel_options()) as channel:
            stub = pb_grpc.LocalizerStub(channel)
            unary = await stub.Detect(request("demo", "big-1", large_frame))
            streamed = [r async for r in stub.StreamDetect(iter([request("demo", "big-2", large_frame)]))]
            return unary, streamed

    unary, streamed = run(calls())
    assert [r.frame_id for r in streamed] == ["big-2"]
    for response in (unary, streamed[0]):
        assert response.status == Status.OK, response.error_message
        assert (response.image.width, response.image.height) == (2952, 2952)


INVALID = grpc.StatusCode.INVALID_ARGUMENT


@pytest.mark.parametrize(("camera_id", "image", "code", "text"), [
    ("nowhere", b"x", grpc.StatusCode.NOT_FOUND, "camera_not_found"),
    ("demo", b"\xff\xd8\xff\xd9", INVALID, "bad_image"),
    ("demo", b"", INVALID, "empty_body"),
    ("demo", encode(np.zeros((480, 640, 3), np.uint8)), INVALID, "frame_size_mismatch"),
])
def test_unary_errors(server: LiveServer, camera_id: str, image: bytes, code: grpc.StatusCode,
                      text: str) -> None:
    message = pb.DetectRequest(camera_id=camera_id, frame_id="1", image=image)

    async def call() -> None:
        async with grpc.aio.insecure_channel(target(server)) as channel:
            await pb_grpc.LocalizerStub(channel).Detect(message)

    with pytest.raises(grpc.aio.AioRpcError) as caught:
        run(call())
    assert caught.value.code() == code and text in (caught.value.details() or "")


# ----- streaming


def test_stream_with_several_cameras_equals_rest(server: LiveServer, frames: list[bytes]) -> None:
    requests = [request(camera, f"{camera}-{i}", frames[i % len(frames)])
                for i in range(6) for camera in ("demo", "tall")]
    responses = run(stream(server, requests))
    assert len(responses) == len(requests)
    by_camera: dict[str, list[pb.DetectResponse]] = {"demo": [], "tall": []}
    for response in responses:
        by_camera[response.camera_id].append(response)
    for camera, answers in by_camera.items():
        sent = [r.frame_id for r in requests if r.camera_id == camera]
        assert [a.frame_id for a in answers] == sent  # each camera's frame order is kept
        for answer in answers:
            assert answer.status in (Status.OK, Status.DROPPED)
            index = int(answer.frame_id.split("-")[1])
            assert answer.capture_time.ToNanoseconds() == 1_700_000_000_000_000_000 + index
            if answer.status == Status.OK:
                rest = rest_answer(server, camera, frames[index % len(frames)], answer.frame_id)
                assert without_timing(response_to_json(answer)) == without_timing(rest)
            else:
                assert answer.error_code == "newer_frame" and not answer.detections
    # The taller camera sees the same pixels twice as far away.
    tall_ok = next(a for a in by_camera["tall"] if a.status == Status.OK)
    index = int(tall_ok.frame_id.split("-")[1])
    demo = rest_answer(server, "demo", frames[index % len(frames)], "x")["detections"][0]["position_m"]
    tall = tall_ok.detections[0].position_m
    np.testing.assert_allclose([tall.x, tall.y], 2 * np.array(demo), atol=1e-3)


def test_a_bad_frame_mid_stream_gets_an_error_and_the_stream_goes_on(server: LiveServer,
                                                                      frames: list[bytes]) -> None:
    requests = [request("demo", "a-0", frames[0]), request("demo", "a-1", b"not an image at all"),
                request("nowhere", "a-2", frames[1]), request("demo", "a-3", frames[2], min_score=3.0),
                request("demo", "a-4", frames[3]), request("demo", "a-5", frames[0])]

    async def lockstep() -> tuple[list[pb.DetectResponse], grpc.StatusCode]:
        """One stream; each frame is written only after the previous one is answered (no drops)."""
        async with grpc.aio.insecure_channel(target(server)) as channel:
            call = pb_grpc.LocalizerStub(channel).StreamDetect()
            answers: list[pb.DetectResponse] = []
            for message in requests:
                await call.write(message)
                answers.append(await call.read())
            await call.done_writing()
            assert await call.read() == grpc.aio.EOF
            return answers, await call.code()

    responses, code = run(lockstep())
    assert code == grpc.StatusCode.OK
    statuses = [(r.camera_id, r.frame_id, Status.Name(r.status), r.error_code) for r in responses]
    assert statuses == [("demo", "a-0", "OK", ""), ("demo", "a-1", "ERROR", "unsupported_image"),
                        ("nowhere", "a-2", "ERROR", "camera_not_found"),
                        ("demo", "a-3", "ERROR", "invalid_request"),
                        ("demo", "a-4", "OK", ""), ("demo", "a-5", "OK", "")]
    assert all(r.error_message and not r.detections for r in responses if r.status == Status.ERROR)
    assert all(len(r.detections) == 2 for r in responses if r.status == Status.OK)
    # Pipelined on one stream, each camera's frames still come back in order, every one answered.
    requests = requests[:5]
    mixed = run(stream(server, requests))
    assert [r.frame_id for r in mixed if r.camera_id == "demo"] == ["a-0", "a-1", "a-3", "a-4"]
    assert len(mixed) == 5 and mixed[-1].frame_id in ("a-4", "a-2")
    assert all(r.error_message for r in mixed if r.status != Status.OK)


def test_overloaded_stream_answers_every_frame(server: LiveServer, frames: list[bytes]) -> None:
    """While the first frame waits for the pipeline, every newer frame replaces the waiting one:
    with N frames sent, exactly N - 2 are DROPPED and 2 are answered, in frame order."""
    runner = server.state.runner
    dropped = server.state.metrics.dropped.labels(camera_id="demo")
    n = 40
    held = 0
    while runner.try_admit():  # fill every in-flight slot, as a long frame would
        held += 1
    before = dropped._value.get()

    async def scenario() -> list[pb.DetectResponse]:
        async with grpc.aio.insecure_channel(target(server)) as channel:
            call = pb_grpc.LocalizerStub(channel).StreamDetect()
            for i in range(n):
                await call.write(request("demo", f"o-{i}", frames[i % len(frames)]))
            deadline = time.monotonic() + 30
            while dropped._value.get() - before < n - 2 and time.monotonic() < deadline:
                await asyncio.sleep(0.01)
            for _ in range(held):
                runner.release()
            await call.done_writing()
            return [response async for response in call]

    try:
        responses = run(scenario())
    finally:
        while runner.in_flight > 0 and held > 0:  # if the scenario failed before releasing
            runner.release()
            held -= 1
    assert [r.frame_id for r in responses] == [f"o-{i}" for i in range(n)]
    statuses = [r.status for r in responses]
    assert statuses.count(Status.DROPPED) == n - 2 and statuses.count(Status.OK) == 2
    assert statuses[0] == statuses[-1] == Status.OK


# ----- registry, model, health, reflection


def test_registry_calls_and_token(server: LiveServer, demo_camera: FisheyeCamera) -> None:
    camera = pb.Camera(id="grpc-cam", altitude_m=2.8, image_size=pb.ImageSize(width=900, height=900),
                       principal_point=pb.Point(x=450, y=450), focal_px=pb.Point(x=300, y=300),
                       kb=[1.0, -0.01])
    auth = (("authorization", f"Bearer {TOKEN}"),)

    async def calls() -> dict[str, Any]:
        async with grpc.aio.insecure_channel(target(server)) as channel:
            stub = pb_grpc.LocalizerStub(channel)
            out: dict[str, Any] = {}
            try:
                await stub.PutCamera(pb.PutCameraRequest(camera=camera))
            except grpc.aio.AioRpcError as error:
                out["no_token"] = error.code()
            out["put"] = await stub.PutCamera(pb.PutCameraRequest(camera=camera), metadata=auth)
            out["again"] = await stub.PutCamera(pb.PutCameraRequest(camera=camera), metadata=auth)
            bad = pb.Camera()
            bad.CopyFrom(camera)
            bad.kb[:] = [1.0, -0.5]
            try:
                await stub.PutCamera(pb.PutCameraRequest(camera=bad), metadata=auth)
            except grpc.aio.AioRpcError as error:
                out["invalid"] = error.code()
            own = pb.Camera()
            own.CopyFrom(camera)
            own.max_view_pixels = 2_000_000  # the camera's own view budget, within the server's limit
            own.second_look_pixels = 786_432  # and its own second look
            own.longest_person_ratio = 1.8  # and its own bound on a person's length
            out["own"] = await stub.PutCamera(pb.PutCameraRequest(camera=own), metadata=auth)
            out["own_read"] = await stub.GetCamera(pb.GetCameraRequest(camera_id="grpc-cam"))
            own.max_view_pixels = 4_000_001  # over the default limit: refused, nothing written
            try:
                await stub.PutCamera(pb.PutCameraRequest(camera=own), metadata=auth)
            except grpc.aio.AioRpcError as error:
                out["over"] = (error.code(), error.details())
            out["after_over"] = await stub.GetCamera(pb.GetCameraRequest(camera_id="grpc-cam"))
            out["list"] = await stub.ListCameras(pb.ListCamerasRequest())
            out["demo"] = await stub.GetCamera(pb.GetCameraRequest(camera_id="demo"))
            await stub.DeleteCamera(pb.DeleteCameraRequest(camera_id="grpc-cam"), metadata=auth)
            try:
                await stub.GetCamera(pb.GetCameraRequest(camera_id="grpc-cam"))
            except grpc.aio.AioRpcError as error:
                out["gone"] = error.code()
            out["model"] = await stub.GetModel(pb.GetModelRequest())
            return out

    out = run(calls())
    assert out["no_token"] == grpc.StatusCode.UNAUTHENTICATED
    assert out["put"].created and not out["again"].created and out["put"].camera == camera
    assert out["invalid"] == grpc.StatusCode.INVALID_ARGUMENT
    assert out["own"].camera.max_view_pixels == out["own_read"].max_view_pixels == 2_000_000
    assert not out["put"].camera.HasField("max_view_pixels")
    assert out["own"].camera.second_look_pixels == out["own_read"].second_look_pixels == 786_432
    assert not out["put"].camera.HasField("second_look_pixels")
    assert out["own"].camera.longest_person_ratio == out["own_read"].longest_person_ratio == 1.8
    assert not out["put"].camera.HasField("longest_person_ratio")
    assert out["over"][0] == grpc.StatusCode.INVALID_ARGUMENT and "view_budget_over_limit" in out["over"][1]
    assert out["after_over"].max_view_pixels == 2_000_000
    assert "grpc-cam" in [c.id for c in out["list"].cameras]
    demo = out["demo"]
    assert (demo.altitude_m, list(demo.kb)) == (demo_camera.altitude_m, demo_camera.kb)
    assert demo.max_theta_deg == 95.0
    assert demo.HasField("site_pose")
    assert out["gone"] == grpc.StatusCode.NOT_FOUND
    assert out["model"].name == "plumbing-double" and out["model"].input_size == 256
    assert out["model"].nms_iou == 0.6 and not out["model"].view_operating_points  # legacy point, no views


def test_health_follows_readiness_and_reflection_lists_the_service(server: LiveServer) -> None:
    async def calls() -> tuple[Any, Any, list[str]]:
        async with grpc.aio.insecure_channel(target(server)) as channel:
            health = health_pb2_grpc.HealthStub(channel)
            overall = await health.Check(health_pb2.HealthCheckRequest(service=""))
            localizer = await health.Check(health_pb2.HealthCheckRequest(service="fishloc.v1.Localizer"))
            reflection = reflection_pb2_grpc.ServerReflectionStub(channel)
            ask = reflection_pb2.ServerReflectionRequest(list_services="")
            answers = reflection.ServerReflectionInfo(iter([ask]))
            names = [s.name async for answer in answers for s in answer.list_services_response.service]
            return overall, localizer, names

    overall, localizer, names = run(calls())
    assert overall.status == localizer.status == health_pb2.HealthCheckResponse.SERVING
    assert {"fishloc.v1.Localizer", "grpc.health.v1.Health"} <= set(names)


def test_health_is_not_serving_before_warm_up(settings_for: Callable[..., Settings]) -> None:
    live = LiveServer(settings_for(grpc_port=0), warm_up=False).start(wait_ready=False)
    try:
        async def check() -> Any:
            async with grpc.aio.insecure_channel(target(live)) as channel:
                stub = health_pb2_grpc.HealthStub(channel)
                return await stub.Check(health_pb2.HealthCheckRequest(service=""))

        assert run(check()).status == health_pb2.HealthCheckResponse.NOT_SERVING
    finally:
        live.stop()



def test_shutdown_ends_open_streams_after_answering(settings_for: Callable[..., Settings],
                                                    frames: list[bytes]) -> None:
    live = LiveServer(settings_for(grpc_port=0)).start()
    stopper = threading.Thread(target=live.stop)

    async def scenario() -> tuple[list[pb.DetectResponse], grpc.StatusCode]:
        async with grpc.aio.insecure_channel(target(live)) as channel:
            call = pb_grpc.LocalizerStub(channel).StreamDetect()
            for i in range(5):
                await call.write(request("demo", f"s-{i}", frames[i % len(frames)]))
            responses = [await call.read()]
            stopper.start()  # the gateway has not finished; the server ends the stream
            while (response := await call.read()) != grpc.aio.EOF:
                responses.append(response)
            return responses, await call.code()

    try:
        responses, code = run(scenario())
    finally:
        if stopper.ident is None:
            live.stop()
        else:
            stopper.join(30)
    assert code == grpc.StatusCode.OK
    ids = [r.frame_id for r in responses]
    assert ids == [f"s-{i}" for i in range(len(ids))] and len(ids) >= 1
    for response in responses:
        assert response.status == Status.OK or response.error_code in ("newer_frame", "shutting_down")


def test_shutdown_answers_a_unary_detect_in_flight(settings_for: Callable[..., Settings], frames: list[bytes],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    live = LiveServer(settings_for(grpc_port=0)).start()
    pipeline = live.state.runner.pipeline
    entered, gate = threading.Event(), threading.Event()
    detect = pipeline.detect

    def held_detect(*args: Any, **kwargs: Any) -> Any:
        entered.set()
        gate.wait(30)  # a bound, not an assertion
        return detect(*args, **kwargs)

    monkeypatch.setattr(pipeline, "detect", held_detect)
    stopper = threading.Thread(target=live.stop)
    address = target(live)

    async def refused() -> bool:
        """Whether a new call is refused (the server has stopped accepting)."""
        async with grpc.aio.insecure_channel(address) as channel:
            try:
                await health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(), timeout=1)
            except grpc.aio.AioRpcError:
                return True
            return False

    async def scenario() -> tuple[pb.DetectResponse, bool]:
        async with grpc.aio.insecure_channel(address) as channel:
            call = pb_grpc.LocalizerStub(channel).Detect(request("demo", "u-1", frames[0]))
            assert await asyncio.to_thread(entered.wait, 30)  # the frame is in the pipeline
            stopper.start()
            deadline = time.monotonic() + 30
            while not (stopped := await refused()) and time.monotonic() < deadline:
                await asyncio.sleep(0.02)
            gate.set()
            return await call, stopped

    try:
        response, stopped = run(scenario())
    finally:
        gate.set()
        if stopper.ident is None:
            live.stop()
        else:
            stopper.join(30)
    assert stopped  # the answer below came while the server was shutting down
    assert response.status == Status.OK and response.frame_id == "u-1" and len(response.detections) == 2


def test_taken_ports_stop_start_up(server: LiveServer, settings_for: Callable[..., Settings]) -> None:
    assert server.service is not None
    with pytest.raises(RuntimeError, match="bind"):
        LiveServer(settings_for(grpc_port=server.service.grpc_port)).start()
    with pytest.raises(OSError, match="cannot listen for REST"):
        LiveServer(settings_for(grpc_port=0, http_port=server.service.http_port)).start()


def test_the_model_message_carries_each_views_operating_point() -> None:
    from contract import OnnxModel, OperatingPoint, SessionThreads
    from models import DEFAULT_MODEL_PATH
    from service.grpc.convert import model_to_message

    info = OnnxModel(DEFAULT_MODEL_PATH, SessionThreads(1)).info
    message = model_to_message(info)
    assert message.nms_iou == pytest.approx(info.nms_iou) and info.view_points
    for layout, point in info.view_points:
        got = message.view_operating_points[layout]
        assert OperatingPoint(got.min_score, got.nms_iou) == point
