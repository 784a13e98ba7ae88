"""The model being served."""

from __future__ import annotations

from fastapi import APIRouter

from service.http.dependencies import State
from service.http.schemas import ModelResponse

router = APIRouter(tags=["model"])


@router.get("/v1/model", response_model=ModelResponse,
            summary="Model name, version, input size, training data")
async def get_model(state: State) -> dict[str, object]:
    return state.runner.pipeline.info.public()
