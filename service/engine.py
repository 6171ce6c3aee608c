"""The engine: owns the tracking pipeline and runs it on one worker thread.

Batches arrive as raw bytes from any thread (:meth:`Engine.submit`) and wait on a bounded
queue; a full queue blocks the sender for up to ``put_timeout`` seconds (back-pressure for
Zenoh publishers using ``CongestionControl.BLOCK``) and then the batch is dropped, counted
and reported as ``overloaded``, never silently lost. The worker decodes, validates, converts
and tracks each batch in turn, publishes a Track report or an Error report through its
:class:`ReportSink`, and keeps the latest report (as a dict and as JSON bytes) plus every live
track for REST and the Zenoh queryable. A rejected batch changes no track.

With a reorder window ``W > 0`` valid batches are held in a time-ordered heap and released
once the newest batch time received, minus ``W``, has passed them, or after ``W`` seconds of
wall time. Configuration changes are validated and saved by the caller's thread, queued, and
applied by the worker before its next batch.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import json
import logging
import math
import os
import queue
import tempfile
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import orjson
from pydantic import ValidationError

from service.convert import (
    batch_to_scan,
    dumps,
    empty_report,
    error_report,
    report_dict,
    track_to_dict,
)
from service.schemas import (
    BatchError,
    DetectionBatchIn,
    IngestConfig,
    decode_batch,
    format_validation_error,
    valid_sensor_id,
)
from service.stats import Stats
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline
from trackers.types import ScanRejected, StepResult, TrackSnapshot

__all__ = [
    "ConfigError",
    "Engine",
    "IngestResult",
    "NullSink",
    "ReportSink",
    "config_document",
    "load_config_file",
    "merge_patch",
    "save_config_file",
    "validate_config_document",
]

log = logging.getLogger("service.engine")


# -- configuration document -------------------------------------------------------------------


class ConfigError(ValueError):
    """An invalid configuration document; the message starts with the field path."""


def config_document(tracker: TrackerConfig, ingest: IngestConfig) -> dict[str, Any]:
    """The REST configuration document: the tracker's sections plus ``ingest``."""
    doc = tracker.to_dict()
    doc["ingest"] = ingest.model_dump()
    return doc


def validate_config_document(
    doc: Any, ingest_defaults: IngestConfig
) -> tuple[TrackerConfig, IngestConfig]:
    """Check a whole document; missing fields take their defaults. Raises :class:`ConfigError`."""
    if not isinstance(doc, dict):
        raise ConfigError("config: expected a JSON object")
    rest = dict(doc)
    ingest_part = rest.pop("ingest", None)
    if ingest_part is None:
        ingest_part = {}
    if not isinstance(ingest_part, dict):
        raise ConfigError("ingest: expected an object")
    try:
        ingest = IngestConfig.model_validate({**ingest_defaults.model_dump(), **ingest_part})
    except ValidationError as exc:
        raise ConfigError(
            "; ".join("ingest." + p for p in format_validation_error(exc).split("; "))
        ) from None
    try:
        tracker = TrackerConfig.from_dict(rest)
    except (ValueError, TypeError) as exc:
        raise ConfigError(str(exc)) from None
    return tracker, ingest


def merge_patch(base: Any, patch: Any) -> Any:
    """JSON merge patch (RFC 7386): objects merge recursively, ``null`` removes a field (so it
    takes its default), anything else replaces."""
    if not isinstance(patch, dict):
        return patch
    out = dict(base) if isinstance(base, dict) else {}
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        else:
            out[key] = merge_patch(out.get(key), value)
    return out


def load_config_file(
    path: Path, ingest_defaults: IngestConfig
) -> tuple[TrackerConfig, IngestConfig] | None:
    """The configuration saved in ``path``, or ``None`` when the file does not exist.

    Raises :class:`ConfigError` when it exists but cannot be used."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise ConfigError(f"config file {path}: {exc.strerror or exc}") from None
    try:
        doc = orjson.loads(raw)
    except orjson.JSONDecodeError as exc:
        raise ConfigError(f"config file {path}: not JSON ({exc})") from None
    try:
        return validate_config_document(doc, ingest_defaults)
    except ConfigError as exc:
        raise ConfigError(f"config file {path}: {exc}") from None


def save_config_file(path: Path, doc: dict[str, Any]) -> None:
    """Write ``doc`` to ``path`` atomically: a temporary file in the same folder, fsync'd,
    then renamed over the old one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = orjson.dumps(doc, option=orjson.OPT_INDENT_2 | orjson.OPT_APPEND_NEWLINE)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


# -- reports out ------------------------------------------------------------------------------


class ReportSink(Protocol):
    """Where reports go (Zenoh in the service, a list in some tests)."""

    def publish_tracks(self, data: bytes) -> None: ...

    def publish_error(self, sensor_id: str, data: bytes) -> None: ...


class NullSink:
    """Publishes nothing."""

    def publish_tracks(self, data: bytes) -> None:
        pass

    def publish_error(self, sensor_id: str, data: bytes) -> None:
        pass


@dataclass(frozen=True)
class IngestResult:
    """What became of one submitted batch: accepted with the Track report's ``seq``, or
    refused with its Error report. ``seq`` is ``None`` while a batch is held for reordering
    (never in a resolved future)."""

    accepted: bool
    seq: int | None = None
    error: dict[str, Any] | None = None


# -- the engine -------------------------------------------------------------------------------


@dataclass
class _Item:
    payload: bytes
    key_sensor_id: str | None
    source: str
    future: Future[IngestResult]
    batch: DetectionBatchIn | None = None
    arrived: float = field(default_factory=time.monotonic)


class _Stop:
    pass


_STOP = _Stop()


@dataclass
class _State:
    """The latest report and tracks; replaced as a whole, so readers need no lock."""

    report: dict[str, Any]
    data: bytes
    result: StepResult | None = None
    confirmed: dict[str, dict[str, Any]] = field(default_factory=dict)
    _all: list[dict[str, Any]] | None = None

    def snapshots(self) -> tuple[TrackSnapshot, ...]:
        """Every live track, tentative too (built on first use; the step's state is
        immutable, so any thread may build it)."""
        return () if self.result is None else self.result.tracks

    def tentative_count(self) -> int:
        return len(self.snapshots()) - len(self.confirmed)

    def all_tracks(self) -> list[dict[str, Any]]:
        """Confirmed tracks as in the report, then the tentative ones (converted once)."""
        if self._all is None:
            tentative = [track_to_dict(t) for t in self.snapshots() if t.status != "confirmed"]
            self._all = list(self.report["tracks"]) + tentative
        return self._all


class Engine:
    """One tracking pipeline behind a bounded queue and one worker thread."""

    def __init__(
        self,
        config: TrackerConfig | None = None,
        ingest: IngestConfig | None = None,
        *,
        stats: Stats | None = None,
        sink: ReportSink | None = None,
        queue_size: int = 1024,
        put_timeout: float = 2.0,
        ingest_defaults: IngestConfig | None = None,
        config_file: Path | None = None,
        pipeline_factory: Callable[[TrackerConfig], TrackingPipeline] = TrackingPipeline,
        stop_drain_seconds: float = 1.0,
    ) -> None:
        self._tracker_config = config or TrackerConfig()
        self._ingest_defaults = ingest_defaults or IngestConfig()
        self._accepted_ingest = ingest or self._ingest_defaults
        self._applied_ingest = self._accepted_ingest
        self._pipeline = pipeline_factory(self._tracker_config)
        self.stats = stats or Stats("engine", queue_size)
        self.stats.queue_capacity = queue_size
        self.sink: ReportSink = sink or NullSink()
        self.config_file = config_file
        self._queue: queue.Queue[_Item | _Stop] = queue.Queue(maxsize=queue_size)
        self._put_timeout = put_timeout
        self._stop_drain_seconds = stop_drain_seconds
        self._config_lock = threading.Lock()
        self._pending: tuple[TrackerConfig, IngestConfig] | None = None
        self._state = _State(report=empty_report(), data=dumps(empty_report()))
        self._seq = 0
        self._heap: list[tuple[float, int, _Item, DetectionBatchIn]] = []
        self._heap_counter = itertools.count()
        self._newest_time = -math.inf
        self._last_wall = time.monotonic()  # wall time of the last processed batch
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._stop_deadline = math.inf
        self._drop_log_lock = threading.Lock()
        self._drops_unlogged = 0
        self._last_drop_log = -math.inf
        self.stats.queue_depth = self._queue.qsize
        self.stats.held_for_reorder = lambda: len(self._heap)
        self.stats.tracks_tentative = lambda: self._state.tentative_count()

    # -- lifecycle --------------------------------------------------------------------------

    def start(self) -> None:
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, name="tracker-engine", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Process what is queued (for up to ``stop_drain_seconds``; the rest is dropped and
        reported), then stop the worker."""
        if self._thread is None:
            return
        self._stop_deadline = time.monotonic() + self._stop_drain_seconds
        self._stopping.set()
        with contextlib.suppress(queue.Full):
            self._queue.put(_STOP, timeout=min(timeout, 0.5))
        self._thread.join(timeout)
        if self._thread.is_alive():
            log.warning("tracker worker did not stop within %.1f s", timeout)
        self._thread = None

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # -- ingest -----------------------------------------------------------------------------

    def check(self, payload: bytes, key_sensor_id: str | None = None) -> DetectionBatchIn:
        """Decode and validate one batch against the contract and the current ingest limits;
        raise :class:`BatchError` when it is refused. Thread-safe, changes nothing."""
        return self._check(payload, key_sensor_id, self._accepted_ingest)

    @staticmethod
    def _check(payload: bytes, key_sensor_id: str | None, ingest: IngestConfig) -> DetectionBatchIn:
        batch = decode_batch(payload)
        if key_sensor_id is not None and batch.sensor_id != key_sensor_id:
            raise BatchError(
                "sensor_mismatch",
                f"sensor_id: {batch.sensor_id!r} differs from the key's last chunk "
                f"{key_sensor_id!r}",
            )
        n = len(batch.detections)
        if n > ingest.max_detections_per_batch:
            raise BatchError(
                "too_many_detections",
                f"detections: {n} detections, more than ingest.max_detections_per_batch "
                f"= {ingest.max_detections_per_batch}",
            )
        return batch

    def submit(
        self,
        payload: bytes,
        key_sensor_id: str | None,
        source: str,
        *,
        batch: DetectionBatchIn | None = None,
    ) -> Future[IngestResult]:
        """Queue one raw batch (``key_sensor_id``: the Zenoh key's last chunk, ``None`` for
        REST; ``batch``: the already validated batch, if the caller checked it). Blocks while
        the queue is full, for up to ``put_timeout`` seconds; then the batch is dropped and
        reported as ``overloaded``. The future resolves to an :class:`IngestResult`."""
        fut: Future[IngestResult] = Future()
        self.stats.received(len(payload))
        if self._stopping.is_set() or self._thread is None:
            self._drop(_Item(payload, key_sensor_id, source, fut, batch), "the service is stopping")
            return fut
        item = _Item(payload, key_sensor_id, source, fut, batch)
        try:
            self._queue.put(item, timeout=self._put_timeout)
        except queue.Full:
            self._drop(
                item,
                f"the ingest queue ({self._queue.maxsize} batches) stayed full for "
                f"{self._put_timeout} s",
            )
        return fut

    def reject(
        self,
        payload: bytes,
        key_sensor_id: str | None,
        reason: str,
        detail: str,
        *,
        batch: DetectionBatchIn | None = None,
    ) -> dict[str, Any]:
        """Count, publish and return the Error report of a batch refused before the queue
        (REST validates in the request's thread)."""
        self.stats.received(len(payload))
        return self._publish_error(payload, key_sensor_id, reason, detail, batch)

    # -- configuration ----------------------------------------------------------------------

    def config_document(self) -> dict[str, Any]:
        """The accepted configuration (applied by the worker before its next batch)."""
        with self._config_lock:
            return config_document(self._tracker_config, self._accepted_ingest)

    @property
    def ingest(self) -> IngestConfig:
        return self._accepted_ingest

    @property
    def tracker_config(self) -> TrackerConfig:
        return self._tracker_config

    def replace_config(self, doc: Any) -> dict[str, Any]:
        """Validate a whole document (missing fields take defaults), save it, and queue it for
        the next batch. Raises :class:`ConfigError` and changes nothing when it is invalid."""
        with self._config_lock:
            return self._accept(doc)

    def patch_config(self, patch: Any) -> dict[str, Any]:
        """Merge ``patch`` into the current document (JSON merge patch), then as
        :meth:`replace_config`."""
        if not isinstance(patch, dict):
            raise ConfigError("config patch: expected a JSON object")
        with self._config_lock:
            current = config_document(self._tracker_config, self._accepted_ingest)
            return self._accept(merge_patch(current, patch))

    def _accept(self, doc: Any) -> dict[str, Any]:
        tracker, ingest = validate_config_document(doc, self._ingest_defaults)
        out = config_document(tracker, ingest)
        if self.config_file is not None:
            try:
                save_config_file(self.config_file, out)
            except OSError as exc:
                raise OSError(f"could not save {self.config_file}: {exc}") from exc
        self._tracker_config = tracker
        self._accepted_ingest = ingest
        self._pending = (tracker, ingest)
        return out

    # -- reading ----------------------------------------------------------------------------

    @property
    def seq(self) -> int:
        return self._seq

    def latest_report(self) -> dict[str, Any]:
        """The latest Track report (confirmed tracks); do not modify it."""
        return self._state.report

    def latest_report_bytes(self) -> bytes:
        """The latest Track report as published, JSON bytes."""
        return self._state.data

    def tracks(self, status: str = "confirmed", kinds: set[str] | None = None) -> dict[str, Any]:
        """The latest report with its tracks filtered: ``status`` is ``confirmed``,
        ``tentative`` or ``all``; ``kinds`` keeps only those kinds."""
        st = self._state
        if status == "confirmed":
            tracks = st.report["tracks"]
        else:
            tracks = st.all_tracks()
            if status == "tentative":
                tracks = [t for t in tracks if t["status"] == "tentative"]
        if kinds:
            tracks = [t for t in tracks if t["kind"] in kinds]
        return {**st.report, "tracks": tracks}

    def track(self, track_id: str) -> dict[str, Any] | None:
        """One live track (tentative too) by id, or ``None``."""
        st = self._state
        found = st.confirmed.get(track_id)
        if found is not None:
            return found
        for t in st.snapshots():
            if t.id == track_id:
                return track_to_dict(t)
        return None

    def snapshots(self) -> tuple[TrackSnapshot, ...]:
        """Every live track as the tracker's snapshots (as of the latest report)."""
        return self._state.snapshots()

    # -- the worker -------------------------------------------------------------------------

    def _run(self) -> None:
        q = self._queue
        while True:
            try:
                if not self._run_once(q):
                    break
            except Exception:  # a bug outside any one batch: the worker must not die of it
                log.exception("tracker worker: unexpected error; going on")
                time.sleep(0.05)
        self._apply_pending()
        while self._heap:  # flush what the reorder window held, in time order
            _, _, held, batch = heapq.heappop(self._heap)
            self._process(held, batch)
        while True:  # anything queued behind a late sentinel
            try:
                rest = q.get_nowait()
            except queue.Empty:
                break
            if isinstance(rest, _Item):
                self._drop(rest, "the service is stopping")
        self._flush_drop_log()

    def _run_once(self, q: queue.Queue[_Item | _Stop]) -> bool:
        """Take at most one batch, then release what the reorder window lets go; ``False``
        when the worker should stop."""
        timeout = self._next_wall_release()
        if self._stopping.is_set():
            timeout = 0.05 if timeout is None else min(timeout, 0.05)
        try:
            item = q.get(timeout=timeout) if timeout is None or timeout > 0 else q.get_nowait()
        except queue.Empty:
            item = None
        if isinstance(item, _Stop):
            return False
        try:
            self._apply_pending()
            if item is not None:
                if self._stopping.is_set() and time.monotonic() > self._stop_deadline:
                    self._drop(item, "the service is stopping")
                else:
                    self._safe_handle(item)
            self._release_due(time.monotonic())
        except Exception as exc:
            if item is not None and not item.future.done():  # refused, never lost
                self._reject(item, "internal_error", f"{type(exc).__name__}: {exc}", None)
            raise
        return not (self._stopping.is_set() and item is None and q.empty())

    def _safe_handle(self, item: _Item) -> None:
        try:
            self._handle(item)
        except Exception as exc:  # a bug: keep the worker alive and say so
            log.exception("batch from %s failed", item.source)
            if not item.future.done():
                self._reject(item, "internal_error", f"{type(exc).__name__}: {exc}", None)

    def _apply_pending(self) -> None:
        pending = self._pending
        if pending is None:
            return
        with self._config_lock:
            pending, self._pending = self._pending, None
        if pending is None:
            return
        tracker, ingest = pending
        if tracker != self._pipeline.config:
            self._pipeline.reconfigure(tracker)
        self._applied_ingest = ingest
        log.info("configuration applied")

    def _handle(self, item: _Item) -> None:
        batch = item.batch
        try:
            if batch is None:
                batch = self._check(item.payload, item.key_sensor_id, self._applied_ingest)
            elif len(batch.detections) > self._applied_ingest.max_detections_per_batch:
                # validated by the caller against a config that has changed since
                batch = self._check(item.payload, item.key_sensor_id, self._applied_ingest)
        except BatchError as exc:
            self._reject(item, exc.reason, exc.detail, None)
            return
        self.stats.detections_in(len(batch.detections))
        window = self._applied_ingest.reorder_window
        last = self._pipeline.last_time
        if last is not None:
            # Batch time may run ahead of the last processed time by the wall time since then
            # plus max_time_jump; further ahead, it would put every later batch out of sequence.
            jump = self._applied_ingest.max_time_jump
            waited = time.monotonic() - self._last_wall
            if batch.time - last > jump + waited:
                self._reject(
                    item,
                    "time_jump",
                    f"time {batch.time} is {batch.time - last:.6g} s after the last processed "
                    f"time {last}: more than ingest.max_time_jump = {jump} s plus the "
                    f"{waited:.3g} s of wall time since",
                    batch,
                )
                return
        if window > 0 and (last is None or batch.time >= last):
            self._newest_time = max(self._newest_time, batch.time)
            heapq.heappush(self._heap, (batch.time, next(self._heap_counter), item, batch))
            return
        self._process(item, batch)

    def _next_wall_release(self) -> float | None:
        if not self._heap:
            return None
        window = self._applied_ingest.reorder_window
        oldest_arrival = min(entry[2].arrived for entry in self._heap)
        return max(0.0, oldest_arrival + window - time.monotonic())

    def _release_due(self, now: float) -> None:
        heap = self._heap
        if not heap:
            return
        window = self._applied_ingest.reorder_window
        while heap:
            t, _, item, _batch = heap[0]
            if window <= 0 or t <= self._newest_time - window:
                heapq.heappop(heap)
                self._process(item, _batch)
                continue
            # a batch held W seconds of wall time goes, and with it everything older
            expired = [e for e in heap if now - e[2].arrived >= window]
            if not expired:
                break
            cutoff = max(e[0] for e in expired)
            while heap and heap[0][0] <= cutoff:
                _, _, held, held_batch = heapq.heappop(heap)
                self._process(held, held_batch)

    def _process(self, item: _Item, batch: DetectionBatchIn) -> None:
        pipeline = self._pipeline
        try:
            scan = batch_to_scan(batch, pipeline.config.measurement.position_std)
            t0 = time.perf_counter()
            result = pipeline.process(scan)
            ms = (time.perf_counter() - t0) * 1000.0
        except ScanRejected as exc:
            self._reject(item, exc.reason, exc.detail, batch)
            return
        except Exception as exc:  # a tracker bug: report it, keep the worker alive
            log.exception("the tracker failed on a batch from %s", batch.sensor_id)
            self._reject(item, "internal_error", f"{type(exc).__name__}: {exc}", batch)
            return
        self._seq += 1
        self._last_wall = time.monotonic()
        seq = self._seq
        confirmed = [track_to_dict(t) for t in result.confirmed()]
        report = report_dict(seq, result, ms, confirmed)
        data = dumps(report)
        self._state = _State(
            report=report,
            data=data,
            result=result,
            confirmed={t["id"]: t for t in confirmed},
        )
        self.stats.processed(seq, result.time, len(batch.detections), ms, len(confirmed))
        self._publish(lambda: self.sink.publish_tracks(data))
        item.future.set_result(IngestResult(True, seq))

    # -- refusals ---------------------------------------------------------------------------

    def _reject(
        self, item: _Item, reason: str, detail: str, batch: DetectionBatchIn | None
    ) -> None:
        report = self._publish_error(item.payload, item.key_sensor_id, reason, detail, batch)
        if not item.future.done():
            item.future.set_result(IngestResult(False, error=report))

    def _drop(self, item: _Item, detail: str) -> None:
        self.stats.dropped()
        report = self._error_report(item.payload, item.key_sensor_id, "overloaded", detail, None)
        data = dumps(report)
        self._publish(lambda: self.sink.publish_error(report["sensor_id"], data))
        self._log_drop(detail)
        if not item.future.done():
            item.future.set_result(IngestResult(False, error=report))

    def _log_drop(self, detail: str) -> None:
        """One warning per second at most, with how many batches were dropped since."""
        with self._drop_log_lock:
            self._drops_unlogged += 1
            now = time.monotonic()
            if now - self._last_drop_log < 1.0:
                return
            n, self._drops_unlogged = self._drops_unlogged, 0
            self._last_drop_log = now
        log.warning("%d batch(es) dropped: %s", n, detail)

    def _flush_drop_log(self) -> None:
        with self._drop_log_lock:
            n, self._drops_unlogged = self._drops_unlogged, 0
        if n:
            log.warning("%d more batch(es) dropped", n)

    def _publish_error(
        self,
        payload: bytes,
        key_sensor_id: str | None,
        reason: str,
        detail: str,
        batch: DetectionBatchIn | None,
    ) -> dict[str, Any]:
        self.stats.rejected_batch(reason)
        report = self._error_report(payload, key_sensor_id, reason, detail, batch)
        data = dumps(report)
        self._publish(lambda: self.sink.publish_error(report["sensor_id"], data))
        log.debug("batch refused: %s", report)
        return report

    @staticmethod
    def _error_report(
        payload: bytes,
        key_sensor_id: str | None,
        reason: str,
        detail: str,
        batch: DetectionBatchIn | None,
    ) -> dict[str, Any]:
        sensor: str | None = key_sensor_id
        t: float | None = None
        if batch is not None:
            sensor = sensor or batch.sensor_id
            t = batch.time
        else:
            peek_sensor, t = _peek(payload)
            sensor = sensor or peek_sensor
        return error_report(sensor or "unknown", t, reason, detail, len(payload))

    @staticmethod
    def _publish(action: Callable[[], None]) -> None:
        try:
            action()
        except Exception:
            log.exception("publishing a report failed")


def _peek(payload: bytes) -> tuple[str | None, float | None]:
    """Best effort: the sensor id and time of a batch that failed validation."""
    try:
        obj = orjson.loads(payload)
    except (orjson.JSONDecodeError, TypeError):
        try:  # the standard parser reads the NaN and Infinity that orjson refuses
            obj = json.loads(payload)
        except (ValueError, TypeError, RecursionError):
            return None, None
    if not isinstance(obj, dict):
        return None, None
    sensor = obj.get("sensor_id")
    t = obj.get("time")
    ok_sensor = sensor if isinstance(sensor, str) and valid_sensor_id(sensor) else None
    ok_time = (
        float(t)
        if isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t)
        else None
    )
    return ok_sensor, ok_time
