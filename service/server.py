"""One FishLoc service instance: the state (model, registry, metrics) and the servers over it.

`Service.start()` serves REST (uvicorn) on the running event loop; `Service.stop()` shuts it down
after answering the requests in flight. `fishloc serve` and the tests both use it.
"""

from __future__ import annotations

import asyncio
import logging

import uvicorn

from fisheye import load_cameras
from service.app import create_app
from service.cameras import CameraRegistry
from service.config import Settings
from service.dependencies import ServiceState
from service.http_protocol import head_deadline_protocol
from service.metrics import ServiceMetrics
from service.runner import build_runner
from service.tls import TlsFiles, tls_from_settings

log = logging.getLogger(__name__)

DEMO_SEED_KEY = "seeded:demo"


def build_state(settings: Settings) -> ServiceState:
    """Load the model (ModelError) and open and seed the camera registry (CalibrationError)."""
    metrics = ServiceMetrics()
    runner = build_runner(settings, metrics)
    registry = CameraRegistry(settings.database)
    try:
        if settings.demo_camera:
            registry.seed_once(DEMO_SEED_KEY, settings.demo_camera_path)
        if settings.cameras is not None:
            registry.seed(load_cameras(settings.cameras), str(settings.cameras))
    except Exception:
        registry.close()
        runner.close()
        raise
    return ServiceState(settings=settings, runner=runner, registry=registry, metrics=metrics)


class Service:
    """REST beside (later) gRPC, over one ServiceState, on the running event loop."""

    def __init__(self, state: ServiceState, warm_up: bool = True) -> None:
        self.state = state
        self.warm_up = warm_up
        self._http: uvicorn.Server | None = None
        self._http_task: asyncio.Task[None] | None = None
        self.tls: TlsFiles | None = None

    @property
    def http_port(self) -> int:
        if self._http is None or not self._http.servers:
            raise RuntimeError("the HTTP server is not running")
        port: int = self._http.servers[0].sockets[0].getsockname()[1]
        return port

    async def start(self) -> None:
        settings = self.state.settings
        self.tls = tls_from_settings(settings)  # TlsError before anything listens
        config = uvicorn.Config(
            create_app(self.state, warm_up=self.warm_up), host=settings.host, port=settings.http_port,
            log_config=None, access_log=False, lifespan="on", timeout_graceful_shutdown=30,
            http=head_deadline_protocol(settings.head_timeout_s),
            timeout_keep_alive=settings.keep_alive_timeout_s,
            ssl_certfile=self.tls.cert_path if self.tls else None,
            ssl_keyfile=self.tls.key_path if self.tls else None,
        )
        self._http = uvicorn.Server(config)
        self._http_task = asyncio.create_task(self._http.serve())
        while not self._http.started:
            if self._http_task.done():
                await self._http_task  # raises what made start-up fail
                raise RuntimeError(f"the HTTP server did not start on {settings.host}:{settings.http_port}")
            await asyncio.sleep(0.01)
        scheme = "https" if self.tls else "http"
        log.info("REST listening on %s://%s:%d", scheme, settings.host, self.http_port)

    async def wait(self) -> None:
        """Until the HTTP server exits (SIGINT/SIGTERM in the main thread, or `stop`)."""
        if self._http_task is not None:
            await self._http_task

    async def stop(self) -> None:
        """Stop accepting, answer what is in flight, then release the model and the database."""
        if self._http is not None:
            self._http.should_exit = True
        await self.wait()
        self.state.runner.close()
        self.state.registry.close()


async def run_service(settings: Settings) -> None:
    """Serve until interrupted."""
    service = Service(build_state(settings))
    await service.start()
    try:
        await service.wait()
    finally:
        await service.stop()
