"""Point-pattern tracks started by hand: ``POST /api/v1/tracks/pattern``.

The request (:class:`~service.schemas.PatternTrackIn`) names a configured reference pattern
(``point_patterns.patterns``) and gives the target frame's origin, velocity and attitude; it
needs ``Authorization: Bearer <token>``. It is validated in the request's thread (422 naming
the field), then the tracker's worker starts the track between two batches
(:meth:`service.engine.Engine.start_pattern_track`) and the answer is the new Track (201,
``kind`` ``extended`` with ``attitude`` and ``shape_probabilities``), listed at once by
``GET /api/v1/tracks``. Nothing changes when the answer is not 201.
"""

from __future__ import annotations

import functools
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response

from service.api.deps import EngineDep, WriteAccess
from service.api.track_commands import json_body, run_track_command
from service.schemas import PatternTrackIn, TrackOut, decode_pattern_track

__all__ = ["MAX_BODY_BYTES", "router"]

router = APIRouter(prefix="/tracks", tags=["tracks"])

#: The largest request body (bytes): a request is a few hundred.
MAX_BODY_BYTES = 16 * 1024
#: How long the request waits for the tracker's worker to take the command (s).
WORKER_TIMEOUT = 5.0

_DESCRIPTION = (
    "Start a **confirmed** point-pattern track: a target that shows the reference `pattern` "
    "(a name of the configuration's `point_patterns.patterns`), its frame's origin at "
    "`position` moving at `velocity`, its frame's x axis at `attitude` (rad) from the global "
    "x axis, so that pattern point p is seen at position + R(attitude) p. The track starts at "
    "the time of the last processed batch, or at `time` (s) if given: never before the last "
    "processed batch, nor more than `ingest.max_time_jump` after it; before the first batch "
    "`time` is required. The answer is the new Track (`kind` `extended`, with `attitude` and "
    "`shape_probabilities`), listed at once by `GET /api/v1/tracks`; Track reports over Zenoh "
    "carry it from the next batch on.\n\n"
    "Refusals change nothing: **422** for bad input (`detail` names the field: an unknown "
    "pattern, the time rules above), **409** when point-pattern tracking is switched off "
    "(`point_patterns.enabled` false), **503** when the tracker's worker is not running or "
    f"did not take the request within {WORKER_TIMEOUT:g} s."
)


@router.post(
    "/pattern",
    status_code=201,
    response_model=TrackOut,
    summary="Start a point-pattern track by hand",
    description=_DESCRIPTION,
    openapi_extra=json_body(PatternTrackIn, "the pattern, position, velocity and attitude"),
    responses={
        201: {"description": "the new Track"},
        401: {"description": "no or a wrong bearer token"},
        409: {
            "description": "point-pattern tracking is switched off (`point_patterns.enabled` false)"
        },
        422: {"description": "invalid: `detail` names the field; nothing changed"},
        503: {"description": "the tracker's worker is not running or busy; nothing changed"},
    },
)
async def start_pattern_track(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    def command(body: PatternTrackIn) -> functools.partial[dict[str, Any]]:
        return functools.partial(
            engine.start_pattern_track,
            body.pattern,
            body.position,
            body.velocity,
            body.attitude,
            attitude_rate=body.attitude_rate,
            position_std=body.position_std,
            velocity_std=body.velocity_std,
            attitude_std=body.attitude_std,
            at=body.time,
            timeout=WORKER_TIMEOUT,
        )

    return await run_track_command(request, MAX_BODY_BYTES, decode_pattern_track, command)


@router.api_route("/pattern", methods=["GET", "PUT", "PATCH", "DELETE"], include_in_schema=False)
async def other_methods() -> Response:
    """``/tracks/pattern`` is no track id: its other methods are not allowed."""
    raise HTTPException(status_code=405, detail="Method Not Allowed")
