"""Schemathesis against the service's own OpenAPI document, on a real server: a bounded run here
(no 5xx, answers that conform to the document); the long run is a documented command
(docs/RELIABILITY.md, `schemathesis run ...`)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from reliability_support import LiveServer, test_settings
from schemathesis import GenerationMode
from schemathesis.checks import (
    content_type_conformance,
    negative_data_rejection,
    not_a_server_error,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

pytest_plugins = ["reliability_fixtures"]

EXAMPLES = int(os.environ.get("FISHLOC_FUZZ_SCALE", "1")) * 12
# positive_data_acceptance is left out: a camera record can match the JSON schema and still be
# refused (id differing from the path, r(θ) not increasing), which no JSON schema can express.
# allow_header_conformance is left out: a 405 on /v1/cameras/{id} lists only GET in `Allow`
# (Starlette answers from the first route that matches the path), see docs/RELIABILITY.md.
CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance,
          response_headers_conformance, response_schema_conformance, negative_data_rejection]


@pytest.fixture(scope="module")
def server(double_model_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings_ = test_settings(double_model_path, tmp_path_factory.mktemp("openapi-fuzz"),
                              max_body_bytes=1024 * 1024, max_pixels=9_000_000)
    with LiveServer(settings_) as live:
        yield live


@pytest.fixture(scope="module")
def api_schema(server: LiveServer) -> schemathesis.BaseSchema:
    return schemathesis.openapi.from_url(f"{server.url}/openapi.json")


def _operations(api_schema: schemathesis.BaseSchema) -> list[schemathesis.APIOperation]:
    return [result.ok() for result in api_schema.get_all_operations()]


def _has_inputs(operation: schemathesis.APIOperation) -> bool:
    definition = operation.definition.raw
    return bool(definition.get("parameters") or definition.get("requestBody"))


# Schemathesis' own pytest plugin does not run under this pytest version, so each operation's case
# strategy (valid and invalid data) drives a plain hypothesis loop.
@pytest.mark.parametrize("mode", [GenerationMode.POSITIVE, GenerationMode.NEGATIVE])
def test_openapi(api_schema: schemathesis.BaseSchema, mode: GenerationMode) -> None:
    operations = _operations(api_schema)
    assert len(operations) >= 9  # every route of the document is fuzzed
    for operation in operations:
        strategy = operation.as_strategy(generation_mode=mode)

        @given(case=strategy)
        @settings(max_examples=EXAMPLES, deadline=None, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
        def run(case: schemathesis.Case) -> None:
            # Some camera ids become `demo`, so detection reaches the pipeline, not just 404.
            camera_id = (case.path_parameters or {}).get("camera_id")
            if camera_id is not None and case.method == "POST" and len(str(camera_id)) % 2 == 0:
                case.path_parameters = {**(case.path_parameters or {}), "camera_id": "demo"}
            case.call_and_validate(checks=CHECKS)

        try:
            run()
        except Unsatisfiable:
            # No invalid request exists for an operation without parameters or body (GET /healthz).
            assert mode == GenerationMode.NEGATIVE and not _has_inputs(operation)
