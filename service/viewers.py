"""The live view's feed: each processed batch's report handed to the connected viewers
(``GET /api/v1/stream``, server-sent events) without slowing the tracker.

The tracker's worker calls :meth:`ViewerHub.publish` once per report: with no viewer it
keeps a reference and returns; otherwise it puts one :class:`Frame` (a reference to the
report state and the batch's positions, nothing serialised) in each viewer's one-frame slot,
replacing a frame the viewer has not taken yet (counted as dropped), and wakes the viewer's
event loop. A frame's bytes are built once, by the first viewer that sends it, off the worker:
the report's bytes as published, the tentative tracks and the batch's detection positions.
A viewer that reads slowly or never holds one frame and its socket's buffers, whatever the
rate of reports; the worker never waits for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import orjson

from service.reports import ReportState

__all__ = ["Frame", "ViewerHub", "ViewerSlot"]


class Frame:
    """One report for the viewers; :attr:`data` (JSON bytes) is built on first use, once."""

    __slots__ = ("_data", "_lock", "positions", "seq", "state")

    def __init__(self, state: ReportState, positions: np.ndarray | None = None) -> None:
        self.state = state
        self.seq = int(state.report.get("seq", 0))
        self.positions = positions  # the batch's detections, shape (n, 2), or None
        self._data: bytes | None = None
        self._lock = threading.Lock()

    @property
    def data(self) -> bytes:
        """``{"report": <the Track report as published>, "tentative": [...], "detections":
        [x0, y0, x1, y1, ...]}``."""
        data = self._data
        if data is None:
            with self._lock:
                data = self._data
                if data is None:
                    data = self._data = self._build()
        return data

    def _build(self) -> bytes:
        # Tentative tracks as the view draws them: no covariance, no detection ids.
        tentative = [
            {
                "id": t.id,
                "kind": t.kind,
                "status": t.status,
                "position": t.position,
                "velocity": t.velocity,
                "score": t.score,
                "hits": t.hits,
                "model_probabilities": t.model_probabilities,
            }
            for t in self.state.snapshots()
            if t.status != "confirmed"
        ]
        if self.positions is None or self.positions.size == 0:
            flat: Any = []
        else:
            flat = np.ascontiguousarray(self.positions, dtype=np.float64).ravel()
        rest = orjson.dumps(
            {"tentative": tentative, "detections": flat}, option=orjson.OPT_SERIALIZE_NUMPY
        )
        return b'{"report":' + self.state.data + b"," + rest[1:]


class ViewerSlot:
    """One viewer: the latest frame it has not taken yet, and a wake-up for its event loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop, on_drop: Callable[[], None]) -> None:
        self._loop = loop
        self._on_drop = on_drop
        self._lock = threading.Lock()
        self._frame: Frame | None = None
        self._closed = False
        self._event = asyncio.Event()  # set and cleared on the loop's thread only
        self.dropped = 0

    def offer(self, frame: Frame) -> None:
        """Put ``frame`` in the slot (any thread; never blocks)."""
        with self._lock:
            if self._closed:
                return
            replaced = self._frame is not None
            self._frame = frame
            if replaced:
                self.dropped += 1
        if replaced:
            self._on_drop()
        else:  # the slot was empty: the viewer may be waiting
            self._wake()

    def close(self) -> None:
        """End this viewer's stream (any thread)."""
        with self._lock:
            self._closed = True
        self._wake()

    @property
    def closed(self) -> bool:
        return self._closed

    def _wake(self) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closed: nobody is waiting
            self._loop.call_soon_threadsafe(self._event.set)

    def take(self) -> Frame | None:
        """The frame in the slot, if any, without waiting."""
        with self._lock:
            frame, self._frame = self._frame, None
        return frame

    def skip(self) -> None:
        """Count a frame taken from the slot and not sent (a newer one came first)."""
        with self._lock:
            self.dropped += 1
        self._on_drop()

    async def next(self, timeout: float) -> Frame | None:
        """The next frame, waiting up to ``timeout`` seconds; ``None`` when there is none
        (then check :attr:`closed`)."""
        frame = self.take()
        if frame is not None or self._closed:
            return frame
        self._event.clear()
        frame = self.take()  # one offered between the two looks has set the event already
        if frame is not None:
            return frame
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._event.wait(), timeout)
        return self.take()


class ViewerHub:
    """The connected viewers and the latest frame; thread-safe."""

    def __init__(self, on_drop: Callable[[], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._viewers: tuple[ViewerSlot, ...] = ()
        self._on_drop = on_drop or (lambda: None)
        self.latest: Frame | None = None
        self._closed = False

    def __len__(self) -> int:
        return len(self._viewers)

    def publish(self, state: ReportState, positions: np.ndarray | None = None) -> None:
        """Hand a processed batch's report to every viewer (the tracker's worker, once per
        report). Costs an object and one slot write per viewer; never blocks on a viewer."""
        frame = Frame(state, positions)
        self.latest = frame
        for viewer in self._viewers:  # a tuple replaced as a whole: no lock needed to read
            viewer.offer(frame)

    def connect(self, loop: asyncio.AbstractEventLoop) -> ViewerSlot:
        """A new viewer, its slot holding the latest frame (if any) to start from."""
        slot = ViewerSlot(loop, self._on_drop)
        with self._lock:
            if self._closed:
                slot.close()
            self._viewers = (*self._viewers, slot)
        latest = self.latest
        if latest is not None:
            slot.offer(latest)
        return slot

    def disconnect(self, slot: ViewerSlot) -> None:
        slot.close()
        with self._lock:
            self._viewers = tuple(v for v in self._viewers if v is not slot)

    def close(self) -> None:
        """End every viewer's stream and refuse new ones (the service is stopping)."""
        with self._lock:
            self._closed = True
            viewers = self._viewers
        for viewer in viewers:
            viewer.close()
