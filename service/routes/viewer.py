"""The web viewer: its HTML pages (`/`, and the live site map at `/site`) and their ES modules and
style sheets, shipped in the package.

No build step and nothing from elsewhere: the page talks only to this service's REST API, and its
Content-Security-Policy forbids any other origin, so it works on a closed network.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import Response

from service.errors import ApiError

router = APIRouter(include_in_schema=False)

ASSETS_DIR = Path(__file__).resolve().parent.parent / "static" / "viewer"
_ASSET_NAME = re.compile(r"^[a-z0-9_-]+\.(js|css)$")
_MEDIA_TYPES = {"js": "text/javascript; charset=utf-8", "css": "text/css; charset=utf-8"}
# Frames shown by the page are blob: URLs (uploads) or this service's own latest.jpg.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' blob: data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'"
)
_HEADERS = {"Content-Security-Policy": CONTENT_SECURITY_POLICY, "X-Content-Type-Options": "nosniff",
            "Cache-Control": "no-cache"}


@cache
def _read_asset(name: str) -> bytes:
    return (ASSETS_DIR / name).read_bytes()


@router.get("/", response_class=Response)
async def index() -> Response:
    return Response(_read_asset("index.html"), media_type="text/html; charset=utf-8", headers=_HEADERS)


@router.get("/site", response_class=Response)
async def site_map() -> Response:
    return Response(_read_asset("site.html"), media_type="text/html; charset=utf-8", headers=_HEADERS)


@router.get("/viewer/{name}", response_class=Response)
async def asset(name: str) -> Response:
    match = _ASSET_NAME.match(name)
    if match is None or not (ASSETS_DIR / name).is_file():
        raise ApiError(404, "not_found", f"no viewer asset {name!r}")
    return Response(_read_asset(name), media_type=_MEDIA_TYPES[match.group(1)], headers=_HEADERS)
