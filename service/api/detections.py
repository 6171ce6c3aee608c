"""Ingest over REST: ``POST /api/v1/detections`` takes one Detection batch.

The batch is validated in the request (422 with an Error report when it breaks the
contract), then queued for the tracker like a Zenoh batch; the answer waits for the tracker:
202 with the Track report's ``seq``, 422 when the tracker refused it (out of sequence), 503
when the ingest queue stayed full.
"""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse
from service.schemas import BatchError, ErrorReportOut, IngestAcceptedOut

__all__ = ["router"]

router = APIRouter(prefix="/detections", tags=["detections"])

_BODY: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/DetectionBatchIn"}}
        },
    }
}


@router.post(
    "",
    status_code=202,
    response_model=IngestAcceptedOut,
    summary="Ingest one Detection batch",
    openapi_extra=_BODY,
    responses={
        422: {"model": ErrorReportOut, "description": "refused: the Error report says why"},
        503: {"model": ErrorReportOut, "description": "dropped: the ingest queue stayed full"},
    },
)
async def post_detections(request: Request, engine: EngineDep) -> Response:
    payload = await request.body()
    try:
        batch = engine.check(payload)
    except BatchError as exc:
        report = engine.reject(payload, None, exc.reason, exc.detail)
        return FastJSONResponse(report, status_code=422)
    future = await run_in_threadpool(engine.submit, payload, None, "rest", batch=batch)
    wait = 30.0 + 2.0 * engine.ingest.reorder_window
    try:
        result = await asyncio.wait_for(asyncio.wrap_future(future), timeout=wait)
    except TimeoutError:
        return FastJSONResponse({"accepted": True, "seq": None}, status_code=202)
    if result.accepted:
        return FastJSONResponse({"accepted": True, "seq": result.seq}, status_code=202)
    report = result.error or {}
    code = 503 if report.get("error") == "overloaded" else 422
    return FastJSONResponse(report, status_code=code)
