"""The OpenAPI document tells the truth: schemathesis, with all its checks, against the live
service (every operation, generated valid and invalid requests, with the bearer token).

One check is left out, deliberately: ``positive_data_acceptance`` (a request that fits the
schema must be accepted). The service also refuses, with 422 and a detail naming the rule,
what a JSON schema cannot state: rules across fields (a detection's ``vr`` and the batch's
``sensor_velocity`` and ``max_range`` need the batch's ``sensor_position``; ``motion``'s lists
have one entry per model and its probabilities sum to 1; the confirmation threshold must
exceed the deletion threshold) and rules over time (a batch older than the last processed
one). The operations' descriptions say so.
"""

from __future__ import annotations

from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from schemathesis.checks import positive_data_acceptance
from schemathesis.generation import GenerationMode

from tests.conftest import RunningService

pytestmark = pytest.mark.timeout(300)


@pytest.mark.parametrize("mode", list(GenerationMode), ids=lambda m: m.value)
def test_the_service_keeps_to_its_openapi_document(
    service: RunningService, mode: GenerationMode
) -> None:
    schema = schemathesis.openapi.from_url(f"{service.url}/openapi.json")

    @given(case=schema.as_strategy(generation_mode=mode))
    @settings(
        max_examples=300, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    def check(case: Any) -> None:
        case.call_and_validate(headers=service.auth, excluded_checks=[positive_data_acceptance])

    check()


def test_options_and_method_not_allowed_name_every_method_of_the_path(
    service: RunningService,
) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.options("/api/v1/config")
        assert r.status_code == 204
        assert r.headers["allow"] == "GET, HEAD, OPTIONS, PATCH, PUT"
        r = http.delete("/api/v1/config", headers=service.auth)
        assert r.status_code == 405 and r.headers["allow"] == "GET, HEAD, OPTIONS, PATCH, PUT"
        r = http.options("/api/v1/tracks/T1")
        assert r.status_code == 204 and r.headers["allow"] == "GET, HEAD, OPTIONS"
        assert http.options("/nowhere").status_code == 404
