"""Every gRPC case of reliability_grpc_cases.py against a real grpc.aio server on a loopback port:
unary Detect answers the status code expected, the same frame inside a StreamDetect stream gets an
ERROR answer while the stream goes on, and afterwards the server still finds the person in a good
frame; refused registry calls leave the registry as it was."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterator
from pathlib import Path

import grpc
import pytest
from reliability_cases import MAX_BODY_BYTES, MAX_PIXELS
from reliability_grpc_cases import (
    GRPC_CAMERA_CASES,
    GRPC_FRAME_CASES,
    MAX_MESSAGE_BYTES,
    GrpcCameraCase,
    GrpcExpect,
    GrpcFrameCase,
    camera_message,
)
from reliability_grpc_client import Status, assert_person, grpc_target, localizer, refused, stream_all
from reliability_samples import Samples
from reliability_support import LiveServer, test_settings

from fisheye import FisheyeCamera
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc

pytest_plugins = ["reliability_fixtures"]  # fixtures shared by the reliability tests

Call = Callable[[pb_grpc.LocalizerStub], Awaitable[object]]
# Details travel in the trailing metadata, which a client refuses past 8 KiB: an error never quotes
# an input whole.
MAX_DETAILS_CHARS = 1000


@pytest.fixture(scope="module")
def server(double_model_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = test_settings(double_model_path, tmp_path_factory.mktemp("grpc-bad-input"), grpc_port=0,
                             max_body_bytes=MAX_BODY_BYTES, max_pixels=MAX_PIXELS,
                             grpc_max_message_bytes=MAX_MESSAGE_BYTES)
    with LiveServer(settings) as live:
        yield live


@pytest.fixture(scope="module")
def samples(demo_camera: FisheyeCamera) -> Samples:
    return Samples(demo_camera)


def good_request(samples: Samples, frame_id: str = "good") -> pb.DetectRequest:
    return pb.DetectRequest(camera_id="demo", frame_id=frame_id, image=samples.good_jpeg)


def registry(target: str) -> list[pb.Camera]:
    async def use(stub: pb_grpc.LocalizerStub) -> list[pb.Camera]:
        return list((await stub.ListCameras(pb.ListCamerasRequest())).cameras)

    return localizer(target, use)


def detect(request: pb.DetectRequest) -> Call:
    return lambda stub: stub.Detect(request)


def put(camera: pb.Camera) -> Call:
    return lambda stub: stub.PutCamera(pb.PutCameraRequest(camera=camera))


def get(camera_id: str) -> Call:
    return lambda stub: stub.GetCamera(pb.GetCameraRequest(camera_id=camera_id))


def delete(camera_id: str) -> Call:
    return lambda stub: stub.DeleteCamera(pb.DeleteCameraRequest(camera_id=camera_id))


def assert_refused(error: grpc.aio.AioRpcError, expect: GrpcExpect) -> None:
    details = error.details() or ""
    assert error.code() == expect.code, details
    if expect.error_code:
        assert details.startswith(f"{expect.error_code}: "), details
    assert expect.message in details, details
    assert len(details) < MAX_DETAILS_CHARS


def assert_unharmed(target: str, samples: Samples, cameras_before: list[pb.Camera]) -> None:
    assert_person(localizer(target, detect(good_request(samples))))
    assert registry(target) == cameras_before


@pytest.mark.parametrize("case", GRPC_FRAME_CASES, ids=[case.name for case in GRPC_FRAME_CASES])
def test_grpc_frame_case(server: LiveServer, samples: Samples, case: GrpcFrameCase) -> None:
    target = grpc_target(server)
    cameras_before = registry(target)
    request, expect = case.request(samples), case.expect
    # Unary.
    if expect.code == grpc.StatusCode.OK:
        response = localizer(target, detect(request))
        assert response.status == Status.OK
        if expect.person:
            assert_person(response)
    else:
        assert_refused(refused(target, detect(request)), expect)
    # The same frame on a stream, then a good frame of the demo camera on the same stream.
    if expect.ends_stream:
        # Alone on its stream: a frame written after the end could hide the status (see
        # stream_refusal); a new stream is served.
        with pytest.raises(grpc.aio.AioRpcError) as caught:
            stream_all(target, [request])
        assert_refused(caught.value, expect)
        assert_person(stream_all(target, [good_request(samples, "good-after")])[0])
    else:
        answers = {answer.frame_id: answer
                   for answer in stream_all(target, [request, good_request(samples, "good-after")])}
        assert set(answers) == {request.frame_id, "good-after"}
        answer = answers[request.frame_id]
        assert answer.camera_id == request.camera_id
        if expect.code == grpc.StatusCode.OK:
            assert answer.status == Status.OK
            if expect.person:
                assert_person(answer)
        else:
            assert Status.Name(answer.status) == "ERROR" and answer.error_code == expect.error_code
            assert expect.message in answer.error_message and not answer.detections
        assert_person(answers["good-after"])  # the stream went on
    assert_unharmed(target, samples, cameras_before)


def demo_replacement(camera: pb.Camera) -> pb.Camera:
    """`camera` with the id of the demo camera: a bad replacement must leave demo as it was."""
    replacement = pb.Camera()
    replacement.CopyFrom(camera)
    replacement.id = "demo"
    return replacement


@pytest.mark.parametrize("case", GRPC_CAMERA_CASES, ids=[case.name for case in GRPC_CAMERA_CASES])
def test_grpc_camera_case(server: LiveServer, samples: Samples, case: GrpcCameraCase) -> None:
    target = grpc_target(server)
    cameras_before = registry(target)
    if case.camera is not None:
        camera = case.camera()
        calls = [put(camera)] if case.id_case else [put(camera), put(demo_replacement(camera))]
    else:
        assert case.camera_id is not None
        calls = [get(case.camera_id), delete(case.camera_id)]
    for call in calls:
        assert_refused(refused(target, call), case.expect)
    assert_unharmed(target, samples, cameras_before)


def test_a_valid_camera_is_still_written(server: LiveServer, samples: Samples) -> None:
    """The reference for the camera cases: the same message without its fault is stored and read
    back, then deleted."""
    target = grpc_target(server)
    cameras_before = registry(target)
    camera = camera_message(id="grpc-valid")
    written = localizer(target, put(camera))
    assert isinstance(written, pb.PutCameraResponse) and written.created
    assert localizer(target, get("grpc-valid")) == camera
    localizer(target, delete("grpc-valid"))
    assert_unharmed(target, samples, cameras_before)
