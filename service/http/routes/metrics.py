"""Prometheus metrics."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response

from service.core.metrics import CONTENT_TYPE
from service.http.dependencies import State

router = APIRouter(tags=["metrics"])


@router.get("/metrics", response_class=Response, summary="Prometheus text format",
            responses={200: {"content": {"text/plain": {}}, "description": "Prometheus exposition"}})
async def metrics(state: State) -> Response:
    return Response(state.metrics.exposition(), media_type=CONTENT_TYPE)
