"""The REST API: one router per resource, collected in :data:`api_router`."""

from __future__ import annotations

from fastapi import APIRouter

from service.api import (
    config,
    detections,
    extended,
    formation,
    health,
    patterns,
    reset,
    tracks,
)

__all__ = ["api_router"]

api_router = APIRouter()
api_router.include_router(health.router)
api_router.include_router(extended.router, prefix="/api/v1")  # before /tracks/{track_id}
api_router.include_router(formation.router, prefix="/api/v1")  # before /tracks/{track_id}
api_router.include_router(patterns.router, prefix="/api/v1")  # before /tracks/{track_id}
api_router.include_router(tracks.router, prefix="/api/v1")
api_router.include_router(detections.router, prefix="/api/v1")
api_router.include_router(config.router, prefix="/api/v1")
api_router.include_router(reset.router, prefix="/api/v1")
