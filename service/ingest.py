"""What happens to a batch before the tracker: the edge checks (:func:`check_batch`), the
memory of recent batches that refuses exact duplicates (:class:`RecentBatches`), the
time-jump guard (:func:`time_jump_detail`), the reorder window (:class:`ReorderBuffer`), and
refusals (:class:`Refusals`: counted, reported, drops logged at most once a second).

Every check that costs in proportion to the payload comes after one that bounds it: its size
first, then what it holds (:func:`service.payload.check_cost`), before it is parsed.

A refused batch gets an Error report naming its sensor and time where they can be read, even
from a payload that failed validation (:func:`peek`, which reads at most a bounded effort).
"""

from __future__ import annotations

import bisect
import functools
import hashlib
import heapq
import itertools
import json
import logging
import math
import re
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any, TypeVar

import orjson

from service.payload import (
    DEFAULT_MAX_BATCH_BYTES,
    check_cost,
    duplicate_key_detail,
    duplicate_keys,
    too_large_detail,
)
from service.reports import ReportOut, error_report_for
from service.schemas import (
    MAX_REORDER_WINDOW,
    BatchError,
    DetectionBatchIn,
    IngestConfig,
    decode_batch,
    valid_sensor_id,
)
from service.stats import Stats

__all__ = [
    "REVISIT_FACTOR",
    "IngestResult",
    "Item",
    "RecentBatches",
    "Refusals",
    "ReorderBuffer",
    "SensorClocks",
    "batch_digest",
    "check_batch",
    "peek",
    "time_jump_detail",
]

log = logging.getLogger("service.ingest")


@dataclass(frozen=True)
class IngestResult:
    """What became of one submitted batch: accepted with the Track report's ``seq``, or
    refused with its Error report. ``seq`` is ``None`` while a batch is held for reordering
    (never in a resolved future)."""

    accepted: bool
    seq: int | None = None
    error: dict[str, Any] | None = None


@dataclass
class Item:
    """One submitted batch on its way to the tracker. ``key_sensor_id``: the Zenoh key's last
    chunk (``None`` over REST); ``batch``: the batch if the submitter validated it already;
    ``digest``: its :func:`batch_digest` once accepted."""

    payload: bytes
    key_sensor_id: str | None
    source: str
    future: Future[IngestResult]
    batch: DetectionBatchIn | None = None
    arrived: float = field(default_factory=time.monotonic)
    digest: bytes | None = None
    #: Called (on the worker) when the batch is held back by the reorder window.
    on_held: Callable[[], None] | None = None


def check_batch(
    payload: bytes,
    key_sensor_id: str | None,
    ingest: IngestConfig,
    max_bytes: int = DEFAULT_MAX_BATCH_BYTES,
) -> DetectionBatchIn:
    """Decode and validate one batch against the contract and the ingest limits; raise
    :class:`~service.schemas.BatchError` when it is refused.

    In order of cost: the payload's size (``max_bytes``), what it holds counted from its bytes
    (at most ``ingest.max_detections_per_batch`` detections and the JSON values a batch of
    them can have), then parsing and validation, which stop at the first bad detection; then
    keys that JSON parsers would take twice, keeping the last."""
    size = len(payload)
    if size > max_bytes:
        raise BatchError("batch_too_large", too_large_detail(size, max_bytes))
    exact = check_cost(payload, ingest.max_detections_per_batch)
    batch = decode_batch(payload)
    dropped = duplicate_keys(payload, batch, exact)
    if dropped:
        raise BatchError("invalid_batch", duplicate_key_detail(payload, dropped))
    if key_sensor_id is not None and batch.sensor_id != key_sensor_id:
        raise BatchError(
            "sensor_mismatch",
            f"sensor_id: {batch.sensor_id!r} differs from the key's last chunk {key_sensor_id!r}",
        )
    n = len(batch.detections)
    if n > ingest.max_detections_per_batch:
        raise BatchError(
            "too_many_detections",
            f"detections: {n} detections, more than ingest.max_detections_per_batch "
            f"= {ingest.max_detections_per_batch}",
        )
    return batch


def time_jump_detail(
    batch_time: float,
    last: float,
    max_jump: float,
    waited: float,
    revisit: float = 0.0,
    window: float = 0.0,
) -> str | None:
    """Why a batch at ``batch_time`` is too far ahead of the last processed time ``last``, or
    ``None`` when it is not.

    It may run ahead by the ``waited`` seconds of wall time since ``last`` was processed plus
    its allowance ``max(max_jump, REVISIT_FACTOR · revisit)``, ``revisit`` being its sensor's
    usual interval between batches (:class:`SensorClocks`): a sensor that reports every 10 s,
    replayed faster than real time, moves the time on by 10 s a batch; and by the reorder
    ``window``, since batches that recent may still be held back. Further ahead, its
    clock is wrong: taking the batch would coast every track of every sensor to that time
    (deleting them) and put every later batch out of sequence."""
    allowed = max(max_jump, REVISIT_FACTOR * revisit)
    if batch_time - last <= allowed + waited + window:
        return None
    why = f"ingest.max_time_jump = {max_jump} s"
    if allowed > max_jump:
        why = f"{REVISIT_FACTOR:g} times the sensor's usual {revisit:.3g} s between batches"
    if window:
        why += f" plus the {window:g} s reorder window"
    if batch_time - last > MAX_REORDER_WINDOW + waited:
        remedy = (
            "this sensor's clock and that of the sensors before it differ: all sensors must "
            "share one time line, such as Unix time in seconds; the service keeps the time "
            "line of the batches it processed until POST /api/v1/reset"
        )
    else:  # (a newcomer's second run, on a later time line, was refused batch by batch)
        remedy = (
            "if this sensor's clock is right, raise ingest.max_time_jump: PATCH /api/v1/config"
            "; if every sensor moved on to a new run or recording: POST /api/v1/reset (with the "
            "API token) drops the tracks and the last time first"
        )
    return (
        f"time {batch_time} is {batch_time - last:.6g} s after the last processed time {last}: "
        f"more than {why} plus the {waited:.3g} s of wall time since ({remedy})"
    )


#: A batch may run ahead of the service's time by this many times its sensor's usual interval.
REVISIT_FACTOR = 2.0


_V = TypeVar("_V")


def _recently_seen(
    by_sensor: OrderedDict[str, _V],
    sensor_id: str,
    make: Callable[[], _V],
    most: int,
    forget: Callable[[str], None] | None = None,
) -> _V:
    """``sensor_id``'s entry of a per-sensor memory, made by ``make`` if it has none, now the
    most recently seen; beyond ``most`` sensors the least recently seen is forgotten (and
    ``forget`` called with it)."""
    entry = by_sensor.get(sensor_id)
    if entry is None:
        entry = by_sensor[sensor_id] = make()
        if len(by_sensor) > most:
            gone, _ = by_sensor.popitem(last=False)
            if forget is not None:
                forget(gone)
    else:
        by_sensor.move_to_end(sensor_id)
    return entry


_monotonic = time.monotonic


#: A sensor is due for a time up to this fraction of its interval before its expected time:
#: two sensors on one tick stamp their batches some microseconds to milliseconds apart.
DUE_JITTER = 0.05


class SensorClocks:
    """Each sensor's usual interval between batches: the median of the gaps between the times
    of its last ``gaps + 1`` accepted batches, for the last ``sensors`` sensors seen (least
    recently seen forgotten first); and when each is due next (its last time plus that
    interval), kept sorted. Used by one thread (the worker)."""

    def __init__(self, gaps: int = 8, sensors: int = 1024) -> None:
        self.gaps = gaps
        self.sensors = sensors
        self._times: OrderedDict[str, deque[float]] = OrderedDict()
        self._interval: dict[str, float] = {}
        self._wall: dict[str, float] = {}
        self._due: list[tuple[float, str]] = []  # (next due time, sensor), ascending
        self._due_of: dict[str, float] = {}
        self._latest = -math.inf  # the latest time accepted
        self._longest = 0.0  # no interval has been longer

    def accepted(self, sensor_id: str, time: float, wall: float | None = None) -> None:
        make = functools.partial(deque, maxlen=self.gaps + 1)
        times = _recently_seen(self._times, sensor_id, make, self.sensors, self._forget)
        times.append(time)
        gaps = sorted(b - a for a, b in pairwise(times) if b > a)
        interval = gaps[len(gaps) // 2] if gaps else 0.0
        self._interval[sensor_id] = interval
        self._longest = max(self._longest, interval)
        self._wall[sensor_id] = _monotonic() if wall is None else wall
        self._latest = max(self._latest, time)
        self._undue(sensor_id)
        if interval > 0.0:
            due = time + interval
            bisect.insort(self._due, (due, sensor_id))
            self._due_of[sensor_id] = due

    def _forget(self, sensor_id: str) -> None:
        self._interval.pop(sensor_id, None)
        self._wall.pop(sensor_id, None)
        self._undue(sensor_id)

    def _undue(self, sensor_id: str) -> None:
        due = self._due_of.pop(sensor_id, None)
        if due is not None:
            k = bisect.bisect_left(self._due, (due, sensor_id))
            del self._due[k]

    def expected_before(
        self, time: float, sensor_id: str, now: float, busy: set[str], recent: float = 10.0
    ) -> bool:
        """Whether another sensor, not in ``busy`` (those with a batch waiting already) and
        heard from within ``recent`` seconds of wall time, is due to send a batch of ``time``
        or earlier: its last time plus its usual interval is at most ``time`` (plus
        :data:`DUE_JITTER` of that interval), and it is not late by a whole interval more
        (then it missed a beat, and nothing waits for it). Looks only at the sensors due by
        then, in due order; those late for every time still to come are dropped."""
        stale: list[tuple[float, str]] = []
        found = False
        for due, other in self._due:
            interval = self._interval[other]
            if due + interval <= self._latest:
                stale.append((due, other))  # late for every batch not out of sequence
                continue
            if due > time + DUE_JITTER * interval:
                if due > time + DUE_JITTER * self._longest:
                    break  # so is every sensor after it
                continue
            if (
                other != sensor_id
                and other not in busy
                and time < due + interval
                and now - self._wall[other] <= recent
            ):
                found = True
                break
        for _, other in stale:
            self._undue(other)
        return found

    def revisit(self, sensor_id: str) -> float:
        """The sensor's usual interval between batches (s), 0 before its second batch."""
        return self._interval.get(sensor_id, 0.0)


class ReorderBuffer:
    """Valid batches held in time order. A batch goes once the newest batch time received,
    minus the window ``W``, has passed it, or once one held batch has waited ``W`` seconds of
    wall time (and with it everything older). Used by one thread (the worker)."""

    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Item, DetectionBatchIn]] = []
        self._counter = itertools.count()
        self.newest_time = -math.inf

    def __len__(self) -> int:
        return len(self._heap)

    def hold(self, item: Item, batch: DetectionBatchIn) -> None:
        self.newest_time = max(self.newest_time, batch.time)
        heapq.heappush(self._heap, (batch.time, next(self._counter), item, batch))

    def wait_time(self, now: float, window: float) -> float | None:
        """Seconds until the oldest arrival has waited ``window``; ``None`` when empty."""
        if not self._heap:
            return None
        oldest_arrival = min(entry[2].arrived for entry in self._heap)
        return max(0.0, oldest_arrival + window - now)

    def sensors(self) -> set[str]:
        """The sensors with a batch held."""
        return {entry[3].sensor_id for entry in self._heap}

    @property
    def oldest_time(self) -> float:
        """The earliest time held (``inf`` when empty)."""
        return self._heap[0][0] if self._heap else math.inf

    def waited(
        self, now: float, wait: float, expected: Callable[[float, str], bool]
    ) -> Iterator[tuple[Item, DetectionBatchIn]]:
        """With no reorder window: the batches that may go now, in time order. A batch goes
        once no other sensor is ``expected`` to send one of its time or earlier, or once one
        held batch of its time or later has waited ``wait`` seconds of wall time."""
        return self._release(
            now, wait, lambda t, batch: wait <= 0 or not expected(t, batch.sensor_id)
        )

    def due(self, now: float, window: float) -> Iterator[tuple[Item, DetectionBatchIn]]:
        """The batches that may go now, in time order (all of them when ``window`` <= 0)."""
        return self._release(
            now, window, lambda t, _: window <= 0 or t <= self.newest_time - window
        )

    def _release(
        self, now: float, wait: float, may_go: Callable[[float, DetectionBatchIn], bool]
    ) -> Iterator[tuple[Item, DetectionBatchIn]]:
        """The held batches in time order while the first ``may_go``; then, once some held
        batch has waited ``wait`` seconds of wall time, it and every older one."""
        heap = self._heap
        while heap:
            t, _, item, batch = heap[0]
            if may_go(t, batch):
                heapq.heappop(heap)
                yield item, batch
                continue
            expired = [e for e in heap if now - e[2].arrived >= wait]
            if not expired:
                return
            cutoff = max(e[0] for e in expired)
            while heap and heap[0][0] <= cutoff:
                _, _, held, held_batch = heapq.heappop(heap)
                yield held, held_batch

    def drain(self) -> Iterator[tuple[Item, DetectionBatchIn]]:
        """Every held batch, in time order."""
        while self._heap:
            _, _, item, batch = heapq.heappop(self._heap)
            yield item, batch


def batch_digest(payload: bytes) -> bytes:
    """What identifies a payload byte for byte (BLAKE2b, 128 bits)."""
    return hashlib.blake2b(payload, digest_size=16).digest()


class RecentBatches:
    """The digests of the last ``per_sensor`` batches accepted from each of the last
    ``sensors`` sensors (least recently seen forgotten first): at most
    ``per_sensor x sensors`` digests, 9 MB with the defaults. A batch whose payload is
    byte for byte one of its sensor's is an exact duplicate (a sender's retry, a replay): it
    is refused, not processed twice. Used by one thread (the worker)."""

    def __init__(self, per_sensor: int = 64, sensors: int = 1024) -> None:
        self.per_sensor = per_sensor
        self.sensors = sensors
        self._by_sensor: OrderedDict[str, OrderedDict[bytes, None]] = OrderedDict()

    def __len__(self) -> int:
        return sum(len(d) for d in self._by_sensor.values())

    def seen(self, sensor_id: str, digest: bytes) -> bool:
        recent = self._by_sensor.get(sensor_id)
        return recent is not None and digest in recent

    def add(self, sensor_id: str, digest: bytes) -> None:
        recent = _recently_seen(self._by_sensor, sensor_id, OrderedDict, self.sensors)
        recent[digest] = None
        if len(recent) > self.per_sensor:
            recent.popitem(last=False)

    def discard(self, sensor_id: str, digest: bytes) -> None:
        """Forget a batch accepted, then refused by the tracker: it may come again."""
        recent = self._by_sensor.get(sensor_id)
        if recent is not None:
            recent.pop(digest, None)


#: Seconds between two log lines about refused batches of one reason (the rest are counted).
REFUSAL_LOG_INTERVAL = 10.0


def _printable(text: str) -> str:
    """``text`` with control characters escaped (``\\n``, ``\\x1b``): a sender's field names
    and values cannot start a line of their own in the log."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


class Refusals:
    """Refuses batches: counts each in the stats, publishes its Error report and resolves its
    future. Drops (``overloaded``) are logged at most once a second; refusals at warning level,
    at most one line per reason every :data:`REFUSAL_LOG_INTERVAL` seconds, with the number
    refused since the previous line (a hostile sender cannot flood the log); that count is
    logged once the interval is over even if no batch is refused then (a burst of refusals
    followed by silence was counted only at shutdown). Thread-safe."""

    def __init__(self, stats: Stats, out: ReportOut) -> None:
        self.stats = stats
        self.out = out
        self._log_lock = threading.Lock()
        self._unlogged = 0
        self._last_log = -math.inf
        self._refusal_log: dict[str, tuple[float, int]] = {}  # reason → (last line, unlogged)
        self._timers: dict[str, threading.Timer] = {}  # reason → the timer that logs its count

    def refuse(
        self,
        payload: bytes,
        key_sensor_id: str | None,
        reason: str,
        detail: str,
        batch: DetectionBatchIn | None = None,
    ) -> dict[str, Any]:
        """Count and publish the Error report of a refused batch, and return it."""
        report = self.report(payload, key_sensor_id, reason, detail, batch)
        self.stats.rejected_batch(reason)
        self.out.error(report)
        self._log_refusal(report)
        return report

    def refuse_unread(
        self, size: int, sensor_id: str | None, reason: str, detail: str
    ) -> dict[str, Any]:
        """:meth:`refuse` a payload of ``size`` bytes that is not read at all (too large, or
        on a key that is not a sensor's): its report names ``sensor_id`` (or ``unknown``) and
        no time."""
        report = error_report_for(
            size, reason, detail, key_sensor_id=sensor_id, sensor_id=None, time=None
        )
        self.stats.rejected_batch(reason)
        self.out.error(report)
        self._log_refusal(report)
        return report

    def reject(self, item: Item, reason: str, detail: str, batch: DetectionBatchIn | None) -> None:
        """:meth:`refuse` a queued batch and resolve its future."""
        report = self.refuse(item.payload, item.key_sensor_id, reason, detail, batch or item.batch)
        if not item.future.done():
            item.future.set_result(IngestResult(False, error=report))

    def drop(self, item: Item, detail: str) -> None:
        """Drop a batch the tracker cannot take (``overloaded``), and resolve its future."""
        self.stats.dropped()
        report = self.report(item.payload, item.key_sensor_id, "overloaded", detail, None)
        self.out.error(report)
        self._log_drop(detail)
        if not item.future.done():
            item.future.set_result(IngestResult(False, error=report))

    def flush_log(self) -> None:
        """Log the drops and the refusals not logged yet."""
        with self._log_lock:
            n, self._unlogged = self._unlogged, 0
            refused = {r: k for r, (_, k) in self._refusal_log.items() if k}
            self._refusal_log = {r: (last, 0) for r, (last, _) in self._refusal_log.items()}
            timers, self._timers = list(self._timers.values()), {}
        for timer in timers:
            timer.cancel()
        if n:
            log.warning("%d more batch(es) dropped", n)
        for reason, k in sorted(refused.items()):
            log.warning("%d more batch(es) refused, %s", k, reason)

    @staticmethod
    def report(
        payload: bytes,
        key_sensor_id: str | None,
        reason: str,
        detail: str,
        batch: DetectionBatchIn | None,
    ) -> dict[str, Any]:
        """The Error report, naming the sensor and time from the batch or the payload."""
        sensor, t = (batch.sensor_id, batch.time) if batch is not None else peek(payload)
        return error_report_for(
            len(payload), reason, detail, key_sensor_id=key_sensor_id, sensor_id=sensor, time=t
        )

    def _log_refusal(self, report: dict[str, Any]) -> None:
        reason = str(report.get("error", "?"))
        now = time.monotonic()
        with self._log_lock:
            last, unlogged = self._refusal_log.get(reason, (-math.inf, 0))
            if now - last < REFUSAL_LOG_INTERVAL:
                self._refusal_log[reason] = (last, unlogged + 1)
                if reason not in self._timers:
                    timer = threading.Timer(
                        last + REFUSAL_LOG_INTERVAL - now, self._log_count, (reason,)
                    )
                    timer.daemon = True
                    self._timers[reason] = timer
                    timer.start()
                return
            self._refusal_log[reason] = (now, 0)
            timer = self._timers.pop(reason, None)
        if timer is not None:
            timer.cancel()
        more = f" ({unlogged} more {reason} since the last such line)" if unlogged else ""
        log.warning(
            "batch refused, %s, sensor %s, time %s: %s%s",
            reason,
            report.get("sensor_id"),
            report.get("time"),
            _printable(str(report.get("detail")))[:200],
            more,
        )

    def _log_count(self, reason: str) -> None:
        """The timer's line: the refusals of ``reason`` counted since its last line."""
        with self._log_lock:
            self._timers.pop(reason, None)
            _, unlogged = self._refusal_log.get(reason, (-math.inf, 0))
            if not unlogged:
                return
            self._refusal_log[reason] = (time.monotonic(), 0)
        log.warning("%d more batch(es) refused, %s", unlogged, reason)

    def _log_drop(self, detail: str) -> None:
        with self._log_lock:
            self._unlogged += 1
            now = time.monotonic()
            if now - self._last_log < 1.0:
                return
            n, self._unlogged = self._unlogged, 0
            self._last_log = now
        log.warning("%d batch(es) dropped: %s", n, detail)


#: Payloads up to this size are parsed to read their sensor and time; larger ones are
#: searched for the two keys (:func:`peek`).
PEEK_PARSE_UP_TO = 64 * 1024
_PEEK_SENSOR = re.compile(rb'"sensor_id"\s*:\s*"([A-Za-z0-9_.\-]{1,64})"')
_PEEK_TIME = re.compile(
    rb'"time"\s*:\s*(-?[0-9]{1,400}(?:\.[0-9]{1,400})?(?:[eE][+-]?[0-9]{1,6})?)'
)


def _finite(value: Any) -> float | None:
    """``value`` as a finite float, if it is a JSON number that is one."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        out = float(value)  # an integer of 400 digits overflows
    except OverflowError:
        return None
    return out if math.isfinite(out) else None


def peek(payload: bytes) -> tuple[str | None, float | None]:
    """Best effort: the sensor id and time of a batch that failed validation. Never raises.

    A payload of up to :data:`PEEK_PARSE_UP_TO` bytes is parsed; a larger one is searched
    for its first ``"sensor_id"`` and ``"time"`` keys (one pass each, in C), so that reading
    them costs little whatever the payload holds."""
    if len(payload) > PEEK_PARSE_UP_TO:
        return _peek_search(payload)
    try:
        obj = orjson.loads(payload)
    except (orjson.JSONDecodeError, TypeError):
        try:  # the standard parser reads the NaN, Infinity and huge numbers orjson refuses
            obj = json.loads(payload)
        except (ValueError, TypeError, RecursionError):
            return None, None
    if not isinstance(obj, dict):
        return None, None
    sensor = obj.get("sensor_id")
    ok_sensor = sensor if isinstance(sensor, str) and valid_sensor_id(sensor) else None
    return ok_sensor, _finite(obj.get("time"))


def _peek_search(payload: bytes) -> tuple[str | None, float | None]:
    sensor = _PEEK_SENSOR.search(payload)
    t = _PEEK_TIME.search(payload)
    return (
        sensor.group(1).decode() if sensor else None,
        _finite(float(t.group(1))) if t else None,
    )
