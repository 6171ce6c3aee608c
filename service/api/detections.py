"""Ingest over REST: ``POST /api/v1/detections`` takes one Detection batch.

The body is read up to ``max_batch_bytes`` (a larger one is read to its end, kept nowhere, and
refused as ``batch_too_large``), then validated off the event loop (422 with an Error report
when it breaks the contract), then queued for the tracker like a Zenoh batch; the answer
waits for the tracker: 202 with the Track report's ``seq``, 422 when the tracker refused it
(out of sequence, a duplicate), 503 when the ingest queue stayed full; 202 with ``seq`` null
at once when the reorder window holds the batch back.

At most :data:`INGEST_SLOTS` batches are read and validated at once: each holds its payload
and what validating it costs, so many senders at once do not multiply that; the others wait
their turn (their bodies wait in the socket). They are validated on as many threads of their
own, not the server's pool of 40: the C allocator keeps memory a thread freed for that
thread's reuse, and 40 threads that each validated a large batch would hold 40 times that.
Nothing heavy runs on the event loop, so ``/health`` and the other endpoints answer while a
large batch is handled.
"""

from __future__ import annotations

import asyncio
import functools
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse
from service.payload import too_large_detail
from service.schemas import BatchError, ErrorReportOut, IngestAcceptedOut

__all__ = ["INGEST_SLOTS", "read_body", "router"]

router = APIRouter(prefix="/detections", tags=["detections"])

#: Batches read and validated at once.
INGEST_SLOTS = 2
#: A body this many times over ``max_batch_bytes`` is not read to its end: the answer goes
#: at once and the connection is closed.
DRAIN_FACTOR = 16

_BODY: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": {"$ref": "#/components/schemas/DetectionBatchIn"}}
        },
    }
}


async def read_body(request: Request, limit: int) -> tuple[bytes | None, int]:
    """The request's body and its size; ``None`` for the body when it is over ``limit``
    bytes (what is past the limit is counted, not kept; reading stops
    :data:`DRAIN_FACTOR` times past it)."""
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size <= limit:
            chunks.append(chunk)
            continue
        chunks = []
        if size > DRAIN_FACTOR * limit:
            break
    return (b"".join(chunks) if size <= limit else None), size


_decoders = ThreadPoolExecutor(INGEST_SLOTS, thread_name_prefix="rest-ingest")


def _slots(request: Request) -> asyncio.Semaphore:
    state = request.app.state
    slots: asyncio.Semaphore | None = getattr(state, "ingest_slots", None)
    if slots is None:
        slots = state.ingest_slots = asyncio.Semaphore(INGEST_SLOTS)
    return slots


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
    async with _slots(request):
        limit = engine.max_batch_bytes
        payload, size = await read_body(request, limit)
        if payload is None:
            detail = too_large_detail(size, limit)
            report = engine.refuse_unread(size, None, "batch_too_large", detail)
            return FastJSONResponse(report, status_code=422)
        loop = asyncio.get_running_loop()
        try:
            batch = await loop.run_in_executor(_decoders, engine.check, payload)
        except BatchError as exc:
            reject = functools.partial(engine.reject, payload, None, exc.reason, exc.detail)
            report = await loop.run_in_executor(_decoders, reject)
            return FastJSONResponse(report, status_code=422)
    # A batch the reorder window holds back is answered at once (seq null): it may wait up to
    # the window, and the sender need not.
    held = asyncio.Event()
    submit = functools.partial(
        engine.submit,
        payload,
        None,
        "rest",
        batch=batch,
        on_held=lambda: loop.call_soon_threadsafe(held.set),
    )
    future = asyncio.wrap_future(await run_in_threadpool(submit))
    held_wait = asyncio.ensure_future(held.wait())
    try:
        await asyncio.wait({future, held_wait}, timeout=30.0, return_when=asyncio.FIRST_COMPLETED)
    finally:
        held_wait.cancel()
    if not future.done():
        return FastJSONResponse({"accepted": True, "seq": None}, status_code=202)
    result = future.result()
    if result.accepted:
        return FastJSONResponse({"accepted": True, "seq": result.seq}, status_code=202)
    report = result.error or {}
    code = 503 if report.get("error") == "overloaded" else 422
    return FastJSONResponse(report, status_code=code)
