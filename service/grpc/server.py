"""The gRPC front end: `fishloc.v1.Localizer` over the shared pipeline, with health and reflection.

Thin adapters over the same runner and registry as REST. Unary failures are gRPC status codes;
streamed frames are answered per frame (see protos/fishloc/v1/localizer.proto and grpc_stream).
"""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import AsyncIterator
from typing import Any, NoReturn

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from fisheye import CalibrationError, FisheyeCamera
from fisheye.camera import CAMERA_ID_PATTERN
from fisheye.view_plan import ViewPlanError
from protos.fishloc.v1 import localizer_pb2 as pb
from protos.fishloc.v1 import localizer_pb2_grpc as pb_grpc
from service.core.capture_time import CaptureTimeError, check_unix_s
from service.core.tls import TlsFiles
from service.frame_decode import FrameError
from service.grpc.convert import (
    camera_to_message,
    message_to_camera,
    model_to_message,
    occupancy_to_message,
    response_for,
    result_to_response,
)
from service.grpc.stream import FrameStream
from service.http.dependencies import ServiceState, bearer_matches, read_token_passes
from service.pipeline import ViewBudgetError
from service.result import DetectionResult
from service.runner import OverloadedError
from service.sites.interface import SitesUnavailableError
from sites.layout import NAME_PATTERN

log = logging.getLogger(__name__)

SERVICE_NAME = pb.DESCRIPTOR.services_by_name["Localizer"].full_name
Status = pb.DetectResponse.Status
_ADMIT_POLL_S = 0.005
MAX_FRAME_ID_CHARS = 128  # as REST's frame_id query parameter
_SHOWN_ID_CHARS = 64


async def _abort(context: grpc.aio.ServicerContext, code: grpc.StatusCode, message: str) -> NoReturn:
    await context.abort(code, message)
    raise AssertionError("context.abort returned")  # it raises; this tells the type checker


def _authorization(context: grpc.aio.ServicerContext) -> str:
    """The `authorization` metadata of a call ('' when absent)."""
    for key, value in context.invocation_metadata() or ():
        if key == "authorization":
            return str(value)
    return ""


class _FrameRefusedError(Exception):
    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = message


def _shown(camera_id: str) -> str:
    """An id as an error message may quote it: a 10 kB id in a status's details would pass the
    client's metadata limit, and the client would see RESOURCE_EXHAUSTED instead of the error."""
    if len(camera_id) <= _SHOWN_ID_CHARS:
        return repr(camera_id)
    return f"{camera_id[:_SHOWN_ID_CHARS]!r}... ({len(camera_id)} characters)"


def check_camera_id(camera_id: str) -> None:
    """Refuse an id no camera can have, as REST's path pattern does (`invalid_request`)."""
    if re.fullmatch(CAMERA_ID_PATTERN, camera_id) is None:
        raise _FrameRefusedError(
            "invalid_request",
            f"camera_id {_shown(camera_id)} must be 1-64 characters of letters, digits, '.', '_' or '-', "
            "starting with a letter or digit",
        )


def check_frame_id(frame_id: str) -> None:
    if len(frame_id) > MAX_FRAME_ID_CHARS:
        raise _FrameRefusedError("invalid_request", f"frame_id must be at most {MAX_FRAME_ID_CHARS} "
                                                    f"characters, got {len(frame_id)}")


def server_options(max_message_bytes: int) -> list[tuple[str, Any]]:
    """Channel options of the server: message limits and keepalive for long-lived camera streams."""
    return [
        ("grpc.max_receive_message_length", max_message_bytes),
        ("grpc.max_send_message_length", max_message_bytes),
        ("grpc.so_reuseport", 0),  # a second server on a taken port must fail, not share it
        ("grpc.keepalive_time_ms", 20_000),  # ping idle gateways to notice dead connections
        ("grpc.keepalive_timeout_ms", 10_000),
        ("grpc.keepalive_permit_without_calls", 1),
        ("grpc.http2.min_recv_ping_interval_without_data_ms", 5_000),  # gateways may ping every 5 s
        ("grpc.http2.max_ping_strikes", 2),
    ]


class LocalizerServicer:
    """fishloc.v1.Localizer."""

    def __init__(self, state: ServiceState, stopping: asyncio.Event) -> None:
        self.state = state
        self.stopping = stopping

    # ----- detection

    async def _camera(self, request: pb.DetectRequest) -> FisheyeCamera:
        """The request's camera, once its camera_id and frame_id are known to be well formed."""
        camera_id = request.camera_id
        check_camera_id(camera_id)
        check_frame_id(request.frame_id)
        camera = await asyncio.to_thread(self.state.registry.get, camera_id)
        if camera is None:
            raise _FrameRefusedError("camera_not_found", f"no camera {camera_id!r} in the registry")
        return camera

    def _capture_time(self, request: pb.DetectRequest) -> float | None:
        if not request.HasField("capture_time"):
            return None
        stamp = request.capture_time
        try:
            return check_unix_s(stamp.seconds + stamp.nanos * 1e-9)
        except CaptureTimeError as error:
            raise _FrameRefusedError("invalid_capture_time", str(error)) from None

    def _min_score(self, request: pb.DetectRequest) -> float | None:
        if not request.HasField("min_score"):
            return None
        if not 0.0 <= request.min_score <= 1.0:
            raise _FrameRefusedError("invalid_request",
                                     f"min_score must be within [0, 1], got {request.min_score}")
        return request.min_score

    async def _require_detect_token(self, context: grpc.aio.ServicerContext) -> None:
        settings = self.state.settings
        if settings.detect_token is None:
            return
        tokens = [settings.detect_token] + ([settings.api_token] if settings.api_token is not None else [])
        if not bearer_matches(_authorization(context), tokens):
            await _abort(context, grpc.StatusCode.UNAUTHENTICATED,
                         "detection needs 'authorization: Bearer <token>'")

    async def Detect(self, request: pb.DetectRequest, context: grpc.aio.ServicerContext) -> pb.DetectResponse:  # noqa: N802
        await self._require_detect_token(context)
        runner = self.state.runner
        if not runner.ready:
            await _abort(context, grpc.StatusCode.UNAVAILABLE, "not_ready: the model is warming up")
        try:
            camera = await self._camera(request)
            result = await runner.detect(request.image, camera, min_score=self._min_score(request),
                                         frame_id=request.frame_id or None, frontend="grpc",
                                         capture_time=self._capture_time(request))
        except _FrameRefusedError as error:
            not_found = error.code == "camera_not_found"
            status = grpc.StatusCode.NOT_FOUND if not_found else grpc.StatusCode.INVALID_ARGUMENT
            await _abort(context, status, f"{error.code}: {error.message}")
        except FrameError as error:
            await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, f"{error.code}: {error.message}")
        except OverloadedError as error:
            await _abort(context, grpc.StatusCode.RESOURCE_EXHAUSTED, f"overloaded: {error}")
        return result_to_response(result, request)

    async def _stream_frame(self, request: pb.DetectRequest) -> pb.DetectResponse:
        runner = self.state.runner
        try:
            if not runner.ready:
                raise _FrameRefusedError("not_ready", "the model is warming up")
            camera = await self._camera(request)
            min_score = self._min_score(request)
            capture_time = self._capture_time(request)
            # A lane holds one frame at a time, so waiting for room here is bounded per stream;
            # newer frames of this camera meanwhile replace the waiting one (DROPPED).
            while not runner.try_admit():
                await asyncio.sleep(_ADMIT_POLL_S)
            try:
                result: DetectionResult = await runner.run_admitted(
                    request.image, camera, min_score=min_score, frame_id=request.frame_id or None,
                    frontend="grpc-stream", capture_time=capture_time,
                )
            finally:
                runner.release()
        except _FrameRefusedError as error:
            return response_for(request, Status.ERROR, error.code, error.message)
        except FrameError as error:
            return response_for(request, Status.ERROR, error.code, error.message)
        return result_to_response(result, request)

    async def StreamDetect(self, request_iterator: AsyncIterator[pb.DetectRequest],  # noqa: N802
                           context: grpc.aio.ServicerContext) -> AsyncIterator[pb.DetectResponse]:
        await self._require_detect_token(context)
        stream = FrameStream(request_iterator, self._stream_frame, self.stopping,
                             on_drop=self.state.metrics.count_dropped)
        async for response in stream.responses():
            yield response
        log.info("stream ended: %d frames, %d answered, %d dropped", stream.counts.received,
                 stream.counts.answered, stream.counts.dropped)

    # ----- registry and model

    async def _require_token(self, context: grpc.aio.ServicerContext) -> None:
        token = self.state.settings.api_token
        if token is None:
            return
        if not bearer_matches(_authorization(context), [token]):
            await _abort(context, grpc.StatusCode.UNAUTHENTICATED,
                         "registry writes need 'authorization: Bearer <token>'")

    async def ListCameras(self, request: pb.ListCamerasRequest,  # noqa: N802
                          context: grpc.aio.ServicerContext) -> pb.ListCamerasResponse:
        cameras = await asyncio.to_thread(self.state.registry.all)
        return pb.ListCamerasResponse(cameras=[camera_to_message(camera) for camera in cameras])

    async def _require_camera_id(self, camera_id: str, context: grpc.aio.ServicerContext) -> None:
        try:
            check_camera_id(camera_id)
        except _FrameRefusedError as error:
            await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, f"{error.code}: {error.message}")

    async def GetCamera(self, request: pb.GetCameraRequest, context: grpc.aio.ServicerContext) -> pb.Camera:  # noqa: N802
        await self._require_camera_id(request.camera_id, context)
        camera = await asyncio.to_thread(self.state.registry.get, request.camera_id)
        if camera is None:
            await _abort(context, grpc.StatusCode.NOT_FOUND, f"no camera {request.camera_id!r}")
        return camera_to_message(camera)

    async def PutCamera(self, request: pb.PutCameraRequest,  # noqa: N802
                        context: grpc.aio.ServicerContext) -> pb.PutCameraResponse:
        await self._require_token(context)
        try:
            camera = message_to_camera(request.camera)
        except CalibrationError as error:
            await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, str(error))
        try:  # nothing is saved for a view that cannot be planned or a budget over the limit
            await asyncio.to_thread(self.state.runner.pipeline.admit, camera)
        except ViewPlanError as error:
            code = "view_budget_over_limit" if isinstance(error, ViewBudgetError) else "view_unplannable"
            await _abort(context, grpc.StatusCode.INVALID_ARGUMENT, f"{code}: camera {camera.id}: {error}")
        outcome = await asyncio.to_thread(self.state.registry.put, camera)
        await asyncio.to_thread(self.state.sites.camera_changed, camera.id, outcome.camera)
        return pb.PutCameraResponse(camera=camera_to_message(outcome.camera), created=outcome.created)

    async def DeleteCamera(self, request: pb.DeleteCameraRequest,  # noqa: N802
                           context: grpc.aio.ServicerContext) -> pb.DeleteCameraResponse:
        await self._require_token(context)
        await self._require_camera_id(request.camera_id, context)
        if not await asyncio.to_thread(self.state.registry.delete, request.camera_id):
            await _abort(context, grpc.StatusCode.NOT_FOUND, f"no camera {request.camera_id!r}")
        await asyncio.to_thread(self.state.sites.camera_changed, request.camera_id, None)
        return pb.DeleteCameraResponse()

    async def GetModel(self, request: pb.GetModelRequest, context: grpc.aio.ServicerContext) -> pb.ModelInfo:  # noqa: N802
        return model_to_message(self.state.runner.pipeline.info)

    # ----- sites

    async def WatchSite(self, request: pb.WatchSiteRequest,  # noqa: N802
                        context: grpc.aio.ServicerContext) -> AsyncIterator[pb.SiteOccupancy]:
        if not read_token_passes(self.state, _authorization(context)):
            await _abort(context, grpc.StatusCode.UNAUTHENTICATED,
                         "site reads need 'authorization: Bearer <token>'")
        site_id = request.site
        if re.fullmatch(NAME_PATTERN, site_id) is None:
            await _abort(context, grpc.StatusCode.INVALID_ARGUMENT,
                         f"invalid_request: site {_shown(site_id)} is not a site id")
        if site_id not in await asyncio.to_thread(self.state.site_store.site_cameras):
            await _abort(context, grpc.StatusCode.NOT_FOUND,
                         f"site_not_found: no camera names site {site_id!r}")
        sites = self.state.sites
        try:
            watcher = await sites.subscribe(site_id)
        except SitesUnavailableError as error:
            await _abort(context, grpc.StatusCode.UNAVAILABLE, f"sites_unavailable: {error}")
        try:
            async for update in watcher.updates():
                yield occupancy_to_message(update)
        finally:
            sites.unwatch(site_id, watcher)


class GrpcFrontEnd:
    """The grpc.aio server: Localizer, health (following readiness) and reflection."""

    def __init__(self, state: ServiceState, tls: TlsFiles | None = None) -> None:
        self.state = state
        self.stopping = asyncio.Event()
        settings = state.settings
        self.server = grpc.aio.server(options=server_options(settings.grpc_max_message_bytes))
        pb_grpc.add_LocalizerServicer_to_server(LocalizerServicer(state, self.stopping), self.server)
        self.health = health.aio.HealthServicer()
        health_pb2_grpc.add_HealthServicer_to_server(self.health, self.server)
        reflection.enable_server_reflection(
            (SERVICE_NAME, health_pb2.DESCRIPTOR.services_by_name["Health"].full_name,
             reflection.SERVICE_NAME), self.server,
        )
        address = f"{settings.host}:{settings.grpc_port}"
        if tls is None:
            self.port = self.server.add_insecure_port(address)
        else:
            credentials = grpc.ssl_server_credentials([(tls.key_pem, tls.cert_pem)])
            self.port = self.server.add_secure_port(address, credentials)
        if self.port == 0:
            raise RuntimeError(f"cannot listen for gRPC on {settings.host}:{settings.grpc_port}")
        self._readiness: asyncio.Task[None] | None = None

    async def _follow_readiness(self) -> None:
        while not self.state.runner.ready:
            await asyncio.sleep(0.05)
        for name in ("", SERVICE_NAME):
            await self.health.set(name, health_pb2.HealthCheckResponse.SERVING)

    async def start(self) -> None:
        for name in ("", SERVICE_NAME):
            await self.health.set(name, health_pb2.HealthCheckResponse.NOT_SERVING)
        await self.server.start()
        self._readiness = asyncio.create_task(self._follow_readiness())
        log.info("gRPC listening on %s:%d", self.state.settings.host, self.port)

    async def stop(self, grace_s: float = 10.0) -> None:
        """Refuse new calls, let streams answer their frames in flight, then close."""
        if self._readiness is not None:
            self._readiness.cancel()
        await self.health.enter_graceful_shutdown()
        self.stopping.set()
        await self.server.stop(grace_s)
