"""What the routes need, taken from the app's state: settings, runner, registry, metrics, auth."""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request
from pydantic import SecretStr

from service.cameras import CameraRegistry
from service.core.config import Settings
from service.core.errors import ApiError
from service.core.metrics import ServiceMetrics
from service.outputs.build import Outputs
from service.runner import InferenceRunner
from service.sites.interface import Sites
from service.sites.store import SiteStore


@dataclass
class ServiceState:
    """The objects one service instance is made of, shared by both front ends."""

    settings: Settings
    runner: InferenceRunner
    registry: CameraRegistry
    metrics: ServiceMetrics
    site_store: SiteStore
    sites: Sites
    outputs: Outputs


def get_state(request: Request) -> ServiceState:
    state: ServiceState = request.app.state.fishloc
    return state


State = Annotated[ServiceState, Depends(get_state)]


def bearer_matches(authorization: str, tokens: list[SecretStr]) -> bool:
    """Whether an Authorization header value is `Bearer <one of tokens>`, compared in constant time.

    Every token is compared (no early exit), with hmac.compare_digest, so the answer takes as long
    for a wrong token as for a right one and says nothing about which token nearly matched.
    """
    scheme, _, given = authorization.partition(" ")
    given_bytes = given.strip().encode("utf-8")
    matched = False
    for token in tokens:
        matched |= hmac.compare_digest(given_bytes, token.get_secret_value().encode("utf-8"))
    return scheme.lower() == "bearer" and matched


def require_write_token(request: Request, state: State) -> None:
    """Registry writes need `Authorization: Bearer <FISHLOC_API_TOKEN>` when a token is configured."""
    token = state.settings.api_token
    if token is None:
        return
    if not bearer_matches(request.headers.get("authorization", ""), [token]):
        raise ApiError(401, "unauthorized", "registry writes need 'Authorization: Bearer <token>'",
                       headers={"WWW-Authenticate": "Bearer"})


def require_detect_token(request: Request, state: State) -> None:
    """Detection needs `Authorization: Bearer <FISHLOC_DETECT_TOKEN>` (or the API token) when a
    detect token is configured."""
    settings = state.settings
    if settings.detect_token is None:
        return
    tokens = [settings.detect_token] + ([settings.api_token] if settings.api_token is not None else [])
    if not bearer_matches(request.headers.get("authorization", ""), tokens):
        raise ApiError(401, "unauthorized", "detection needs 'Authorization: Bearer <token>'",
                       headers={"WWW-Authenticate": "Bearer"})


def read_token_passes(state: ServiceState, authorization: str) -> bool:
    """Whether a request may read sites, their events and latest frames: no read token is configured,
    or `authorization` is `Bearer <read token or API token>`."""
    settings = state.settings
    if settings.read_token is None:
        return True
    tokens = [settings.read_token] + ([settings.api_token] if settings.api_token is not None else [])
    return bearer_matches(authorization, tokens)


def require_read_token(request: Request, state: State) -> None:
    """Site reads, events and latest frames show where people are: with FISHLOC_READ_TOKEN set they
    need it (or the API token) as a bearer token, or as the query parameter `access_token` (a
    browser's EventSource cannot send headers)."""
    authorization = request.headers.get("authorization", "")
    query_token = request.query_params.get("access_token")
    if not authorization and query_token:
        authorization = f"Bearer {query_token}"
    if not read_token_passes(state, authorization):
        raise ApiError(401, "unauthorized",
                       "site reads and latest frames need 'Authorization: Bearer <token>'",
                       headers={"WWW-Authenticate": "Bearer"})


WriteAccess = Depends(require_write_token)
ReadAccess = Depends(require_read_token)
DetectAccess = Depends(require_detect_token)
