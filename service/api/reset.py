"""Starting again: ``POST /api/v1/reset``.

Drops every track and what the tracker learned of its sensors, and forgets the last processed
time (:meth:`service.engine.Engine.reset`), so that a recording can be replayed from its start
without restarting the service. It needs ``Authorization: Bearer <token>``; the configuration
stays.
"""

from __future__ import annotations

from fastapi import APIRouter, HTTPException
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, WriteAccess
from service.engine import EngineUnavailable

__all__ = ["router"]

router = APIRouter(tags=["reset"])

#: How long the request waits for the tracker's worker to take the reset (s).
WORKER_TIMEOUT = 5.0

_DESCRIPTION = (
    "Start again: after the batches queued before it, every track of every kind, the "
    "two-point candidates and what was learned of each sensor (detection probability, "
    "coverage, clutter map, usual interval, recent batches) are dropped, and the last "
    "processed time is forgotten, so that batches of any time are taken again (a recording "
    "replayed from its start, which would otherwise be refused as `out_of_sequence`). The "
    "configuration, the report `seq`, the counters and the id counters stay (new ids go on "
    "from the last one given), and the next Track report lists the confirmed tracks dropped "
    "in `deleted`. With a "
    "state file, the empty state is what the next save writes.\\n\\n"
    '**200** `{"reset": true, "seq": n, "dropped": k}` (`k` live tracks dropped); '
    "**401** without the token; **503** when the tracker's worker is not running or did not "
    f"take the request within {WORKER_TIMEOUT:g} s (nothing changed)."
)


@router.post(
    "/reset",
    summary="Drop every track and forget the last processed time",
    description=_DESCRIPTION,
    responses={
        200: {
            "content": {"application/json": {"example": {"reset": True, "seq": 412, "dropped": 57}}}
        },
        401: {"description": "no or a wrong bearer token"},
        503: {"description": "the tracker's worker is not running or busy; nothing changed"},
    },
)
async def reset(engine: EngineDep, _auth: WriteAccess) -> Response:
    try:
        answer = await run_in_threadpool(engine.reset, timeout=WORKER_TIMEOUT)
    except EngineUnavailable as exc:
        raise HTTPException(status_code=503, detail=str(exc)) from None
    return FastJSONResponse(answer)


@router.api_route("/reset", methods=["GET", "PUT", "PATCH", "DELETE"], include_in_schema=False)
async def other_methods() -> Response:
    """Only ``POST`` resets."""
    raise HTTPException(status_code=405, detail="Method Not Allowed")
