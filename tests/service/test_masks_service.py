"""Camera masks against real servers: a detection whose foot point lies in a mask is dropped over REST
and gRPC (and counted), masks survive a restart, and a bad mask is refused. The model is the plumbing
test double (see service_doubles)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import grpc
import httpx
import numpy as np
import pytest
from service_frames import encode, person_frame
from service_live_server import LiveServer

from fisheye import FisheyeCamera, camera_to_dict
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.config import Settings
from service.grpc.convert import camera_to_message

FRAME_WH = (1024, 1024)
PERSON_XY_M = (1.5, 1.0)


def person(demo_camera: FisheyeCamera) -> tuple[bytes, np.ndarray]:
    """A frame with one person, and its foot point at the camera's image_size (px)."""
    frame = person_frame(demo_camera, PERSON_XY_M, FRAME_WH, disk_radius_px=20)
    return encode(frame.bgr), demo_camera.floor_to_pixels(np.array([PERSON_XY_M]))[0]


def square_around(point_px: np.ndarray, half_px: float) -> list[list[float]]:
    u, v = float(point_px[0]), float(point_px[1])
    return [[u - half_px, v - half_px], [u + half_px, v - half_px], [u + half_px, v + half_px],
            [u - half_px, v + half_px]]


def masked_record(demo_camera: FisheyeCamera, mask: list[list[float]]) -> dict[str, Any]:
    return camera_to_dict(demo_camera) | {"id": "mirror", "masks_px": [mask]}


def positions(answer: dict[str, Any]) -> list[list[float]]:
    return [d["position_m"] for d in answer["detections"]]


def rest_detect(server: LiveServer, camera_id: str, frame: bytes) -> dict[str, Any]:
    response = httpx.post(f"{server.url}/v1/cameras/{camera_id}/detect", content=frame,
                          headers={"content-type": "image/jpeg"})
    assert response.status_code == 200, response.text
    return dict(response.json())


def masked_count(server: LiveServer, camera_id: str) -> float:
    for line in httpx.get(f"{server.url}/metrics").text.splitlines():
        if line.startswith(f'fishloc_masked_detections_total{{camera_id="{camera_id}"}}'):
            return float(line.split()[-1])
    return 0.0


def near_person(answer: dict[str, Any]) -> bool:
    return any(p is not None and np.hypot(p[0] - PERSON_XY_M[0], p[1] - PERSON_XY_M[1]) < 0.1
               for p in positions(answer))


def test_a_masked_person_is_dropped_over_rest_and_grpc(settings_for: Callable[..., Settings],
                                                       demo_camera: FisheyeCamera) -> None:
    frame, foot_px = person(demo_camera)
    with LiveServer(settings_for(grpc_port=0, host="127.0.0.1")) as server:
        assert httpx.put(f"{server.url}/v1/cameras/mirror",
                         json=masked_record(demo_camera, square_around(foot_px, 60.0))).status_code == 201
        unmasked = rest_detect(server, "demo", frame)
        masked = rest_detect(server, "mirror", frame)
        assert near_person(unmasked) and not near_person(masked)
        # Only the person in the mask is gone: the double's other (constant) box is still there.
        assert len(masked["detections"]) == len(unmasked["detections"]) - 1 >= 1
        assert masked_count(server, "mirror") == 1.0 and masked_count(server, "demo") == 0.0

        async def grpc_detect() -> tuple[pb.DetectResponse, pb.Camera]:
            assert server.service is not None
            async with grpc.aio.insecure_channel(f"127.0.0.1:{server.service.grpc_port}") as channel:
                stub = pb_grpc.LocalizerStub(channel)
                response = await stub.Detect(pb.DetectRequest(camera_id="mirror", frame_id="1", image=frame))
                return response, await stub.GetCamera(pb.GetCameraRequest(camera_id="mirror"))

        response, camera = asyncio.run(grpc_detect())
        assert response.status == pb.DetectResponse.Status.OK
        assert len(response.detections) == len(masked["detections"])
        assert masked_count(server, "mirror") == 2.0
        assert [[p.x, p.y] for p in camera.masks_px[0].points] == square_around(foot_px, 60.0)


def test_a_mask_elsewhere_drops_nothing(live_server: LiveServer, demo_camera: FisheyeCamera) -> None:
    frame, foot_px = person(demo_camera)
    record = masked_record(demo_camera, square_around(foot_px + 300.0, 60.0))
    assert httpx.put(f"{live_server.url}/v1/cameras/mirror", json=record).status_code == 201
    expected = positions(rest_detect(live_server, "demo", frame))
    assert positions(rest_detect(live_server, "mirror", frame)) == expected
    assert masked_count(live_server, "mirror") == 0.0


def test_masks_and_tilt_survive_a_restart(settings_for: Callable[..., Settings],
                                          demo_camera: FisheyeCamera) -> None:
    settings = settings_for()
    frame, foot_px = person(demo_camera)
    record = masked_record(demo_camera, square_around(foot_px, 60.0)) | {"tilt_deg": [1.0, -0.5]}
    with LiveServer(settings) as first:
        assert httpx.put(f"{first.url}/v1/cameras/mirror", json=record).status_code == 201
    with LiveServer(settings) as second:  # the same database, a new server
        stored = httpx.get(f"{second.url}/v1/cameras/mirror").json()
        assert stored["masks_px"] == record["masks_px"] and stored["tilt_deg"] == [1.0, -0.5]
        assert not near_person(rest_detect(second, "mirror", frame))
        assert masked_count(second, "mirror") == 1.0


BAD_MASKS = [
    ([[0.0, 0.0], [100.0, 100.0], [100.0, 0.0], [0.0, 100.0]], "mask 1: the polygon intersects itself"),
    ([[0.0, 0.0], [100.0, 0.0], [200.0, 0.0]], "mask 1: the polygon has no area"),
    ([[0.0, 0.0], [100.0, 0.0]], "mask 1: a polygon needs at least 3 corners"),
    ([[0.0, 0.0], [3000.0, 0.0], [0.0, 100.0]], "lies outside the image 2048x2048"),
]


@pytest.mark.parametrize(("mask", "message"), BAD_MASKS)
def test_bad_masks_are_refused_over_rest_and_grpc(settings_for: Callable[..., Settings],
                                                  demo_camera: FisheyeCamera, mask: list[list[float]],
                                                  message: str) -> None:
    with LiveServer(settings_for(grpc_port=0, host="127.0.0.1")) as server:
        answer = httpx.put(f"{server.url}/v1/cameras/mirror", json=masked_record(demo_camera, mask))
        assert answer.status_code == 422
        error = answer.json()["error"]
        assert error["code"] == "invalid_camera" and message in error["message"]

        async def grpc_put() -> grpc.StatusCode:
            assert server.service is not None
            message_ = camera_to_message(demo_camera.model_copy(update={"id": "mirror"}))
            message_.masks_px.append(pb.Polygon(points=[pb.Point(x=u, y=v) for u, v in mask]))
            async with grpc.aio.insecure_channel(f"127.0.0.1:{server.service.grpc_port}") as channel:
                try:
                    await pb_grpc.LocalizerStub(channel).PutCamera(pb.PutCameraRequest(camera=message_))
                except grpc.aio.AioRpcError as error:
                    return error.code()
            return grpc.StatusCode.OK

        assert asyncio.run(grpc_put()) == grpc.StatusCode.INVALID_ARGUMENT
        assert httpx.get(f"{server.url}/v1/cameras/mirror").status_code == 404  # nothing was saved
