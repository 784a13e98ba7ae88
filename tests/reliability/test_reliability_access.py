"""Access: bearer tokens (constant-time comparison, never logged), the optional detection token, TLS
from certificate paths, and CORS off unless configured."""

from __future__ import annotations

import hmac
import signal
import ssl
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from reliability_cases import SCENARIO
from reliability_samples import Samples
from reliability_support import LiveServer, ServeProcess, self_signed, serve_args

import service.http.dependencies
from fisheye import FisheyeCamera, camera_to_dict
from service.core.config import Settings
from service.core.tls import TlsError

pytest_plugins = ["reliability_fixtures"]

API_TOKEN = "api-7f3c1d9e5b2a4c6e8f0a1b3c5d7e9f1a"
DETECT_TOKEN = "det-2b4d6f8a0c1e3f5a7b9c1d3e5f7a9b1c"
JPEG = {"content-type": "image/jpeg"}


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


# ----- tokens


def test_tokens_are_compared_with_compare_digest(settings_for: Callable[..., Settings],
                                                 monkeypatch: pytest.MonkeyPatch,
                                                 demo_camera: FisheyeCamera) -> None:
    """Every configured token is compared with hmac.compare_digest, whatever the length or prefix of
    the token given (no early exit that a timing could reveal)."""
    calls: list[tuple[bytes, bytes]] = []
    compare_digest = hmac.compare_digest

    def spy(given: bytes, expected: bytes) -> bool:
        calls.append((given, expected))
        return compare_digest(given, expected)

    monkeypatch.setattr(service.http.dependencies.hmac, "compare_digest", spy)
    with LiveServer(settings_for(api_token=API_TOKEN, detect_token=DETECT_TOKEN)) as live:
        record = camera_to_dict(demo_camera) | {"id": "cam"}
        for wrong in ("a", API_TOKEN[:-1], API_TOKEN + "x", "x" * 4096):
            calls.clear()
            answer = httpx.put(f"{live.url}/v1/cameras/cam", json=record, headers=bearer(wrong))
            assert answer.status_code == SCENARIO["token_wrong"].status
            assert calls == [(wrong.encode(), API_TOKEN.encode())]
        calls.clear()
        frame = Samples(demo_camera).good_jpeg
        answer = httpx.post(f"{live.url}/v1/cameras/demo/detect", content=frame,
                            headers=JPEG | bearer(DETECT_TOKEN))
        assert answer.status_code == 200
        # Both tokens that may detect were compared, though the first one matched.
        assert calls == [(DETECT_TOKEN.encode(), DETECT_TOKEN.encode()),
                         (DETECT_TOKEN.encode(), API_TOKEN.encode())]


def test_detect_token(settings_for: Callable[..., Settings], demo_camera: FisheyeCamera) -> None:
    frame = Samples(demo_camera).good_jpeg
    with LiveServer(settings_for(api_token=API_TOKEN, detect_token=DETECT_TOKEN)) as live:
        url = f"{live.url}/v1/cameras/demo/detect"
        for headers in ({}, bearer("wrong"), {"Authorization": DETECT_TOKEN}, {"Authorization": "Basic x"}):
            answer = httpx.post(url, content=frame, headers=JPEG | headers)
            assert answer.status_code == SCENARIO["detect_token"].status
            assert answer.json()["error"]["code"] == "unauthorized"
            assert answer.headers["www-authenticate"] == "Bearer"
        assert httpx.post(url, content=frame, headers=JPEG | bearer(DETECT_TOKEN)).status_code == 200
        assert httpx.post(url, content=frame, headers=JPEG | bearer(API_TOKEN)).status_code == 200
        # The detection token does not open the registry to writes; reads stay open.
        record = camera_to_dict(demo_camera)
        put = httpx.put(f"{live.url}/v1/cameras/demo", json=record, headers=bearer(DETECT_TOKEN))
        assert put.status_code == 401
        assert httpx.get(f"{live.url}/v1/cameras/demo").status_code == 200
        assert httpx.get(f"{live.url}/readyz").status_code == 200
    with LiveServer(settings_for(api_token=API_TOKEN)) as open_detect:  # no detect token: open
        url = f"{open_detect.url}/v1/cameras/demo/detect"
        assert httpx.post(url, content=frame, headers=JPEG).status_code == 200


def test_tokens_never_reach_the_log(double_model_path: Path, tmp_path: Path,
                                    demo_camera: FisheyeCamera) -> None:
    """`fishloc serve` at debug level, requests with right, wrong and near-miss tokens (and one whose
    camera record is refused): its whole log holds neither token."""
    frame = Samples(demo_camera).good_jpeg
    env = {"FISHLOC_API_TOKEN": API_TOKEN, "FISHLOC_DETECT_TOKEN": DETECT_TOKEN, "FISHLOC_LOG_LEVEL": "debug"}
    with ServeProcess(serve_args(double_model_path, tmp_path / "db.sqlite"), env) as server:
        server.wait_ready()
        url = server.url
        record = camera_to_dict(demo_camera) | {"id": "cam"}
        for token in (API_TOKEN, API_TOKEN[:-1], DETECT_TOKEN, DETECT_TOKEN + "x"):
            httpx.put(f"{url}/v1/cameras/cam", json=record, headers=bearer(token))
            httpx.put(f"{url}/v1/cameras/cam", json=record | {"altitude_m": -1}, headers=bearer(token))
            httpx.post(f"{url}/v1/cameras/demo/detect", content=frame, headers=JPEG | bearer(token))
            httpx.post(f"{url}/v1/cameras/demo/detect", content=b"junk", headers=JPEG | bearer(token))
        assert httpx.get(f"{url}/v1/cameras/cam").status_code == 200  # the right token did work
        code = server.stop()
    log = server.log
    assert code in (0, -signal.SIGTERM) and "REST listening" in log and "/v1/cameras/demo/detect" in log
    assert API_TOKEN[:-1] not in log and DETECT_TOKEN not in log


# ----- TLS


def test_rest_over_tls(settings_for: Callable[..., Settings], tmp_path: Path,
                       demo_camera: FisheyeCamera) -> None:
    cert, key = self_signed(tmp_path)
    live = LiveServer(settings_for(tls_cert=cert, tls_key=key)).start(wait_ready=False)
    try:
        url = live.url.replace("http://", "https://")
        trusted = ssl.create_default_context(cafile=str(cert))
        with httpx.Client(verify=trusted, timeout=30) as client:
            deadline = time.monotonic() + 60
            while client.get(f"{url}/readyz").status_code != 200:
                assert time.monotonic() < deadline, "the TLS server did not become ready"
                time.sleep(0.05)
            answer = client.post(f"{url}/v1/cameras/demo/detect", content=Samples(demo_camera).good_jpeg,
                                 headers=JPEG)
            assert answer.status_code == SCENARIO["tls_rest"].status and answer.json()["detections"]
        with pytest.raises(httpx.ConnectError):  # a client that does not trust the certificate
            httpx.get(f"{url}/healthz", verify=ssl.create_default_context())
        with pytest.raises(httpx.HTTPError):  # plain HTTP on the TLS port
            httpx.get(f"{live.url}/healthz")
    finally:
        live.stop()


def test_tls_files_are_checked_at_start(settings_for: Callable[..., Settings], tmp_path: Path,
                                        double_model_path: Path) -> None:
    cert, key = self_signed(tmp_path)
    (tmp_path / "other").mkdir()
    other_cert, _ = self_signed(tmp_path / "other")
    with pytest.raises(TlsError, match="does not fit"):
        LiveServer(settings_for(tls_cert=other_cert, tls_key=key)).start()
    # `fishloc serve` stops with a clear message and exit status 2.
    missing = ServeProcess(serve_args(double_model_path, tmp_path / "db.sqlite"),
                           {"FISHLOC_TLS_CERT": str(tmp_path / "nope.pem"), "FISHLOC_TLS_KEY": str(key)})
    with pytest.raises(RuntimeError, match="cannot read the TLS certificate"):
        missing.start(timeout_s=60)
    assert missing.stop() == SCENARIO["tls_bad_files"].status
    lone = ServeProcess(serve_args(double_model_path, tmp_path / "db.sqlite"),
                        {"FISHLOC_TLS_CERT": str(cert)})
    with pytest.raises(RuntimeError, match="tls_cert and tls_key go together"):
        lone.start(timeout_s=60)
    assert lone.stop() == 2


# ----- CORS


def test_cors_is_off_unless_configured(settings_for: Callable[..., Settings]) -> None:
    origin = "https://viewer.example"
    preflight = {"Origin": origin, "Access-Control-Request-Method": "POST",
                 "Access-Control-Request-Headers": "content-type"}
    with LiveServer(settings_for()) as live:
        answer = httpx.options(f"{live.url}/v1/cameras/demo/detect", headers=preflight)
        assert answer.status_code == 405 and "access-control-allow-origin" not in answer.headers
        plain = httpx.get(f"{live.url}/v1/cameras", headers={"Origin": origin})
        assert plain.status_code == 200 and "access-control-allow-origin" not in plain.headers
    with LiveServer(settings_for(cors_origins=[origin])) as live:
        answer = httpx.options(f"{live.url}/v1/cameras/demo/detect", headers=preflight)
        assert answer.status_code == 200 and answer.headers["access-control-allow-origin"] == origin
        plain = httpx.get(f"{live.url}/v1/cameras", headers={"Origin": origin})
        assert plain.headers["access-control-allow-origin"] == origin
        assert "x-request-id" in plain.headers["access-control-expose-headers"].lower()
        stranger = httpx.options(f"{live.url}/v1/cameras/demo/detect",
                                 headers=preflight | {"Origin": "https://evil.example"})
        assert stranger.status_code == 400 and "access-control-allow-origin" not in stranger.headers
