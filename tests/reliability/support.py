"""What the reliability tests share: the service tests' live server, frames and ONNX model double
(imported from tests/service, not copied) and a raw HTTP/1.1 client. The fixtures over them are in
reliability_fixtures.py (a test module loads them with `pytest_plugins`).

The raw client (http.client) sends paths and headers exactly as given: httpx would normalise
`/v1/cameras/../detect` before sending it, and could not send a body shorter than its Content-Length.
"""

from __future__ import annotations

import contextlib
import http.client
import importlib.util
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

SERVICE_TESTS = Path(__file__).resolve().parents[1] / "service"
if str(SERVICE_TESTS) not in sys.path:
    sys.path.insert(0, str(SERVICE_TESTS))

from live_server import LiveServer  # noqa: E402

from service.config import Settings  # noqa: E402


def _service_conftest() -> ModuleType:
    """tests/service/conftest.py as a plain module (pytest may have loaded it as `conftest`)."""
    loaded = sys.modules.get("conftest")
    if loaded is not None and Path(str(loaded.__file__)).resolve() == SERVICE_TESTS / "conftest.py":
        return loaded
    spec = importlib.util.spec_from_file_location("service_tests_conftest", SERVICE_TESTS / "conftest.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


_service = _service_conftest()
person_frame = _service.person_frame
encode = _service.encode

__all__ = ["LiveServer", "RawResponse", "encode", "person_frame", "raw_request", "test_settings"]




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
