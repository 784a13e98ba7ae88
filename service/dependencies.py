"""What the routes need, taken from the app's state: settings, runner, registry, metrics, auth."""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request

from service.cameras import CameraRegistry
from service.config import Settings
from service.errors import ApiError
from service.metrics import ServiceMetrics
from service.runner import InferenceRunner


@dataclass
class ServiceState:
    """The objects one service instance is made of, shared by both front ends."""

    settings: Settings
    runner: InferenceRunner
    registry: CameraRegistry
    metrics: ServiceMetrics


def get_state(request: Request) -> ServiceState:
    state: ServiceState = request.app.state.fishloc
    return state


State = Annotated[ServiceState, Depends(get_state)]


def require_write_token(request: Request, state: State) -> None:
    """Registry writes need `Authorization: Bearer <FISHLOC_API_TOKEN>` when a token is configured."""
    token = state.settings.api_token
    if token is None:
        return
    scheme, _, given = request.headers.get("authorization", "").partition(" ")
    expected = token.get_secret_value().encode("utf-8")
    # compare_digest takes as long for a wrong token as for a right one.
    if scheme.lower() != "bearer" or not hmac.compare_digest(given.strip().encode("utf-8"), expected):
        raise ApiError(401, "unauthorized", "registry writes need 'Authorization: Bearer <token>'",
                       headers={"WWW-Authenticate": "Bearer"})


WriteAccess = Depends(require_write_token)
