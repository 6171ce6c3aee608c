"""Liveness, counters and metrics: ``GET /health``, ``GET /api/v1/stats``, ``GET /metrics``."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, StatsDep
from service.schemas import StatsOut

__all__ = ["router"]

router = APIRouter(tags=["health"])

_PROMETHEUS = "text/plain; version=0.0.4; charset=utf-8"


@router.get(
    "/health",
    summary="Is the service up?",
    responses={
        200: {"content": {"application/json": {"example": {"status": "ok"}}}},
        503: {"description": "the tracker worker is not running"},
    },
)
async def health(engine: EngineDep) -> Response:
    if not engine.running:
        return FastJSONResponse(
            {"status": "error", "detail": "the tracker worker is not running"}, status_code=503
        )
    return FastJSONResponse({"status": "ok"})


@router.get("/api/v1/stats", response_model=StatsOut, summary="Counters and processing times")
async def stats(stats: StatsDep) -> Response:
    return FastJSONResponse(stats.snapshot())


@router.get(
    "/metrics",
    summary="Counters, gauges and histograms in Prometheus text format",
    response_class=Response,
    responses={200: {"content": {_PROMETHEUS: {}}}},
)
async def metrics(stats: StatsDep) -> Response:
    return Response(stats.prometheus(), media_type=_PROMETHEUS)
