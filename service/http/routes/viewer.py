"""The web viewer: its HTML pages (`/`, and the live site map at `/site`) and their ES modules and
style sheets, shipped in the package.

No build step and nothing from elsewhere: the page talks only to this service's REST API, and its
Content-Security-Policy forbids any other origin, so it works on a closed network.
"""

from __future__ import annotations

import re
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import Response

from service.core.errors import ApiError
from service.http.packaged_files import PackagedFiles

router = APIRouter(include_in_schema=False)

ASSETS_DIR = Path(__file__).resolve().parents[2] / "static" / "viewer"
_ASSET_NAME = re.compile(r"^[a-z0-9_-]+\.(js|css)$")
_MEDIA_TYPES = {"js": "text/javascript; charset=utf-8", "css": "text/css; charset=utf-8"}
# Frames shown by the page are blob: URLs (uploads) or this service's own latest.jpg.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
_FILES = PackagedFiles(ASSETS_DIR, CONTENT_SECURITY_POLICY)


@router.get("/", response_class=Response)
async def index() -> Response:
    return _FILES.response("index.html", "text/html; charset=utf-8")


@router.get("/site", response_class=Response)
async def site_map() -> Response:
    return _FILES.response("site.html", "text/html; charset=utf-8")


@router.get("/viewer/{name}", response_class=Response)
async def asset(name: str) -> Response:
    match = _ASSET_NAME.match(name)
    if match is None or not _FILES.has(name):
        raise ApiError(404, "not_found", f"no viewer asset {name!r}")
    return _FILES.response(name, _MEDIA_TYPES[match.group(1)])
