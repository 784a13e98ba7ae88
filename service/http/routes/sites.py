"""Sites: their cameras, zones and counting lines, the people tracked on them now, and their events.

Reads (and events) need the read token when one is configured; zone and line writes need the API
token like camera writes. A site exists while a camera names it.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from typing import Any

from fastapi import APIRouter, Path, Request, Response, status
from fastapi.responses import JSONResponse, StreamingResponse
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from service.core.errors import ApiError
from service.http.dependencies import ReadAccess, ServiceState, State, WriteAccess
from service.http.request_body import BodyLimits, read_json_object
from service.http.schemas import error_responses as _errors
from service.sites.interface import SitesUnavailableError
from service.sites.store import SiteNotFoundError
from service.sites.views import site_to_json
from sites import LayoutError, line_from_body, zone_from_body
from sites.layout import NAME_PATTERN

router = APIRouter(tags=["sites"])

SiteId = Path(pattern=NAME_PATTERN, description="site id (a camera's `site`)")
ZoneId = Path(pattern=NAME_PATTERN, description="zone id")
LineId = Path(pattern=NAME_PATTERN, description="counting line id")
_MAX_BODY_BYTES = 64 * 1024
KEEP_ALIVE_S = 15.0
_POINT = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
_ZONE_BODY = {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "required": ["polygon_m"], "additionalProperties": False,
    "properties": {"polygon_m": {"type": "array", "items": _POINT, "minItems": 3, "maxItems": 256,
                                 "description": "corners [x, y] in the site frame (m), a simple polygon"}},
}}}}
_LINE_BODY = {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "required": ["from_m", "to_m"], "additionalProperties": False,
    "properties": {"from_m": _POINT, "to_m": _POINT},
}}}}


class SiteSummary(BaseModel):
    id: str
    cameras: list[str]
    zones: list[str]


class SiteList(BaseModel):
    sites: list[SiteSummary]


class SiteCamera(BaseModel):
    id: str
    site_pose: dict[str, float]
    view_m: list[list[float]] = Field(description="the floor the camera sees, a polygon in the site frame")


class SiteZone(BaseModel):
    id: str
    polygon_m: list[list[float]]
    in_view: bool = Field(description="whether any camera of the site sees part of it")


class SiteLine(BaseModel):
    id: str
    from_m: list[float]
    to_m: list[float]


class SiteDescription(BaseModel):
    id: str
    cameras: list[SiteCamera]
    zones: list[SiteZone]
    lines: list[SiteLine]
    notes: list[str]


class Person(BaseModel):
    track_id: str
    position_m: list[float]
    velocity_mps: list[float]
    cameras: list[str]
    first_seen: float
    last_seen: float
    dwell_s: dict[str, float] = Field(description="seconds spent in each zone the track has been in")


class Occupancy(BaseModel):
    site: str
    time: float | None = Field(description="the newest capture_time of the site's frames (Unix s)")
    count: int
    people: list[Person]
    zones: dict[str, dict[str, int]]
    lines: dict[str, dict[str, int]]


def site_not_found(site_id: str) -> ApiError:
    return ApiError(404, "site_not_found", f"no camera names site {site_id!r}")


async def require_site(state: ServiceState, site_id: str) -> None:
    try:
        await run_in_threadpool(state.site_store.require, site_id)
    except SiteNotFoundError:
        raise site_not_found(site_id) from None


@router.get("/v1/sites", response_model=SiteList, dependencies=[ReadAccess], responses=_errors(401),
            summary="Every site: its cameras and zones")
async def list_sites(state: State) -> dict[str, Any]:
    sites = await run_in_threadpool(state.site_store.site_cameras)
    layouts = await run_in_threadpool(state.site_store.layouts, list(sites))
    return {"sites": [{"id": site_id, "cameras": [camera.id for camera in cameras],
                       "zones": list(layouts[site_id].zones)} for site_id, cameras in sites.items()]}


@router.get("/v1/sites/{site_id}", response_model=SiteDescription, dependencies=[ReadAccess],
            responses=_errors(401, 404, 422),
            summary="One site: cameras with their poses and views, zones (and whether any camera sees "
                    "them), counting lines")
async def get_site(state: State, site_id: str = SiteId) -> dict[str, Any]:
    try:
        record = await run_in_threadpool(state.site_store.get, site_id)
    except SiteNotFoundError:
        raise site_not_found(site_id) from None
    return await run_in_threadpool(site_to_json, record)


async def _put(request: Request, response: Response, state: ServiceState, site_id: str, item_id: str,
               kind: str) -> dict[str, Any]:
    limits = BodyLimits(_MAX_BODY_BYTES, state.settings.body_timeout_s)
    body = await read_json_object(request, limits, f"a {kind}", f"invalid_{kind}")
    try:
        if kind == "zone":
            zone = zone_from_body(item_id, body)
            created = await run_in_threadpool(state.site_store.put_zone, site_id, zone)
            answer = {"id": item_id, **zone.to_dict()}
        else:
            line = line_from_body(item_id, body)
            created = await run_in_threadpool(state.site_store.put_line, site_id, line)
            answer = {"id": item_id, **line.to_dict()}
    except LayoutError as error:
        raise ApiError(422, f"invalid_{kind}", str(error)) from None
    except SiteNotFoundError:
        raise site_not_found(site_id) from None
    await run_in_threadpool(state.sites.layout_changed, site_id)
    response.status_code = status.HTTP_201_CREATED if created else status.HTTP_200_OK
    return answer


async def _delete(state: ServiceState, site_id: str, item_id: str, kind: str) -> Response:
    remove = state.site_store.delete_zone if kind == "zone" else state.site_store.delete_line
    try:
        removed = await run_in_threadpool(remove, site_id, item_id)
    except SiteNotFoundError:
        raise site_not_found(site_id) from None
    if not removed:
        raise ApiError(404, f"{kind}_not_found", f"site {site_id!r} has no {kind} {item_id!r}")
    await run_in_threadpool(state.sites.layout_changed, site_id)
    return Response(status_code=204)


@router.put("/v1/sites/{site_id}/zones/{zone_id}", response_model=dict[str, Any], dependencies=[WriteAccess],
            responses={201: {"description": "created"}, **_errors(400, 401, 404, 413, 422)},
            summary="Create or replace a zone", openapi_extra={"requestBody": _ZONE_BODY},
            description="Body `{\"polygon_m\": [[x, y], ...]}` in the site frame (m): a simple polygon of "
                        "3 to 256 corners. 201 when new, 200 when replaced; 404 when no camera names the "
                        "site.")
async def put_zone(request: Request, response: Response, state: State, site_id: str = SiteId,
                   zone_id: str = ZoneId) -> dict[str, Any]:
    return await _put(request, response, state, site_id, zone_id, "zone")


@router.delete("/v1/sites/{site_id}/zones/{zone_id}", status_code=204, response_class=Response,
               dependencies=[WriteAccess], responses=_errors(401, 404, 422), summary="Remove a zone")
async def delete_zone(state: State, site_id: str = SiteId, zone_id: str = ZoneId) -> Response:
    return await _delete(state, site_id, zone_id, "zone")


@router.put("/v1/sites/{site_id}/lines/{line_id}", response_model=dict[str, Any], dependencies=[WriteAccess],
            responses={201: {"description": "created"}, **_errors(400, 401, 404, 413, 422)},
            summary="Create or replace a counting line", openapi_extra={"requestBody": _LINE_BODY},
            description="Body `{\"from_m\": [x, y], \"to_m\": [x, y]}` in the site frame (m). Looking from "
                        "from_m towards to_m, a track crossing from the left side to the right counts `in`, "
                        "the other way `out`.")
async def put_line(request: Request, response: Response, state: State, site_id: str = SiteId,
                   line_id: str = LineId) -> dict[str, Any]:
    return await _put(request, response, state, site_id, line_id, "line")


@router.delete("/v1/sites/{site_id}/lines/{line_id}", status_code=204, response_class=Response,
               dependencies=[WriteAccess], responses=_errors(401, 404, 422), summary="Remove a counting line")
async def delete_line(state: State, site_id: str = SiteId, line_id: str = LineId) -> Response:
    return await _delete(state, site_id, line_id, "line")


@router.get("/v1/sites/{site_id}/occupancy", response_model=Occupancy, dependencies=[ReadAccess],
            responses=_errors(401, 404, 422), summary="The fused, tracked people of a site now")
async def get_occupancy(state: State, site_id: str = SiteId) -> JSONResponse:
    await require_site(state, site_id)
    try:
        occupancy = await state.sites.read(site_id)
    except SitesUnavailableError as error:
        raise ApiError(503, "sites_unavailable", str(error), headers={"Retry-After": "1"}) from None
    return JSONResponse(occupancy, headers={"Cache-Control": "no-store"})


def _event(name: str, data: dict[str, Any]) -> str:
    return f"event: {name}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


@router.get(
    "/v1/sites/{site_id}/events", response_class=StreamingResponse, dependencies=[ReadAccess],
    responses={200: {"content": {"text/event-stream": {"schema": {"type": "string"}}},
                     "description": "Server-Sent Events: `occupancy` (the occupancy answer) now and after "
                                    "every frame of the site; `end` when the site closes"},
               **_errors(401, 404, 422)},
    summary="Occupancy updates of a site as Server-Sent Events",
    description="A client that reads slowly misses updates (its queue keeps the newest 16), it never "
                "slows detection. With a read token, a browser's EventSource passes it as `access_token`.",
)
async def site_events(request: Request, state: State, site_id: str = SiteId) -> StreamingResponse:
    await require_site(state, site_id)
    try:
        watcher = await state.sites.subscribe(site_id)
    except SitesUnavailableError as error:
        raise ApiError(503, "sites_unavailable", str(error), headers={"Retry-After": "1"}) from None

    async def stream() -> AsyncIterator[str]:
        try:
            while True:
                try:
                    update = await asyncio.wait_for(watcher.queue.get(), KEEP_ALIVE_S)
                except TimeoutError:
                    yield ": keep-alive\n\n"
                    continue
                if update is None:
                    yield _event("end", {"site": site_id})
                    return
                yield _event("occupancy", update)
        finally:
            state.sites.unwatch(site_id, watcher)

    headers = {"Cache-Control": "no-store", "X-Accel-Buffering": "no"}
    return StreamingResponse(stream(), media_type="text/event-stream", headers=headers)
