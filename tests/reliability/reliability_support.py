"""What the reliability tests share: the service tests' live server, frames and ONNX model double
(imported from tests/service, not copied) and a raw HTTP/1.1 client. The fixtures over them are in
reliability_fixtures.py (a test module loads them with `pytest_plugins`).

The raw client (http.client) sends paths and headers exactly as given: httpx would normalise
`/v1/cameras/../detect` before sending it, and could not send a body shorter than its Content-Length.
"""

from __future__ import annotations

import contextlib
import datetime
import http.client
import ipaddress
import json
import re
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

REPO_ROOT = Path(__file__).resolve().parents[2]
SERVICE_TESTS = REPO_ROOT / "tests" / "service"
for folder in (SERVICE_TESTS, REPO_ROOT):  # REPO_ROOT: when a helper runs as a script
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

from service_doubles import save_double_model  # noqa: E402
from service_frames import encode, person_frame  # noqa: E402
from service_live_server import LiveServer  # noqa: E402
from service_processes import FishlocProcess  # noqa: E402

from service.core.config import Settings  # noqa: E402

_LISTENING_RE = re.compile(r"REST listening on (https?)://[^:]+:(\d+)")

__all__ = ["LiveServer", "RawResponse", "ServeProcess", "encode", "person_frame", "raw_request",
           "save_double_model", "self_signed", "serve_args", "test_settings", "vm_rss_kib"]




def test_settings(model_path: Path, folder: Path, **overrides: Any) -> Settings:
    """Settings of a test server: the double model, a fresh SQLite file, free port, one thread."""
    values: dict[str, Any] = {
        "model": model_path, "database": str(folder / "cameras.db"), "http_port": 0, "grpc_port": -1,
        "threads": 1, "log_json": True,
    }
    values.update(overrides)
    return Settings(**values)


test_settings.__test__ = False  # type: ignore[attr-defined]  # a helper, not a test


@dataclass
class RawResponse:
    status: int
    headers: dict[str, str]
    body: bytes
    json_body: Any = field(default=None)

    @property
    def error_code(self) -> str | None:
        if isinstance(self.json_body, dict) and isinstance(self.json_body.get("error"), dict):
            return str(self.json_body["error"].get("code"))
        return None

    @property
    def error_message(self) -> str:
        if self.error_code is None:
            return ""
        return str(self.json_body["error"].get("message", ""))


def raw_request(base_url: str, method: str, path: str, body: bytes = b"",
                headers: dict[str, str] | None = None, timeout_s: float = 30.0,
                chunked: bool = False) -> RawResponse:
    """One HTTP/1.1 request with the path, headers and body exactly as given (`chunked`: the body
    in 64 KiB chunks without Content-Length)."""
    host_port = base_url.split("://", 1)[1]
    host, port = host_port.rsplit(":", 1)
    connection = http.client.HTTPConnection(host, int(port), timeout=timeout_s)
    try:
        connection.putrequest(method, path, skip_accept_encoding=True)
        given = {key.lower(): value for key, value in (headers or {}).items()}
        if chunked:
            given["transfer-encoding"] = "chunked"
        else:
            given.setdefault("content-length", str(len(body)))
        for key, value in given.items():
            connection.putheader(key, value)
        if chunked:
            connection.endheaders()
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # answered early
                for start in range(0, len(body), 65536):
                    piece = body[start:start + 65536]
                    connection.send(b"%x\r\n%s\r\n" % (len(piece), piece))
                connection.send(b"0\r\n\r\n")
        else:
            with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # answered early
                connection.endheaders(body or None)
        response = connection.getresponse()
        data = response.read()
        answer_headers = {key.lower(): value for key, value in response.getheaders()}
    finally:
        connection.close()
    parsed: Any = None
    if answer_headers.get("content-type", "").startswith("application/json"):
        parsed = json.loads(data)
    return RawResponse(response.status, answer_headers, data, parsed)


class ServeProcess(FishlocProcess):
    """`fishloc serve ARGS` in a child process (what an operator runs), its log lines collected.

    `start()` waits for the "REST listening" line and reads the port from it; `pid` is the server
    process (for /proc/PID/status and kill -9).
    """

    def __init__(self, args: list[str], env: dict[str, str] | None = None,
                 keep_lines: int | None = None, launcher: list[str] | None = None) -> None:
        super().__init__(["serve", *args], env, keep_lines, launcher)
        self.url = ""
        self._listening = threading.Event()

    def on_line(self, line: str) -> None:
        found = _LISTENING_RE.search(line)
        if found:
            self.url = f"{found.group(1)}://127.0.0.1:{found.group(2)}"
            self._listening.set()

    def on_exit(self) -> None:
        self._listening.set()

    def start(self, timeout_s: float = 60) -> ServeProcess:
        super().start()
        if not self._listening.wait(timeout_s) or not self.url:
            self.stop()
            raise RuntimeError("fishloc serve did not start:\n" + "".join(list(self.lines)[-30:]))
        return self

    def wait_ready(self, timeout_s: float = 60) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with contextlib.suppress(OSError):
                if raw_request(self.url, "GET", "/readyz", timeout_s=5).status == 200:
                    return
            time.sleep(0.05)
        raise TimeoutError("fishloc serve did not become ready")


def serve_args(model_path: Path, database: Path, *extra: str) -> list[str]:
    return ["--model", str(model_path), "--database", str(database), "--http-port", "0",
            "--grpc-port", "-1", "--threads", "1", *extra]


def vm_rss_kib(pid: int) -> int:
    """Resident memory of a process (VmRSS of /proc/PID/status), KiB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for process {pid}")


def self_signed(folder: Path) -> tuple[Path, Path]:
    """A certificate for 127.0.0.1 and localhost, signed by its own key (PEM files)."""
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "fishloc-test")])
    now = datetime.datetime.now(datetime.UTC)
    certificate = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost"),
                                                    x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]),
                       critical=False)
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    cert_path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return cert_path, key_path
