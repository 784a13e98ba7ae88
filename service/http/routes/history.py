"""Counts history of a site (`service.outputs.history`): JSON, or CSV with `Accept: text/csv`."""

from __future__ import annotations

import time
from typing import Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool

from service.core.capture_time import CaptureTimeError, parse_capture_time
from service.core.errors import ApiError
from service.http.dependencies import ReadAccess, State
from service.http.routes.sites import SiteId, require_site
from service.http.schemas import error_responses as _errors
from service.outputs.history import MINUTE_S, HistoryQueryError, rows_to_csv

router = APIRouter(tags=["sites"])

DEFAULT_SPAN_S = 86_400


def _time(text: str | None, name: str, default: float) -> float:
    if text is None or not text.strip():
        return default
    try:
        return parse_capture_time(text)
    except CaptureTimeError as error:
        raise ApiError(422, "invalid_history_query",
                       f"{name}: {str(error).replace('capture_time', name)}") from None


@router.get(
    "/v1/sites/{site_id}/history", dependencies=[ReadAccess], response_model=dict[str, Any],
    responses={200: {"content": {"text/csv": {"schema": {"type": "string"}}},
                     "description": "rows of `step` seconds, oldest first (CSV with `Accept: text/csv`)"},
               **_errors(401, 404, 422)},
    summary="Counts history of a site: people (mean, max), zones (mean, max), line crossings per step",
    description="JSON, or CSV with `Accept: text/csv` (or `format=csv`). `from` and `to`: Unix seconds "
                "or RFC 3339 (default: the last day); `step`: seconds, a "
                "multiple of 60 up to 31 days (default 60). Times are capture times; a row's line counts "
                "are the crossings within it.",
)
async def get_history(request: Request, state: State, site_id: str = SiteId,
                      from_: str | None = Query(None, alias="from", max_length=64),
                      to: str | None = Query(None, max_length=64),
                      step: int = Query(MINUTE_S, description="seconds per row"),
                      format: Literal["json", "csv"] | None = Query(
                          None, description="csv: as `Accept: text/csv` (for links)")) -> Response:
    to_s = _time(to, "to", time.time())
    from_s = _time(from_, "from", to_s - DEFAULT_SPAN_S)
    await require_site(state, site_id)
    history = state.outputs.history
    try:
        rows = await run_in_threadpool(history.store.query, site_id, from_s, to_s, step,
                                       history.open_minute(site_id))
    except HistoryQueryError as error:
        raise ApiError(422, "invalid_history_query", str(error)) from None
    if format == "csv" or (format is None and "text/csv" in request.headers.get("accept", "")):
        return Response(rows_to_csv(rows), media_type="text/csv",
                        headers={"Content-Disposition": f'inline; filename="{site_id}-history.csv"'})
    return JSONResponse({"site": site_id, "step_s": step, "rows": rows})
