"""The API docs page (`/docs`) in a real headless Chromium that can reach nothing but the service.

Every host name resolves to nowhere (`--host-resolver-rules`), as on a closed camera network; the
service is reached by its loopback address. The page must still list every operation of
`/openapi.json`, having loaded only the service's own files.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from service_live_server import LiveServer
from viewer_browser import chromium_driver, wait_for

# Every host but the loopback address (a CDN, fonts, a validator) fails to resolve.
OFFLINE_FLAGS = ("--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",)
HTTP_METHODS = {"get", "put", "post", "delete", "patch", "head", "options"}


@pytest.fixture(scope="module")
def offline_driver() -> Iterator[Any]:
    with chromium_driver(OFFLINE_FLAGS) as chromium:
        yield chromium


def test_the_browser_reaches_no_other_host(offline_driver: Any) -> None:
    offline_driver.get("about:blank")
    outcome = offline_driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch('https://cdn.jsdelivr.net/npm/swagger-ui-dist@5/swagger-ui.css', {mode: 'no-cors'})"
        ".then(() => done('loaded'), (error) => done('failed: ' + error.name));")
    assert outcome == "failed: TypeError"


def test_docs_list_every_operation_offline(offline_driver: Any, live_server: LiveServer) -> None:
    spec = httpx.get(f"{live_server.url}/openapi.json").json()
    operations = sorted((method.upper(), path) for path, item in spec["paths"].items()
                        for method in item if method in HTTP_METHODS)
    assert ("PUT", "/v1/cameras/{camera_id}") in operations
    offline_driver.get_log("browser")  # forget what earlier pages logged
    offline_driver.get(f"{live_server.url}/docs")

    def listed() -> list[tuple[str, str]]:
        found: list[list[str]] = offline_driver.execute_script(
            "return [...document.querySelectorAll('.opblock-summary')].map((s) => ["
            "s.querySelector('.opblock-summary-method').textContent.trim(),"
            "s.querySelector('.opblock-summary-path').dataset.path])")
        return sorted((method, path) for method, path in found)

    wait_for(lambda: len(listed()) == len(operations), "the operations on the docs page")
    assert listed() == operations
    resources = offline_driver.execute_script(
        "return performance.getEntriesByType('resource').map((e) => e.name)")
    assert resources and all(url.startswith(f"{live_server.url}/") for url in resources), resources
    assert {url.removeprefix(live_server.url) for url in resources} >= {
        "/docs/assets/swagger-ui-bundle.js", "/docs/assets/swagger-ui.css", "/openapi.json"}
    errors = [entry["message"] for entry in offline_driver.get_log("browser") if entry["level"] == "SEVERE"]
    assert errors == []


def test_docs_assets_are_only_the_shipped_files(live_server: LiveServer) -> None:
    for name, media_type in (("swagger-ui-bundle.js", "text/javascript"), ("swagger-ui.css", "text/css")):
        response = httpx.get(f"{live_server.url}/docs/assets/{name}")
        assert response.status_code == 200 and response.headers["content-type"].startswith(media_type)
        assert "default-src 'self'" in response.headers["content-security-policy"]
    for name in ("LICENSE", "../routes/docs.py", "index.html"):
        response = httpx.get(f"{live_server.url}/docs/assets/{name}")
        assert response.status_code == 404 and response.json()["error"]["code"] == "not_found"
