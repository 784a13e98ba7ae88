"""Webhooks of a site: signed posts of its events (`service.outputs.webhooks`).

Writes need the API token like other writes; the webhook with its delivery log needs the read token.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Path, Request, Response, status
from starlette.concurrency import run_in_threadpool

from service.core.errors import ApiError
from service.http.dependencies import ReadAccess, State, WriteAccess
from service.http.request_body import BodyLimits, read_json_object
from service.http.routes.sites import SiteId, require_site
from service.http.schemas import error_responses as _errors
from service.outputs.webhooks import EVENT_TYPES, WebhookError, webhook_from_body
from sites.layout import NAME_PATTERN

router = APIRouter(tags=["webhooks"])

WebhookId = Path(pattern=NAME_PATTERN, description="webhook id")
_MAX_BODY_BYTES = 16 * 1024
_BODY = {"required": True, "content": {"application/json": {"schema": {
    "type": "object", "required": ["url", "secret", "events"], "additionalProperties": False,
    "properties": {
        "url": {"type": "string", "description": "http:// or https:// receiver"},
        "secret": {"type": "string", "minLength": 8, "description": "HMAC-SHA256 key of the signature"},
        "events": {"type": "array", "items": {"enum": list(EVENT_TYPES)}, "minItems": 1},
        "zone_thresholds": {"type": "object", "additionalProperties": {"type": "integer", "minimum": 1}},
        "summary_every_s": {"type": "number", "minimum": 1, "maximum": 86400},
    },
}}}}


def _not_found(site_id: str, webhook_id: str) -> ApiError:
    return ApiError(404, "webhook_not_found", f"site {site_id!r} has no webhook {webhook_id!r}")


@router.put("/v1/sites/{site_id}/webhooks/{webhook_id}", response_model=dict[str, Any],
            dependencies=[WriteAccess], responses={201: {"description": "created"},
                                                   **_errors(400, 401, 404, 413, 422)},
            summary="Create or replace a webhook", openapi_extra={"requestBody": _BODY},
            description="Body `{\"url\", \"secret\", \"events\": [\"line_crossing\", \"zone_threshold\", "
                        "\"summary\"], \"zone_thresholds\": {\"<zone>\": 5}, \"summary_every_s\": 60}`. Each "
                        "post is signed `X-FishLoc-Signature: sha256=<hex HMAC-SHA256 of the body>`.")
async def put_webhook(request: Request, response: Response, state: State, site_id: str = SiteId,
                      webhook_id: str = WebhookId) -> dict[str, Any]:
    limits = BodyLimits(_MAX_BODY_BYTES, state.settings.body_timeout_s)
    body = await read_json_object(request, limits, "a webhook", "invalid_webhook")
    try:
        spec = webhook_from_body(body)
    except WebhookError as error:
        raise ApiError(422, "invalid_webhook", str(error)) from None
    await require_site(state, site_id)
    webhooks = state.outputs.webhooks
    try:
        created = await run_in_threadpool(webhooks.store.put, site_id, webhook_id, spec)
    except WebhookError as error:
        raise ApiError(422, "invalid_webhook", str(error)) from None
    webhooks.changed(site_id)
    response.status_code = status.HTTP_201_CREATED if created else status.HTTP_200_OK
    return {"id": webhook_id, "site": site_id, **spec.public()}


@router.get("/v1/sites/{site_id}/webhooks/{webhook_id}", response_model=dict[str, Any],
            dependencies=[ReadAccess], responses=_errors(401, 404, 422),
            summary="A webhook with its last deliveries and failures")
async def get_webhook(state: State, site_id: str = SiteId, webhook_id: str = WebhookId) -> dict[str, Any]:
    store = state.outputs.webhooks.store
    spec = await run_in_threadpool(store.get, site_id, webhook_id)
    if spec is None:
        raise _not_found(site_id, webhook_id)
    log = await run_in_threadpool(store.log, site_id, webhook_id)
    return {"id": webhook_id, "site": site_id, **spec.public(), **log}


@router.delete("/v1/sites/{site_id}/webhooks/{webhook_id}", status_code=204, response_class=Response,
               dependencies=[WriteAccess], responses=_errors(401, 404, 422),
               summary="Remove a webhook (and what its outbox still held)")
async def delete_webhook(state: State, site_id: str = SiteId, webhook_id: str = WebhookId) -> Response:
    webhooks = state.outputs.webhooks
    if not await run_in_threadpool(webhooks.store.delete, site_id, webhook_id):
        raise _not_found(site_id, webhook_id)
    webhooks.changed(site_id)
    return Response(status_code=204)

