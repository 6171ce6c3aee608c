"""Tracks: ``GET /api/v1/tracks`` (the latest Track report, filtered) and
``GET /api/v1/tracks/{id}``."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse
from service.schemas import TrackOut, TrackReportOut

__all__ = ["router"]

router = APIRouter(prefix="/tracks", tags=["tracks"])


@router.get(
    "",
    response_model=TrackReportOut,
    summary="The latest Track report",
    description=(
        "The Track report of the last processed batch. By default it holds the confirmed "
        "tracks, as published on `{prefix}/tracks`; `status=all` adds the tentative tracks, "
        "`status=tentative` keeps only those; `kind` (comma-separated) keeps those kinds."
    ),
)
async def list_tracks(
    engine: EngineDep,
    status: Annotated[
        Literal["confirmed", "tentative", "all"], Query(description="which tracks")
    ] = "confirmed",
    kind: Annotated[
        str | None,
        Query(description="individual, extended or formation (comma-separated)"),
    ] = None,
) -> Response:
    if kind is None and status == "confirmed":
        return Response(engine.latest_report_bytes(), media_type="application/json")
    kinds = {k.strip() for k in kind.split(",") if k.strip()} if kind else None
    return FastJSONResponse(engine.tracks(status, kinds))


@router.get(
    "/{track_id}",
    response_model=TrackOut,
    summary="One live track (tentative ones too)",
    responses={404: {"description": "no live track has this id"}},
)
async def get_track(track_id: str, engine: EngineDep) -> Response:
    track = engine.track(track_id)
    if track is None:
        raise HTTPException(status_code=404, detail=f"no live track {track_id!r}")
    return FastJSONResponse(track)
