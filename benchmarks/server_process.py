"""A live `fishloc serve` in a subprocess, on free loopback ports, with its own registry and cameras."""

from __future__ import annotations

import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType

import httpx

from benchmarks.checkout import checkout_env, source_root
from fisheye import FisheyeCamera, camera_to_dict, save_camera


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def write_cameras(folder: Path, camera: FisheyeCamera, ids: list[str]) -> Path:
    """`camera`'s calibration under each of `ids`, one YAML file per camera, in `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    for camera_id in ids:
        record = dict(camera_to_dict(camera), id=camera_id)
        save_camera(FisheyeCamera.model_validate(record), folder / f"{camera_id}.yaml")
    return folder


class ServerProcess:
    """`python -m service.cli serve` with `model`, `threads`, the given cameras; REST and gRPC ports."""

    def __init__(self, model: Path, camera: FisheyeCamera, camera_ids: list[str], threads: int | None,
                 grpc: bool, extra_env: dict[str, str] | None = None) -> None:
        self._folder = tempfile.TemporaryDirectory(prefix="fishloc-bench-")
        root = Path(self._folder.name)
        self.http_port = free_port()
        self.grpc_port = free_port() if grpc else -1
        cameras = write_cameras(root / "cameras", camera, camera_ids)
        self.command = [
            sys.executable, "-m", "service.cli", "serve", "--host", "127.0.0.1",
            "--http-port", str(self.http_port), "--grpc-port", str(self.grpc_port),
            "--model", str(Path(model).resolve()), "--cameras", str(cameras),
            "--database", str(root / "cameras.db"),
            "--no-demo-camera",
        ]
        if threads is not None:
            self.command += ["--threads", str(threads)]
        # The server runs the same checkout as the benchmark, whatever an installed copy says.
        self.source_root = source_root()
        self.env = checkout_env(dict(FISHLOC_LOG_LEVEL="warning", **(extra_env or {})))
        self.log_path = root / "server.log"
        self._process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.http_port}"

    def start(self, timeout_s: float = 120.0) -> ServerProcess:
        with self.log_path.open("wb") as log:
            self._process = subprocess.Popen(self.command, stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                             cwd=self.source_root)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                raise RuntimeError(f"fishloc serve exited with {self._process.returncode}:\n{self.log()}")
            try:
                if httpx.get(f"{self.url}/readyz", timeout=2.0).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.stop()
        raise TimeoutError(f"fishloc serve was not ready within {timeout_s:.0f} s:\n{self.log()}")

    def log(self) -> str:
        try:
            return self.log_path.read_text(encoding="utf-8", errors="replace")[-4000:]
        except OSError:
            return ""

    def stop(self) -> None:
        if self._process is not None and self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(30)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait(10)
        self._folder.cleanup()

    def __enter__(self) -> ServerProcess:
        return self.start()

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.stop()
