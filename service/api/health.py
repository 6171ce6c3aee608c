"""Liveness, readiness, counters and metrics: ``GET /health``, ``GET /ready``,
``GET /api/v1/stats``, ``GET /metrics``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from fastapi import APIRouter, Request
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, StatsDep
from service.schemas import StatsOut

if TYPE_CHECKING:
    from service.main import ServiceRuntime

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


_READY_EXAMPLE = {
    "status": "ready",
    "zenoh": {"open": True, "connected": True, "mode": "peer", "routers": 1, "peers": 0},
    "worker": {"running": True},
}
_NOT_READY_EXAMPLE = {
    "status": "not_ready",
    "zenoh": {"open": True, "connected": False, "mode": "client", "routers": 0, "peers": 0},
    "worker": {"running": True},
    "detail": "the Zenoh session reaches no router or peer (connect tcp/router:7447)",
}


@router.get(
    "/ready",
    summary="Can the service take detections now?",
    description=(
        "200 when the Zenoh session is open (and, when the service connects to others, "
        "reaches a router or peer) and the tracker worker is running; 503 otherwise, with "
        "`detail` naming what is not ready. `/health` is the liveness check."
    ),
    responses={
        200: {"content": {"application/json": {"example": _READY_EXAMPLE}}},
        503: {
            "description": "Zenoh not connected or the worker not running",
            "content": {"application/json": {"example": _NOT_READY_EXAMPLE}},
        },
    },
)
def ready(request: Request) -> Response:
    # a plain function: FastAPI runs it in its thread pool, so the Zenoh calls it makes
    # never hold up the event loop
    runtime: ServiceRuntime = request.app.state.runtime
    state = runtime.readiness()
    return FastJSONResponse(state, status_code=200 if state["status"] == "ready" else 503)


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
