"""The real peers of the outputs in tests: a `mosquitto` broker on a free loopback port, an MQTT
subscriber (paho-mqtt) that keeps what it hears, a webhook receiver (http.server) that checks each
post's signature and refuses posts for its first seconds, and `fishloc serve` as a process."""

from __future__ import annotations

import getpass
import hashlib
import hmac
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import paho.mqtt.client as paho

from tests.ci_policy import skip_or_fail_in_ci

MOSQUITTO = Path("/usr/sbin/mosquitto")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_for(condition: Callable[[], Any], timeout_s: float, what: str, every_s: float = 0.1) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(every_s)
    raise AssertionError(f"timed out waiting for {what}")


@dataclass
class Broker:
    port: int
    process: subprocess.Popen[bytes]

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"


@contextmanager
def mosquitto(folder: Path, extra_config: str = "", port: int | None = None) -> Iterator[Broker]:
    """A mosquitto broker of its own config on a free loopback port (anonymous, no persistence)."""
    binary = MOSQUITTO if MOSQUITTO.exists() else shutil.which("mosquitto")
    if binary is None:
        skip_or_fail_in_ci("mosquitto is not installed (apt-get install mosquitto)")
    port = port or free_port()
    config = folder / f"mosquitto-{port}.conf"
    # `user`: a broker started as root stays this user, so it can read the test's own (0700) folders.
    config.write_text(f"user {getpass.getuser()}\nlistener {port} 127.0.0.1\nallow_anonymous true\n"
                      f"persistence false\n{extra_config}")
    process = subprocess.Popen([str(binary), "-c", str(config)], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        def listening() -> bool:
            with socket.socket() as probe:
                return probe.connect_ex(("127.0.0.1", port)) == 0

        wait_for(listening, 20, "mosquitto to listen")
        yield Broker(port, process)
    finally:
        process.terminate()
        process.wait(10)


class Subscriber:
    """An MQTT client subscribed to `topics`: the newest payload per topic, and every message."""

    def __init__(self, port: int, topics: tuple[str, ...] = ("#",)) -> None:
        self.port = port
        self.topics = topics
        self.latest: dict[str, str] = {}
        self.retained: dict[str, str] = {}
        self.messages: list[tuple[str, str]] = []
        self._lock = threading.Lock()
        self._client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id=f"test-{port}-{id(self)}")
        self._client.on_connect = self._on_connect
        self._client.on_message = self._on_message

    def _on_connect(self, client: paho.Client, _userdata: Any, _flags: Any, _reason: Any,
                    _properties: Any) -> None:
        for topic in self.topics:
            client.subscribe(topic, qos=1)

    def _on_message(self, _client: paho.Client, _userdata: Any, message: paho.MQTTMessage) -> None:
        payload = message.payload.decode("utf-8")
        with self._lock:
            self.latest[message.topic] = payload
            if message.retain:
                self.retained[message.topic] = payload
            self.messages.append((message.topic, payload))

    def events(self, topic: str) -> list[dict[str, Any]]:
        with self._lock:
            return [json.loads(payload) for t, payload in self.messages if t == topic]

    def __enter__(self) -> Subscriber:
        self._client.connect("127.0.0.1", self.port)
        self._client.loop_start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._client.disconnect()
        self._client.loop_stop()


@dataclass
class Receiver:
    """A webhook receiver on a free loopback port: refuses (503) every post for `refuse_s` after its
    first one, then accepts posts whose signature is right (401 otherwise)."""

    secret: str
    refuse_s: float = 0.0
    port: int = field(default_factory=free_port)
    accepted: dict[str, dict[str, Any]] = field(default_factory=dict)
    accepted_times: Counter[str] = field(default_factory=Counter)
    refused: int = 0
    bad_signatures: int = 0
    first_post: float | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook"

    def handle(self, body: bytes, signature: str) -> int:
        now = time.monotonic()
        self.first_post = self.first_post or now
        expected = "sha256=" + hmac.new(self.secret.encode(), body, hashlib.sha256).hexdigest()
        if not hmac.compare_digest(expected, signature):
            self.bad_signatures += 1
            return 401
        if now - self.first_post < self.refuse_s:
            self.refused += 1
            return 503
        event = json.loads(body)
        self.accepted[event["id"]] = event
        self.accepted_times[event["id"]] += 1
        return 200

    def of_type(self, kind: str) -> list[dict[str, Any]]:
        return [event for event in self.accepted.values() if event["type"] == kind]

    @contextmanager
    def running(self) -> Iterator[Receiver]:
        receiver = self
        lock = threading.Lock()

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers.get("Content-Length", "0")))
                with lock:
                    status = receiver.handle(body, self.headers.get("X-FishLoc-Signature", ""))
                self.send_response(status)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def log_message(self, *_args: Any) -> None:
                pass

        server = ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        thread = threading.Thread(target=server.serve_forever, daemon=True)
        thread.start()
        try:
            yield self
        finally:
            server.shutdown()
            server.server_close()


@contextmanager
def fishloc_serve(database: Path, *flags: str, env: dict[str, str] | None = None,
                  log: Path | None = None) -> Iterator[str]:
    """`fishloc serve` as a process on a free loopback port with `database`; its REST URL. Stopped
    with SIGTERM (a graceful shutdown) at the end."""
    port = free_port()
    command = [sys.executable, "-c", "import sys; from service.cli import main; sys.exit(main())", "serve",
               "--http-port", str(port), "--grpc-port", "-1", "--threads", "1", "--no-demo-camera",
               "--database", str(database), *flags]
    environment = {**os.environ, "FISHLOC_LOG_JSON": "false", **(env or {})}
    out = open(log, "ab") if log is not None else subprocess.DEVNULL  # noqa: SIM115
    process = subprocess.Popen(command, env=environment, stdout=out, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        def ready() -> bool:
            if process.poll() is not None:
                raise AssertionError(f"fishloc serve exited with {process.returncode}")
            try:
                return httpx.get(f"{url}/readyz", timeout=2).status_code == 200
            except httpx.HTTPError:
                return False

        wait_for(ready, 90, "fishloc serve to be ready", every_s=0.2)
        yield url
    finally:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(60)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(10)
        if log is not None:
            out.close()  # type: ignore[union-attr]
