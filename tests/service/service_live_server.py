"""A real FishLoc service (uvicorn on a free loopback port) running in a background thread."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import httpx

from service.core.config import Settings
from service.http.dependencies import ServiceState
from service.server import Service, build_state


class LiveServer:
    """Start with `start()`, stop with `stop()`; `url` is the REST base URL."""

    def __init__(self, settings: Settings, warm_up: bool = True) -> None:
        self.settings = settings
        self.warm_up = warm_up
        self._thread = threading.Thread(target=self._run, name="live-server", daemon=True)
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self.service: Service | None = None

    @property
    def state(self) -> ServiceState:
        assert self.service is not None
        return self.service.state

    @property
    def url(self) -> str:
        assert self.service is not None
        return f"http://127.0.0.1:{self.service.http_port}"

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as error:  # reported to the starting thread
            self._error = error
            self._started.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        self.service = Service(build_state(self.settings), warm_up=self.warm_up)
        await self.service.start()
        self._started.set()
        await self._stop.wait()
        await self.service.stop()

    def start(self, wait_ready: bool = True) -> LiveServer:
        self._thread.start()
        if not self._started.wait(60):
            raise TimeoutError("the service did not start")
        if self._error is not None:
            raise self._error
        if wait_ready:
            self.wait_ready()
        return self

    def wait_ready(self, timeout_s: float = 60) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if httpx.get(f"{self.url}/readyz").status_code == 200:
                return
            time.sleep(0.02)
        raise TimeoutError("the service did not become ready")

    def stop(self) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(60)

    def __enter__(self) -> LiveServer:
        return self.start()

    def __exit__(self, *_exc: Any) -> None:
        self.stop()


def free_port() -> int:
    """A loopback TCP port that is free right now."""
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_until_ready(url: str, process: Any = None, timeout_s: float = 120) -> None:
    """Poll `url`/readyz until it answers 200; TimeoutError past `timeout_s` (a bound, not an
    assertion on time), RuntimeError when `process` (a Popen) exits first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            raise RuntimeError(f"the server exited with code {process.returncode} before it was ready")
        try:
            if httpx.get(f"{url}/readyz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.05)
    raise TimeoutError(f"{url} did not become ready")
