"""One FishLoc service instance: the state (model, registry, metrics) and the servers over it.

`Service.start()` serves REST (uvicorn) and gRPC (grpc.aio) side by side on the running event loop;
`Service.stop()` shuts both down after answering the requests and streamed frames in flight.
`fishloc serve` and the tests both use it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import socket
from collections.abc import Iterator

import uvicorn

from fisheye import load_cameras
from service.cameras import CameraRegistry
from service.core.config import Settings
from service.core.metrics import ServiceMetrics
from service.core.tls import TlsFiles, tls_from_settings
from service.grpc.server import GrpcFrontEnd
from service.http.app import create_app
from service.http.dependencies import ServiceState
from service.http.protocol import head_deadline_protocol
from service.outputs.attach import attach_outputs
from service.outputs.build import build_outputs
from service.runner import build_runner
from service.sites.hub import SiteHub
from service.sites.interface import Sites
from service.sites.store import SiteStore

log = logging.getLogger(__name__)

DEMO_SEED_KEY = "seeded:demo"


class _HttpServer(uvicorn.Server):
    """uvicorn without its own signal handling: `run_service` stops REST and gRPC together (uvicorn
    would re-raise the signal after its own shutdown and kill the process before gRPC's)."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


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
    site_store = SiteStore(registry)
    outputs = build_outputs(settings, registry.engine, metrics)
    sites: Sites
    if settings.sites_bus is not None:
        from service.sites.bus_hub import BusSiteHub  # redis-py is an extra: imported only with a bus

        # The outputs run where the trackers do, in the `fishloc sites` workers: one of each
        # crossing, not one per replica. This replica serves their routes from the database.
        sites = BusSiteHub(settings.sites_bus, site_store, metrics, wait_s=settings.sites_bus_wait_s)
    else:
        hub = SiteHub(site_store, metrics)
        attach_outputs(outputs.dispatcher, hub, site_store)
        sites = hub
    sites.attach(runner)
    return ServiceState(settings=settings, runner=runner, registry=registry, metrics=metrics,
                        site_store=site_store, sites=sites, outputs=outputs)


class Service:
    """REST beside gRPC over one ServiceState, on the running event loop."""

    def __init__(self, state: ServiceState, warm_up: bool = True) -> None:
        self.state = state
        self.warm_up = warm_up
        self._http: uvicorn.Server | None = None
        self._http_task: asyncio.Task[None] | None = None
        self.tls: TlsFiles | None = None
        self.grpc: GrpcFrontEnd | None = None

    @property
    def http_port(self) -> int:
        if self._http is None or not self._http.servers:
            raise RuntimeError("the HTTP server is not running")
        port: int = self._http.servers[0].sockets[0].getsockname()[1]
        return port

    @property
    def grpc_port(self) -> int:
        if self.grpc is None:
            raise RuntimeError("gRPC is not running")
        return self.grpc.port

    async def start(self) -> None:
        settings = self.state.settings
        self.tls = tls_from_settings(settings)  # TlsError before anything listens
        await self.state.sites.start()  # BusError before anything listens
        if settings.sites_bus is None:
            await self.state.outputs.dispatcher.start()
        try:
            await self._serve(settings)
        except BaseException:
            await self.state.outputs.dispatcher.close()
            await self.state.sites.stop()
            raise

    async def _serve(self, settings: Settings) -> None:
        if settings.grpc_port >= 0:
            self.grpc = GrpcFrontEnd(self.state, tls=self.tls)
            await self.grpc.start()
        config = uvicorn.Config(
            create_app(self.state, warm_up=self.warm_up), host=settings.host, port=settings.http_port,
            log_config=None, access_log=False, lifespan="on", timeout_graceful_shutdown=30,
            http=head_deadline_protocol(settings.head_timeout_s),
            timeout_keep_alive=settings.keep_alive_timeout_s,
            ssl_certfile=self.tls.cert_path if self.tls else None,
            ssl_keyfile=self.tls.key_path if self.tls else None,
        )
        try:
            # Bound here so that a taken port is a clear OSError, not uvicorn's sys.exit.
            family = socket.AF_INET6 if ":" in settings.host else socket.AF_INET
            sock = socket.create_server((settings.host, settings.http_port), family=family)
        except OSError as error:
            if self.grpc is not None:
                await self.grpc.stop(grace_s=0)
            where = f"{settings.host}:{settings.http_port}"
            raise OSError(f"cannot listen for REST on {where}: {error.strerror}") from None
        self._http = _HttpServer(config)
        self._http_task = asyncio.create_task(self._http.serve(sockets=[sock]))
        while not self._http.started:
            if self._http_task.done():
                if self.grpc is not None:
                    await self.grpc.stop(grace_s=0)
                # uvicorn logs the cause (e.g. the port is taken) and exits its task.
                raise RuntimeError(f"the HTTP server did not start on {settings.host}:{settings.http_port}")
            await asyncio.sleep(0.01)
        scheme = "https" if self.tls else "http"
        log.info("REST listening on %s://%s:%d", scheme, settings.host, self.http_port)

    async def wait(self) -> None:
        """Until the HTTP server exits (SIGINT/SIGTERM in the main thread, or `stop`)."""
        if self._http_task is not None:
            await asyncio.shield(self._http_task)  # a waiter being cancelled must not stop the server

    async def stop(self) -> None:
        """Stop accepting, answer what is in flight, then release the model and the database."""
        self.state.sites.close()  # event streams end, so the HTTP server need not wait for them
        if self._http is not None:
            self._http.should_exit = True
        stopping = [self.wait()] if self.grpc is None else [self.grpc.stop(), self.wait()]
        await asyncio.gather(*stopping)
        await self.state.outputs.dispatcher.close()  # after the last frame: its update is written
        await self.state.sites.stop()
        self.state.runner.close()
        self.state.registry.close()


async def run_service(settings: Settings) -> None:
    """Serve until SIGINT or SIGTERM, then shut down gracefully."""
    service = Service(build_state(settings))
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await service.start()
    try:
        waiters = {asyncio.create_task(stop.wait()), asyncio.create_task(service.wait())}
        _, pending = await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
        for task in pending:
            task.cancel()
        log.info("shutting down: answering what is in flight")
    finally:
        await service.stop()
    log.info("stopped")
