"""Tracks: ``GET /api/v1/tracks`` (the latest Track report, filtered) and
``GET /api/v1/tracks/{id}``."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, federation_of
from service.schemas import TrackOut, TrackReportOut, parse_kinds

__all__ = ["router"]

router = APIRouter(prefix="/tracks", tags=["tracks"])


@router.get(
    "",
    response_model=TrackReportOut,
    summary="The latest Track report",
    description=(
        "The Track report of the last processed batch. By default it holds the confirmed "
        "tracks, as published on `{prefix}/tracks`; `status=all` adds the tentative tracks, "
        "`status=tentative` keeps only those; `kind` (comma-separated) keeps those kinds "
        "(`individual`, `extended`, `formation`; another gets a 422). "
        "With the setting `federate` (scale-out), every instance's tracks, gathered over "
        "Zenoh within `federate_timeout`, each with its `instance`, and `instances` saying "
        "which answered."
    ),
)
async def list_tracks(
    request: Request,
    engine: EngineDep,
    status: Annotated[
        Literal["confirmed", "tentative", "all"], Query(description="which tracks")
    ] = "confirmed",
    kind: Annotated[
        str | None,
        Query(description="individual, extended or formation (comma-separated)"),
    ] = None,
) -> Response:
    try:
        kinds = parse_kinds(kind) or None if kind else None
    except ValueError as exc:  # as FastAPI answers a bad status: a 422 in its schema
        error = {"type": "value_error", "loc": ["query", "kind"], "msg": str(exc), "input": kind}
        raise RequestValidationError([error]) from None
    federation = federation_of(request)
    if federation is not None:
        answer = await run_in_threadpool(federation.federated_tracks, status, kinds)
        return FastJSONResponse(answer)
    if kind is None and status == "confirmed":
        return Response(engine.latest_report_bytes(), media_type="application/json")
    return FastJSONResponse(engine.tracks(status, kinds))


@router.get(
    "/{track_id}",
    response_model=TrackOut,
    summary="One live track (tentative ones too)",
    responses={404: {"description": "no live track has this id"}},
)
async def get_track(request: Request, track_id: str, engine: EngineDep) -> Response:
    federation = federation_of(request)
    if federation is not None:
        track = await run_in_threadpool(federation.federated_track, track_id)
    else:
        track = engine.track(track_id)
    if track is None:
        raise HTTPException(status_code=404, detail=f"no live track {track_id!r}")
    return FastJSONResponse(track)
