"""Access over gRPC: TLS from the same certificate paths as REST, the optional detection token on
Detect and StreamDetect, and the API token on registry writes."""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable
from pathlib import Path

import grpc
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc
from reliability_grpc_client import (
    Metadata,
    Status,
    assert_person,
    grpc_target,
    localizer,
    on_channel,
    refused,
    stream_all,
    stream_refusal,
)
from reliability_samples import Samples
from reliability_support import LiveServer, self_signed

from fisheye import FisheyeCamera
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.config import Settings
from service.grpc.convert import camera_to_message

pytest_plugins = ["reliability_fixtures"]

API_TOKEN = "api-7f3c1d9e5b2a4c6e8f0a1b3c5d7e9f1a"
DETECT_TOKEN = "det-2b4d6f8a0c1e3f5a7b9c1d3e5f7a9b1c"
UNAUTHENTICATED = grpc.StatusCode.UNAUTHENTICATED


def bearer(token: str) -> Metadata:
    return (("authorization", f"Bearer {token}"),)


def detect(request: pb.DetectRequest, metadata: Metadata = (),
           timeout_s: float | None = None) -> Callable[[pb_grpc.LocalizerStub], Awaitable[object]]:
    return lambda stub: stub.Detect(request, metadata=metadata, timeout=timeout_s)


def good_request(demo_camera: FisheyeCamera, frame_id: str = "f-1") -> pb.DetectRequest:
    return pb.DetectRequest(camera_id="demo", frame_id=frame_id, image=Samples(demo_camera).good_jpeg)


def health_status(target: str, credentials: grpc.ChannelCredentials | None = None,
                  timeout_s: float = 10) -> int:
    async def use(channel: grpc.aio.Channel) -> int:
        stub = health_pb2_grpc.HealthStub(channel)
        answer = await stub.Check(health_pb2.HealthCheckRequest(service=""), timeout=timeout_s)
        return int(answer.status)

    return on_channel(target, use, credentials)


# ----- TLS


def test_grpc_over_tls(settings_for: Callable[..., Settings], tmp_path: Path,
                       demo_camera: FisheyeCamera) -> None:
    cert, key = self_signed(tmp_path)
    live = LiveServer(settings_for(grpc_port=0, tls_cert=cert, tls_key=key)).start(wait_ready=False)
    try:
        target = grpc_target(live)
        trusted = grpc.ssl_channel_credentials(root_certificates=cert.read_bytes())
        deadline = time.monotonic() + 60
        while health_status(target, trusted) != health_pb2.HealthCheckResponse.SERVING:
            assert time.monotonic() < deadline, "the TLS server did not become ready"
            time.sleep(0.05)
        request = good_request(demo_camera)
        assert_person(localizer(target, detect(request), trusted))
        [streamed] = stream_all(target, [request], credentials=trusted)
        assert_person(streamed)
        # A client with the system's roots does not trust a self-signed certificate.
        untrusted = refused(target, detect(request, timeout_s=10), grpc.ssl_channel_credentials())
        assert untrusted.code() == grpc.StatusCode.UNAVAILABLE, untrusted.details()
        with pytest.raises(grpc.aio.AioRpcError) as caught:
            health_status(target, grpc.ssl_channel_credentials())
        assert caught.value.code() == grpc.StatusCode.UNAVAILABLE
        # Plain text on the TLS port.
        plain = refused(target, detect(request, timeout_s=10))
        assert plain.code() == grpc.StatusCode.UNAVAILABLE, plain.details()
    finally:
        live.stop()


# ----- tokens


def test_grpc_detect_token(settings_for: Callable[..., Settings], demo_camera: FisheyeCamera) -> None:
    request = good_request(demo_camera)
    wrong: list[Metadata] = [(), bearer("wrong"), (("authorization", DETECT_TOKEN),),
                             (("authorization", "Basic x"),), bearer(DETECT_TOKEN[:-1])]
    with LiveServer(settings_for(grpc_port=0, api_token=API_TOKEN, detect_token=DETECT_TOKEN)) as live:
        target = grpc_target(live)
        for metadata in wrong:
            error = refused(target, detect(request, metadata))
            assert error.code() == UNAUTHENTICATED and "Bearer" in (error.details() or "")
            assert stream_refusal(target, metadata) == UNAUTHENTICATED
        for token in (DETECT_TOKEN, API_TOKEN):
            assert_person(localizer(target, detect(request, bearer(token))))
            answers = stream_all(target, [request, good_request(demo_camera, "f-2")], bearer(token))
            assert [answer.frame_id for answer in answers] == ["f-1", "f-2"]
            for answer in answers:
                assert_person(answer)
        # Health and registry reads stay open.
        assert health_status(target) == health_pb2.HealthCheckResponse.SERVING
        camera = localizer(target, lambda stub: stub.GetCamera(pb.GetCameraRequest(camera_id="demo")))
        assert isinstance(camera, pb.Camera) and camera.id == "demo"
    with LiveServer(settings_for(grpc_port=0, api_token=API_TOKEN)) as open_detect:  # no detect token
        target = grpc_target(open_detect)
        assert_person(localizer(target, detect(request)))
        [streamed] = stream_all(target, [request])
        assert streamed.status == Status.OK


def test_grpc_registry_writes_need_the_api_token(settings_for: Callable[..., Settings],
                                                 demo_camera: FisheyeCamera) -> None:
    camera = camera_to_message(demo_camera)
    camera.id = "cam"
    put = pb.PutCameraRequest(camera=camera)
    delete_demo = pb.DeleteCameraRequest(camera_id="demo")

    def cameras(target: str) -> list[pb.Camera]:
        async def use(stub: pb_grpc.LocalizerStub) -> list[pb.Camera]:
            return list((await stub.ListCameras(pb.ListCamerasRequest())).cameras)

        return localizer(target, use)

    with LiveServer(settings_for(grpc_port=0, api_token=API_TOKEN, detect_token=DETECT_TOKEN)) as live:
        target = grpc_target(live)
        before = cameras(target)
        for metadata in [(), bearer("wrong"), bearer(API_TOKEN + "x"), bearer(DETECT_TOKEN),
                         (("authorization", API_TOKEN),)]:
            for call in (lambda stub, given=metadata: stub.PutCamera(put, metadata=given),
                         lambda stub, given=metadata: stub.DeleteCamera(delete_demo, metadata=given)):
                error = refused(target, call)
                assert error.code() == UNAUTHENTICATED and "Bearer" in (error.details() or "")
        assert cameras(target) == before
        written = localizer(target, lambda stub: stub.PutCamera(put, metadata=bearer(API_TOKEN)))
        assert isinstance(written, pb.PutCameraResponse) and written.created
        assert {c.id for c in cameras(target)} == {c.id for c in before} | {"cam"}
        localizer(target, lambda stub: stub.DeleteCamera(pb.DeleteCameraRequest(camera_id="cam"),
                                                         metadata=bearer(API_TOKEN)))
        assert cameras(target) == before
