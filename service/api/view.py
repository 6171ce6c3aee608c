"""The live view: ``GET /view`` (the page; its files under ``/view/assets/``), ``GET /``
(a redirect to it) and ``GET /api/v1/stream``, the reports as server-sent events.

The stream sends each viewer the latest report as it comes (the tracker's worker only puts it
in the viewer's one-frame slot, :mod:`service.viewers`), at most :data:`MAX_FRAMES_PER_SECOND`
a second; a frame not sent before a newer one arrived is dropped and counted
(``tracker_view_frames_dropped_total``).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, RedirectResponse, Response, StreamingResponse
from starlette.concurrency import run_in_threadpool

from service.api.deps import EngineDep
from service.engine import Engine
from service.viewers import Frame

__all__ = ["KEEPALIVE_SECONDS", "MAX_FRAMES_PER_SECOND", "VIEW_DIR", "router", "sse_frames"]

#: The live view's static files (HTML, CSS, JavaScript), shipped in the package.
VIEW_DIR = Path(__file__).resolve().parent.parent / "view"

#: At most this many frames a second to one viewer; newer frames replace unsent ones.
MAX_FRAMES_PER_SECOND = 10.0

#: A comment line after this many seconds without a frame, so a vanished viewer is noticed.
KEEPALIVE_SECONDS = 10.0

router = APIRouter(include_in_schema=False)


@router.get("/")
async def root() -> Response:
    return RedirectResponse("/view", status_code=307)


@router.get("/view")
async def view_page() -> Response:
    return FileResponse(VIEW_DIR / "index.html", media_type="text/html; charset=utf-8")


def _frame_data(frame: Frame) -> bytes:
    return frame.data


def _event(frame: Frame, data: bytes) -> bytes:
    return b"event: report\nid: %d\ndata: " % frame.seq + data + b"\n\n"


async def sse_frames(
    engine: Engine,
    max_rate: float = MAX_FRAMES_PER_SECOND,
    keepalive: float = KEEPALIVE_SECONDS,
) -> AsyncIterator[bytes]:
    """The server-sent events of one viewer, from the latest report on, until the service
    stops or the viewer goes away."""
    hub = engine.view
    slot = hub.connect(asyncio.get_running_loop())
    try:
        if hub.latest is None:  # nothing processed since start: the state as it is
            slot.offer(Frame(engine.report_state))
        yield b"retry: 2000\n\n"
        interval = 1.0 / max_rate
        last = -interval
        while not slot.closed:
            frame = await slot.next(keepalive)
            if frame is None:
                if not slot.closed:
                    yield b": keep-alive\n\n"
                continue
            wait = last + interval - time.monotonic()
            if wait > 0:  # newer frames may replace this one meanwhile: send the newest
                await asyncio.sleep(wait)
                newer = slot.take()
                if newer is not None:
                    slot.skip()
                    frame = newer
            # built once per frame, off the event loop (tentative tracks are converted then)
            data = await run_in_threadpool(_frame_data, frame)
            last = time.monotonic()
            yield _event(frame, data)
    finally:
        hub.disconnect(slot)


@router.get("/api/v1/stream")
async def stream(engine: EngineDep) -> Response:
    return StreamingResponse(
        sse_frames(engine),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )
