"""Extended tracks started by hand: ``POST /api/v1/tracks/extended``.

The request (:class:`~service.schemas.ExtendedTrackIn`) gives a centroid, a velocity and an
extent prior; it needs ``Authorization: Bearer <token>``. It is validated in the request's
thread (422 naming the field), then the tracker's worker starts the track between two
batches (:meth:`service.engine.Engine.start_extended_track`) and the answer is the new Track
(201), listed at once by ``GET /api/v1/tracks`` (the next published Track report has it too).
Nothing changes when the answer is not 201.
"""

from __future__ import annotations

import functools
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response

from service.api.deps import EngineDep, WriteAccess
from service.api.track_commands import json_body, run_track_command
from service.schemas import ExtendedTrackIn, TrackOut, decode_extended_track

__all__ = ["MAX_BODY_BYTES", "router"]

router = APIRouter(prefix="/tracks", tags=["tracks"])

#: The largest request body (bytes): a request is a few hundred.
MAX_BODY_BYTES = 64 * 1024
#: How long the request waits for the tracker's worker to take the command (s).
WORKER_TIMEOUT = 5.0


_DESCRIPTION = (
    "Start a **confirmed** extended track from a centroid (`position`), a `velocity` and an "
    'extent prior: either `{"matrix": [[a, b], [b, c]]}` (symmetric positive definite, m²) or '
    '`{"semi_axes": [major, minor], "orientation": rad}` (exactly one of the two forms). '
    "The track starts at the time of the last processed batch, or at `time` (s) if given: "
    "never before the last processed batch, nor more than `ingest.max_time_jump` after it; "
    "before the first batch `time` is required. The answer is the new Track (`kind` "
    "`extended`), listed at once by `GET /api/v1/tracks?kind=extended` and "
    "`GET /api/v1/tracks/{id}`; Track reports over Zenoh carry it from the next batch on.\n\n"
    "Refusals change nothing: **422** for bad input (`detail` names the field; besides the "
    "schema's types and bounds: the extent matrix must be positive definite, and the time "
    "rules above), **409** when extended tracking is switched off in the configuration "
    "(`extended.enabled` false), **503** when the tracker's worker is not running or did not "
    f"take the request within {WORKER_TIMEOUT:g} s."
)


@router.post(
    "/extended",
    status_code=201,
    response_model=TrackOut,
    summary="Start an extended track by hand",
    description=_DESCRIPTION,
    openapi_extra=json_body(ExtendedTrackIn, "the track's centroid, velocity and extent prior"),
    responses={
        201: {"description": "the new Track"},
        401: {"description": "no or a wrong bearer token"},
        409: {"description": "extended tracking is switched off (`extended.enabled` false)"},
        422: {"description": "invalid: `detail` names the field; nothing changed"},
        503: {"description": "the tracker's worker is not running or busy; nothing changed"},
    },
)
async def start_extended_track(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    def command(body: ExtendedTrackIn) -> functools.partial[dict[str, Any]]:
        return functools.partial(
            engine.start_extended_track,
            body.position,
            body.velocity,
            body.extent_matrix(),
            position_std=body.position_std,
            velocity_std=body.velocity_std,
            expected_detections=body.expected_detections,
            at=body.time,
            timeout=WORKER_TIMEOUT,
        )

    return await run_track_command(request, MAX_BODY_BYTES, decode_extended_track, command)


@router.api_route("/extended", methods=["GET", "PUT", "PATCH", "DELETE"], include_in_schema=False)
async def other_methods() -> Response:
    """``/tracks/extended`` is no track id: its other methods are not allowed (the ``Allow``
    header is set by :class:`service.api.methods.AllowedMethods`)."""
    raise HTTPException(status_code=405, detail="Method Not Allowed")
