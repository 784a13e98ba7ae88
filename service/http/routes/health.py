"""Liveness and readiness."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from service.core.errors import ApiError
from service.http.dependencies import State
from service.http.schemas import Readiness, Status, error_responses

router = APIRouter(tags=["health"])


@router.get("/healthz", response_model=Status, summary="Live: the process answers")
async def healthz() -> dict[str, str]:
    return {"status": "ok"}


@router.get("/readyz", response_model=Readiness, responses=error_responses(503),
            response_model_exclude_none=True,
            summary="Ready: the model is loaded and warmed up",
            description="`outputs` tells how each output (MQTT, webhooks, history) is doing; an "
                        "unreachable broker or receiver shows there and never makes the service unready. "
                        "Behind a sites bus, `sites_bus` says whether site state can be read (detection "
                        "answers either way, so the replica stays ready) and the outputs run in the "
                        "`fishloc sites` workers.")
async def readyz(state: State) -> dict[str, Any]:
    if not state.runner.ready:
        raise ApiError(503, "not_ready", "the model is warming up", headers={"Retry-After": "1"})
    if state.settings.sites_bus is None:
        return {"status": "ready", "outputs": state.outputs.dispatcher.health()}
    problem = state.sites.problem()
    return {"status": "ready", "sites_bus": "ok" if problem is None else f"unreachable: {problem}"}
