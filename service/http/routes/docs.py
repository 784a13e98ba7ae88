"""The API documentation page at `/docs`: Swagger UI over `/openapi.json`, served from the package.

FastAPI's own page pulls Swagger UI from a public CDN, which a closed camera network cannot reach (a
blank page). Here the swagger-ui-dist files (Apache-2.0, `static/docs/LICENSE` and `NOTICE`) ship
inside the package, the page's start-up script is a file too, and the Content-Security-Policy
allows this service alone.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import Response

from service.core.errors import ApiError
from service.http.packaged_files import PackagedFiles

router = APIRouter(include_in_schema=False)

ASSETS_DIR = Path(__file__).resolve().parents[2] / "static" / "docs"
_MEDIA_TYPES = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "docs.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
}
# Swagger UI sets style attributes from script; everything it loads comes from this service.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
_FILES = PackagedFiles(ASSETS_DIR, CONTENT_SECURITY_POLICY)


@router.get("/docs", response_class=Response)
async def docs_page() -> Response:
    return _FILES.response("index.html", "text/html; charset=utf-8")


@router.get("/docs/assets/{name}", response_class=Response)
async def docs_asset(name: str) -> Response:
    media_type = _MEDIA_TYPES.get(name)
    if media_type is None:
        raise ApiError(404, "not_found", f"no docs asset {name!r}")
    return _FILES.response(name, media_type)
