"""Formations formed by hand: ``POST /api/v1/tracks/formation``.

The request (:class:`~service.schemas.FormationIn`) names live individual tracks; it needs
``Authorization: Bearer <token>``. It is validated in the request's thread (422 naming the
field), then the tracker's worker checks the ids (:meth:`service.engine.Engine.form_formation`)
and answers with the formation's Track (201); the formation takes its members over at the next
batch, from which Track reports carry it, its members with ``formation_id``. Nothing changes
when the answer is not 201.
"""

from __future__ import annotations

import functools
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import Response

from service.api.deps import EngineDep, WriteAccess
from service.api.track_commands import json_body, run_track_command
from service.schemas import FormationIn, TrackOut, decode_formation

__all__ = ["router"]

router = APIRouter(prefix="/tracks", tags=["tracks"])

#: The largest request body (bytes).
MAX_BODY_BYTES = 16 * 1024
#: How long the request waits for the tracker's worker to take the command (s).
WORKER_TIMEOUT = 5.0

_DESCRIPTION = (
    "Form a **formation** from live individual tracks (`members`, at least 2 ids, each in no "
    "formation yet). The answer is the formation's Track (`kind` `formation`, `members`) as "
    "of now; the formation takes its members over at the next batch (those still live then; "
    "fewer than 2 and it is dropped), and from then on Track reports carry it and its members "
    "carry `formation_id`. A member that leaves the formation is handed back as an individual "
    "track.\\n\\n"
    "Refusals change nothing: **422** for bad input (`detail` names the field: an unknown or "
    "repeated id, one already in a formation, no batch processed yet), **409** when formation "
    "tracking is switched off (`formation.enabled` false), **503** when the tracker's worker "
    f"is not running or did not take the request within {WORKER_TIMEOUT:g} s."
)


@router.post(
    "/formation",
    status_code=201,
    response_model=TrackOut,
    summary="Form a formation from individual tracks",
    description=_DESCRIPTION,
    openapi_extra=json_body(FormationIn, "the member track ids"),
    responses={
        201: {"description": "the formation's Track"},
        401: {"description": "no or a wrong bearer token"},
        409: {"description": "formation tracking is switched off (`formation.enabled` false)"},
        422: {"description": "invalid: `detail` names the field; nothing changed"},
        503: {"description": "the tracker's worker is not running or busy; nothing changed"},
    },
)
async def form_formation(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    def command(body: FormationIn) -> functools.partial[dict[str, Any]]:
        return functools.partial(engine.form_formation, list(body.members), timeout=WORKER_TIMEOUT)

    return await run_track_command(request, MAX_BODY_BYTES, decode_formation, command)


@router.api_route("/formation", methods=["GET", "PUT", "PATCH", "DELETE"], include_in_schema=False)
async def other_methods() -> Response:
    """``/tracks/formation`` is no track id: its other methods are not allowed."""
    raise HTTPException(status_code=405, detail="Method Not Allowed")
