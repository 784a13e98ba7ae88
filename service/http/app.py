"""The REST application factory."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware

from service.core.errors import install_error_handlers
from service.http.dependencies import ServiceState
from service.http.middleware import RequestContextMiddleware
from service.http.routes import (
    calibrations,
    cameras,
    detect,
    docs,
    health,
    history,
    latest,
    metrics,
    model,
    site_poses,
    sites,
    viewer,
    webhooks,
)

log = logging.getLogger(__name__)

DESCRIPTION = """Finds people in overhead fisheye frames and tells where they stand on the floor, in metres.

Errors answer `{"error": {"code": "...", "message": "..."}}`. Registry writes need
`Authorization: Bearer <token>` when the server has a token (FISHLOC_API_TOKEN)."""


def create_app(state: ServiceState, warm_up: bool = True) -> FastAPI:
    """A FastAPI app over one service state; the model is warmed up in the background at start
    (`/readyz` answers 503 until then)."""

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        task = asyncio.create_task(state.runner.warm_up()) if warm_up and not state.runner.ready else None
        yield
        if task is not None and not task.done():
            task.cancel()

    app = FastAPI(
        title="FishLoc", version="1", description=DESCRIPTION, lifespan=lifespan,
        docs_url=None, redoc_url=None,  # /docs: service.http.routes.docs, assets from the package
    )
    app.state.fishloc = state
    install_error_handlers(app)
    for module in (health, model, cameras, calibrations, detect, latest, sites, site_poses, history, webhooks,
                   metrics, viewer, docs):
        app.include_router(module.router)
    if state.settings.cors_origins:  # CORS stays off (no CORS headers at all) unless configured
        app.add_middleware(
            CORSMiddleware, allow_origins=state.settings.cors_origins,
            allow_methods=["GET", "POST", "PUT", "DELETE"],
            allow_headers=["Authorization", "Content-Type", "X-Request-ID"],
            expose_headers=["X-Request-ID", "Retry-After", "X-Detections"],
        )
    app.add_middleware(RequestContextMiddleware, metrics=state.metrics)
    return app
