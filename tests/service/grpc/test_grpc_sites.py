"""Sites over gRPC on a real server: track ids and capture_time on Detect, the read token of WatchSite."""

from __future__ import annotations

from collections.abc import Callable

import grpc
import httpx
import pytest
from service_live_server import LiveServer
from service_sites import MIN_SCORE, POSES, SITE, T0, frame_of, site_camera_record

from fisheye import FisheyeCamera
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.config import Settings
from service.grpc.convert import response_to_json


def _request(demo: FisheyeCamera, camera_id: str, seconds: int, nanos: int = 0) -> pb.DetectRequest:
    request = pb.DetectRequest(camera_id=camera_id, frame_id=str(seconds), min_score=MIN_SCORE,
                               image=frame_of(demo, camera_id, (0.0, 0.5)))
    request.capture_time.seconds = seconds
    request.capture_time.nanos = nanos
    return request


def test_grpc_detections_carry_track_ids_and_follow_capture_time(
        settings_for: Callable[..., Settings], demo_camera: FisheyeCamera) -> None:
    settings = settings_for(grpc_port=0, host="127.0.0.1", read_token="reader")
    with LiveServer(settings) as server, httpx.Client(base_url=server.url, timeout=30) as client:
        for camera_id in POSES:
            client.put(f"/v1/cameras/{camera_id}", json=site_camera_record(demo_camera, camera_id))
        target = f"127.0.0.1:{server.service.grpc_port}"  # type: ignore[union-attr]
        with grpc.insecure_channel(target) as channel:
            stub = pb_grpc.LocalizerStub(channel)
            ids = []
            for step in range(4):
                for camera_id in POSES:
                    answer = stub.Detect(_request(demo_camera, camera_id, int(T0), nanos=step * 200_000_000))
                    assert answer.capture_time.nanos == step * 200_000_000
                    ids.append(response_to_json(answer)["detections"][0]["track_id"])
            # Confirmed at its second capture time (TrackerConfig.min_hits 2).
            assert ids[:2] == [None] * 2 and set(ids[2:]) == {f"{SITE}:1"}
            assert stub.GetCamera(pb.GetCameraRequest(camera_id="cam-a")).site == SITE
            with pytest.raises(grpc.RpcError) as bad_time:
                stub.Detect(_request(demo_camera, "cam-a", -5))
            assert bad_time.value.code() == grpc.StatusCode.INVALID_ARGUMENT
            assert bad_time.value.details().startswith("invalid_capture_time:")
            with pytest.raises(grpc.RpcError) as refused:
                list(stub.WatchSite(pb.WatchSiteRequest(site=SITE), timeout=10))
            assert refused.value.code() == grpc.StatusCode.UNAUTHENTICATED
            watch = stub.WatchSite(pb.WatchSiteRequest(site=SITE), timeout=10,
                                   metadata=[("authorization", "Bearer reader")])
            first = next(watch)
            watch.cancel()
            assert first.count == 1 and first.people[0].track_id == f"{SITE}:1"
            assert first.time == pytest.approx(T0 + 0.6)
        occupancy = client.get(f"/v1/sites/{SITE}/occupancy", headers={"Authorization": "Bearer reader"})
        assert occupancy.json()["time"] == pytest.approx(T0 + 0.6)  # the refused frame changed nothing
