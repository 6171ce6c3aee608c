"""The engine: owns the tracking pipeline and runs it on one worker thread.

Batches arrive as raw bytes from any thread (:meth:`Engine.submit`) and wait on a bounded
queue; a full queue blocks the sender for up to ``put_timeout`` seconds (back-pressure for
Zenoh publishers using ``CongestionControl.BLOCK``) and then the batch is dropped, counted
and reported as ``overloaded``, never silently lost. The queue holds at most ``queue_bytes``
of payloads, and a payload over ``max_batch_bytes`` is refused before it is queued, so what
waits is bounded in memory as well as in count. The worker checks each batch
(:mod:`service.ingest`: edge checks, exact duplicates, time-jump guard, reorder window),
converts and tracks it, publishes a Track report or an Error report, and replaces the state
readers see (:mod:`service.reports`). A rejected batch changes no track. Configuration changes are
validated and saved by the caller's thread (:mod:`service.config_store`) and applied by the
worker before its next batch.

Other work on the tracks (starting an extended track by hand: :meth:`Engine.start_extended_track`)
runs on the worker too, between batches: :meth:`Engine.call_in_worker` queues a command behind
the batches already waiting and waits for its answer.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from service.config_store import ConfigApplied, ConfigStore
from service.convert import batch_to_scan, dumps, empty_report, report_dict, track_to_dict
from service.id_reserve import IdReservation
from service.ingest import (
    IngestResult,
    Item,
    RecentBatches,
    Refusals,
    ReorderBuffer,
    SensorClocks,
    batch_digest,
    check_batch,
    time_jump_detail,
)
from service.payload import DEFAULT_MAX_BATCH_BYTES, DEFAULT_QUEUE_BYTES, too_large_detail
from service.reports import ReportOut, ReportSink, ReportState
from service.schemas import MAX_REORDER_WINDOW, BatchError, DetectionBatchIn, IngestConfig
from service.state_store import EngineCheckpoint, StateStore, restored_result
from service.stats import Stats
from service.viewers import ViewerHub
from trackers.association.gating import position_noise
from trackers.config import TrackerConfig
from trackers.extended.tracker import ExtendedTracker, snapshot_of
from trackers.formation.tracker import FormationTracker
from trackers.pattern.tracker import PatternTracker, pattern_snapshot
from trackers.peers import PointTrackState
from trackers.pipeline import MAX_ABS_POSITION, TrackingPipeline
from trackers.state import StateError
from trackers.types import ScanRejected, StepResult, TrackSnapshot

__all__ = ["CommandRefused", "Engine", "EngineUnavailable"]

#: A batch refused as out of sequence by more than this (s) gets the reset hint in its detail.
RESET_HINT_LAG = 10.0

T = TypeVar("T")

log = logging.getLogger("service.engine")

#: Sensors told at most once each that detections without a covariance get position_std.
MAX_NO_COV_NOTES = 1024
#: A sensor is told once that its range-rates disagree with its tracks when fewer than
#: RANGE_RATE_FIT of the first RANGE_RATE_SAMPLE that came with confirmed tracks' detections
#: fitted them (a wrong sign, another unit, a moving radar without its sensor_velocity).
RANGE_RATE_SAMPLE = 30
RANGE_RATE_FIT = 0.5
#: A sensor is told once that its covariances are too wide when, of its first COV_SAMPLE
#: batches of at least COV_MIN_DETECTIONS detections, COV_WIDE or more have a median position
#: standard deviation larger than the diagonal of the box their detections fill (a range and
#: a bearing mixed up, degrees taken for radians, variances sent where a cov wants squares
#: of standard deviations in m²...): no set of detections spreads less than its own noise.
COV_SAMPLE = 10
COV_MIN_DETECTIONS = 5
COV_WIDE = 8


class _Stop:
    pass


_STOP = _Stop()


class EngineUnavailable(RuntimeError):
    """The worker cannot take a command now: it is not running or stopping, its queue stayed
    full, or it did not get to the command in time (the command then never runs)."""


class CommandRefused(ValueError):
    """A command refused by the worker before it changed anything; ``conflict`` when the
    request is well-formed but the configuration does not allow it (e.g. extended tracking
    switched off)."""

    def __init__(self, detail: str, *, conflict: bool = False) -> None:
        super().__init__(detail)
        self.detail = detail
        self.conflict = conflict


def _kinematic_prior(position: Any, velocity: Any) -> tuple[np.ndarray, np.ndarray]:
    """A hand-started track's position and velocity as arrays; raise
    :class:`CommandRefused` unless they are finite and within ``MAX_ABS_POSITION`` (m)."""
    try:
        pos = np.array(position, dtype=float).reshape(2)
        vel = np.array(velocity, dtype=float).reshape(2)
    except (TypeError, ValueError) as exc:
        raise CommandRefused(f"position, velocity: unusable: {exc}") from None
    if not np.isfinite(pos).all() or np.abs(pos).max() > MAX_ABS_POSITION:
        raise CommandRefused(f"position: finite numbers within ±{MAX_ABS_POSITION:g} m needed")
    if not np.isfinite(vel).all():
        raise CommandRefused("velocity: not finite numbers")
    return pos, vel


def _extended_prior(
    position: Any, velocity: Any, extent: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A hand-started extended track's centroid, velocity and extent as arrays; raise
    :class:`CommandRefused` unless they are finite, within ``MAX_ABS_POSITION`` (m) and the
    extent is a 2x2 symmetric positive definite matrix."""
    pos, vel = _kinematic_prior(position, velocity)
    try:
        ext = np.array(extent, dtype=float).reshape(2, 2)
    except (TypeError, ValueError) as exc:
        raise CommandRefused(f"extent: unusable: {exc}") from None
    (a, b), (c, d) = ext.tolist()
    if (
        not np.isfinite(ext).all()
        or abs(b - c) > 1e-9 * (1.0 + abs(b))
        or a <= 0.0
        or a * d - b * c <= 0.0
    ):
        raise CommandRefused("extent.matrix: not symmetric positive definite")
    ext[0, 1] = ext[1, 0] = 0.5 * (b + c)
    return pos, vel, ext


class _Command:
    """A function to run on the worker between batches; its answer goes to ``future``."""

    __slots__ = ("fn", "future")

    def __init__(self, fn: Callable[[TrackingPipeline], Any]) -> None:
        self.fn = fn
        self.future: Future[Any] = Future()

    def run(self, pipeline: TrackingPipeline) -> None:
        if not self.future.set_running_or_notify_cancel():  # the caller gave up: do nothing
            return
        try:
            result = self.fn(pipeline)
        except BaseException as exc:  # the caller's to handle
            self.future.set_exception(exc)
        else:
            self.future.set_result(result)

    def refuse(self, reason: str) -> None:
        if self.future.set_running_or_notify_cancel():
            self.future.set_exception(EngineUnavailable(reason))


PeerT = TypeVar("PeerT")


def _switched_on_peer(pipeline: TrackingPipeline, kind: str, cls: type[PeerT]) -> PeerT:
    """The pipeline's peer of ``kind`` (a ``cls``) for a command; refused as a conflict when
    the pipeline has none or its configuration section ``{kind}.enabled`` is false."""
    tracker = next((p for p in pipeline.peers if p.kind == kind), None)
    if not isinstance(tracker, cls):
        raise CommandRefused(f"{kind} tracking is not part of this tracker", conflict=True)
    if not getattr(pipeline.config, kind).enabled:
        raise CommandRefused(
            f"{kind} tracking is switched off (configuration {kind}.enabled)", conflict=True
        )
    return tracker


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
        pipeline_factory: Callable[[TrackerConfig], TrackingPipeline] = TrackingPipeline.all_kinds,
        stop_drain_seconds: float = 1.0,
        max_batch_bytes: int = DEFAULT_MAX_BATCH_BYTES,
        queue_bytes: int = DEFAULT_QUEUE_BYTES,
        state_store: StateStore | None = None,
        id_reservation: IdReservation | None = None,
    ) -> None:
        defaults = ingest_defaults or IngestConfig()
        self._config = ConfigStore(
            config or TrackerConfig(),
            ingest or defaults,
            ingest_defaults=defaults,
            path=config_file,
        )
        self._applied_ingest = self._config.ingest
        self._pipeline = pipeline_factory(self._config.tracker)
        self._resets = 0  # resets so far (checkpoints carry it: the state file saves each)
        #: confirmed tracks dropped by a reset, listed in the next report's ``deleted``
        self._dropped: tuple[str, ...] = ()
        self.stats = stats or Stats("engine", queue_size)
        self.stats.queue_capacity = queue_size
        self._out = ReportOut(sink)
        self._refusals = Refusals(self.stats, self._out)
        self._queue: queue.Queue[Item | _Command | _Stop] = queue.Queue(maxsize=queue_size)
        self._put_timeout = put_timeout
        self.max_batch_bytes = max_batch_bytes
        self._queue_bytes = queue_bytes
        self._queued_bytes = 0  # payload bytes in the queue
        self._bytes_free = threading.Condition()
        self._recent = RecentBatches()
        #: sensors already told that detections without a covariance get position_std
        self._no_cov_sensors: set[str] = set()
        #: range-rates per sensor (came, fitted) until its first RANGE_RATE_SAMPLE are judged
        self._range_rates: dict[str, tuple[int, int]] = {}
        #: batches per sensor (judged, too wide) until its first COV_SAMPLE are judged
        self._cov_widths: dict[str, tuple[int, int]] = {}
        self._clocks = SensorClocks()  # each sensor's usual interval, for the time-jump guard
        self._stop_drain_seconds = stop_drain_seconds
        self._state = ReportState.empty()
        self._seq = 0
        self._held = ReorderBuffer()
        self._last_wall = time.monotonic()  # wall time of the last processed batch
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._stop_deadline = math.inf
        self.stats.queue_depth = self._queue.qsize
        self.stats.held_for_reorder = self._held.__len__
        self.stats.tracks_tentative = lambda: self._state.tentative_count()
        #: the live view's viewers: each report is handed to them, never waited for
        self.view = ViewerHub(on_drop=self.stats.view_frame_dropped)
        self.stats.viewers = self.view.__len__
        # the tracker state file (service.state_store): restored at start, saved off the worker
        self._state_store = state_store
        self._checkpoint: EngineCheckpoint | None = None
        self._restore_pending = state_store is not None
        # the track id reservation (service.id_reserve): ids a restart does not give again
        self._ids = id_reservation
        # scale-out: tracks handed over from and to other instances, applied by the worker
        # before its next batch; ``on_report(state)`` runs on the worker after each batch
        self._hand_lock = threading.Lock()
        self._handed_in: list[PointTrackState] = []
        self._handed_over: list[str] = []
        self.on_report: Callable[[ReportState], None] | None = None

    @property
    def sink(self) -> ReportSink:
        """Where Track and Error reports go."""
        return self._out.sink

    @sink.setter
    def sink(self, sink: ReportSink) -> None:
        self._out.sink = sink

    # -- lifecycle --------------------------------------------------------------------------

    def start(self) -> None:
        if self._thread is not None:
            return
        if self._state_store is not None:
            try:
                self._pipeline.checkpoint()
            except StateError as exc:
                log.warning("the tracker state is not saved: %s", exc)
                self._state_store = None
        if self._state_store is not None:
            if self._restore_pending:
                self._restore_pending = False
                self._restore(self._state_store)
            self._state_store.start(lambda: self._checkpoint)
        if self._ids is not None:  # after the restore: past its counters too
            self._ids.begin(self._pipeline)
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
        stuck = self._thread.is_alive()
        if stuck:
            log.warning("tracker worker did not stop within %.1f s", timeout)
        self._thread = None
        if self._state_store is not None:  # the state after the last batch processed,
            self._state_store.stop()  # saved now even if saved before: stopped at this time
            self._state_store.save_logged(self._checkpoint, force=True)
        if self._ids is not None and not stuck:  # (a worker still running may number more)
            self._ids.end(self._pipeline)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def _restore(self, store: StateStore) -> None:
        """Go on from the saved state, if there is one to use: tracks and ids, the
        pipeline's last time, the report counter and the latest report (its tracks as
        restored), and the wall time since its last batch for the time-jump guard."""
        restored = store.restore_into(self._pipeline)
        if restored is None:
            return
        self._seq = restored.seq
        self._last_wall = time.monotonic() - restored.since_last_batch
        result = restored_result(self._pipeline, restored.sensor_id)
        if result is not None:
            confirmed = [track_to_dict(t) for t in result.confirmed()]
            self._state = ReportState.of(report_dict(self._seq, result, 0.0, confirmed), result)
            self.stats.restored(self._seq, result.time, len(confirmed), restored.since_last_batch)
        self._checkpoint = EngineCheckpoint(
            self._seq, self._pipeline.checkpoint(), restored.sensor_id, self._last_wall
        )

    # -- ingest -----------------------------------------------------------------------------

    def check(self, payload: bytes, key_sensor_id: str | None = None) -> DetectionBatchIn:
        """Decode and validate one batch against the contract and the current ingest limits;
        raise :class:`~service.schemas.BatchError` when it is refused. Thread-safe, changes
        nothing."""
        return check_batch(payload, key_sensor_id, self._config.ingest, self.max_batch_bytes)

    def submit(
        self,
        payload: bytes,
        key_sensor_id: str | None,
        source: str,
        *,
        batch: DetectionBatchIn | None = None,
        on_held: Callable[[], None] | None = None,
    ) -> Future[IngestResult]:
        """Queue one raw batch (``key_sensor_id``: the Zenoh key's last chunk, ``None`` for
        REST; ``batch``: the already validated batch, if the caller checked it). Blocks while
        the queue is full, for up to ``put_timeout`` seconds; then the batch is dropped and
        reported as ``overloaded``. The future resolves to an
        :class:`~service.ingest.IngestResult`. ``on_held`` is called (on the worker thread)
        if the reorder window holds the batch back, before the future resolves."""
        fut: Future[IngestResult] = Future()
        size = len(payload)
        self.stats.received(size)
        if size > self.max_batch_bytes:  # refused unread, before it takes any queue space
            detail = too_large_detail(size, self.max_batch_bytes)
            report = self._refusals.refuse_unread(size, key_sensor_id, "batch_too_large", detail)
            fut.set_result(IngestResult(False, error=report))
            return fut
        item = Item(payload, key_sensor_id, source, fut, batch, on_held=on_held)
        if self._stopping.is_set() or self._thread is None:
            self._refusals.drop(item, "the service is stopping")
            return fut
        deadline = time.monotonic() + self._put_timeout
        if not self._reserve(size, deadline):
            self._refusals.drop(
                item,
                f"the ingest queue's {self._queue_bytes} bytes stayed full for "
                f"{self._put_timeout} s",
            )
            return fut
        try:
            self._queue.put(item, timeout=max(0.0, deadline - time.monotonic()))
        except queue.Full:
            self._release(size)
            self._refusals.drop(
                item,
                f"the ingest queue ({self._queue.maxsize} batches) stayed full for "
                f"{self._put_timeout} s",
            )
        return fut

    def _reserve(self, size: int, deadline: float) -> bool:
        """Take ``size`` bytes of the queue's budget, waiting until ``deadline`` for them
        (a batch that fits no budget still goes into an empty queue)."""
        with self._bytes_free:
            while self._queued_bytes and self._queued_bytes + size > self._queue_bytes:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._bytes_free.wait(left)
            self._queued_bytes += size
        return True

    def _release(self, size: int) -> None:
        with self._bytes_free:
            self._queued_bytes -= size
            self._bytes_free.notify_all()

    def refuse_unread(
        self, size: int, sensor_id: str | None, reason: str, detail: str
    ) -> dict[str, Any]:
        """Count, publish and return the Error report of a payload of ``size`` bytes refused
        before it was read (too large, or on a key that names no sensor: ``sensor_id`` is
        then ``None`` and the report goes to ``unknown``)."""
        self.stats.received(size)
        return self._refusals.refuse_unread(size, sensor_id, reason, detail)

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
        return self._refusals.refuse(payload, key_sensor_id, reason, detail, batch)

    # -- configuration ----------------------------------------------------------------------

    def config_document(self) -> dict[str, Any]:
        """The accepted configuration (applied by the worker before its next batch)."""
        return self._config.document()

    @property
    def ingest(self) -> IngestConfig:
        return self._config.ingest

    @property
    def tracker_config(self) -> TrackerConfig:
        return self._config.tracker

    @property
    def config_file(self) -> Path | None:
        return self._config.path

    def replace_config(self, doc: Any) -> dict[str, Any]:
        """Validate a whole document (missing fields take defaults), save it, and queue it for
        the next batch. Raises :class:`~service.config_store.ConfigError` and changes nothing
        when it is invalid."""
        return self._config.replace(doc)

    def patch_config(self, patch: Any) -> dict[str, Any]:
        """Merge ``patch`` into the current document (JSON merge patch), then as
        :meth:`replace_config`."""
        return self._config.patch(patch)

    def apply_config(self, doc: Any, *, merge: bool = False) -> ConfigApplied:
        """:meth:`replace_config` (or :meth:`patch_config` with ``merge``), saying what
        changed and where it was saved."""
        return self._config.apply(doc, merge=merge)

    # -- commands on the worker ---------------------------------------------------------------

    def call_in_worker(self, fn: Callable[[TrackingPipeline], T], timeout: float = 5.0) -> T:
        """Run ``fn(pipeline)`` on the worker thread, between batches (after those queued
        before it), and return its answer or raise its exception here. Raises
        :class:`EngineUnavailable` when the worker is not running or stopping, when the queue
        stayed full for ``timeout`` seconds, or when the worker did not start the command
        within ``timeout`` seconds (it then never runs). A command takes a queue slot but none
        of the queue's bytes; ``fn`` must be quick, as batches wait behind it."""
        fn = self._numbering(fn)
        if self._thread is not None and threading.current_thread() is self._thread:
            return fn(self._pipeline)  # from the worker itself: queueing would deadlock
        if self._stopping.is_set() or not self.running:
            raise EngineUnavailable("the tracker worker is not running")
        command = _Command(fn)
        deadline = time.monotonic() + timeout
        try:
            self._queue.put(command, timeout=max(0.0, timeout))
        except queue.Full:
            raise EngineUnavailable(
                f"the ingest queue ({self._queue.maxsize} items) stayed full for {timeout} s"
            ) from None
        future = command.future
        try:
            result: T = future.result(timeout=max(0.0, deadline - time.monotonic()))
        except TimeoutError:
            if future.cancel():  # not started: it never will be
                raise EngineUnavailable(
                    f"the tracker worker did not take the command within {timeout} s"
                ) from None
            result = future.result()  # running now: its answer comes soon
        return result

    def _numbering(self, fn: Callable[[TrackingPipeline], T]) -> Callable[[TrackingPipeline], T]:
        """``fn`` followed, before its answer goes out, by the id reservation's check (a
        track started by hand takes an id)."""
        ids = self._ids
        if ids is None:
            return fn

        def checked(pipeline: TrackingPipeline) -> T:
            try:
                return fn(pipeline)
            finally:
                ids.check(pipeline)

        return checked

    def _start_by_hand(
        self,
        kind: str,
        cls: type[PeerT],
        start: Callable[[PeerT, float], TrackSnapshot],
        at: float | None,
        timeout: float,
    ) -> dict[str, Any]:
        """Run ``start(peer, t)`` on the worker for the switched-on peer of ``kind`` at the
        time :meth:`_start_time` gives; its ``ValueError`` is a :class:`CommandRefused`. The
        latest report lists the new track at once; the answer is its Track."""

        def command(pipeline: TrackingPipeline) -> dict[str, Any]:
            tracker = _switched_on_peer(pipeline, kind, cls)
            t = self._start_time(pipeline, at)
            try:
                snap = start(tracker, t)
            except ValueError as exc:
                raise CommandRefused(str(exc)) from None
            self._refresh_state(t)
            log.info(
                "%s track %s started by hand at t=%s: position (%.1f, %.1f) m, "
                "velocity (%.1f, %.1f) m/s",
                kind,
                snap.id,
                t,
                *snap.position,
                *snap.velocity,
            )
            return track_to_dict(snap)

        return self.call_in_worker(command, timeout)

    def _start_time(self, pipeline: TrackingPipeline, at: float | None) -> float:
        """When a track started by hand starts: the last processed batch's time, or ``at``
        (not before it, nor more than ``ingest.max_time_jump`` after it; required before the
        first batch). Raises :class:`CommandRefused`."""
        last = pipeline.last_time
        if last is None:
            if at is None:
                raise CommandRefused("time: required before the first batch is processed")
            return float(at)
        t = last if at is None else float(at)
        if t < last:
            raise CommandRefused(f"time: {t} is before the last processed batch's time {last}")
        jump = self._applied_ingest.max_time_jump
        if t > last + jump:
            raise CommandRefused(
                f"time: {t} is more than ingest.max_time_jump ({jump} s) after the "
                f"last processed batch's time {last}"
            )
        return t

    def start_pattern_track(
        self,
        pattern: str,
        position: tuple[float, float],
        velocity: tuple[float, float],
        attitude: float,
        *,
        attitude_rate: float = 0.0,
        position_std: float = 10.0,
        velocity_std: float = 5.0,
        attitude_std: float = 0.1,
        at: float | None = None,
        timeout: float = 5.0,
    ) -> dict[str, Any]:
        """Start a confirmed point-pattern track by hand (:meth:`PatternTracker.start`) on the
        worker, at the time :meth:`_start_time` gives. Returns the new Track; the latest report
        lists it at once. Raises :class:`CommandRefused` (nothing changed) for an unknown
        pattern or unusable values, or when point-pattern tracking is switched off, and
        :class:`EngineUnavailable` as :meth:`call_in_worker`."""
        pos, vel = _kinematic_prior(position, velocity)

        def start(tracker: PatternTracker, t: float) -> TrackSnapshot:
            track = tracker.start(
                t,
                pattern,
                pos,
                vel,
                attitude,
                attitude_rate=attitude_rate,
                position_std=position_std,
                velocity_std=velocity_std,
                attitude_std=attitude_std,
            )
            return pattern_snapshot(track)

        return self._start_by_hand("point_patterns", PatternTracker, start, at, timeout)

    def start_extended_track(
        self,
        position: tuple[float, float],
        velocity: tuple[float, float],
        extent: np.ndarray | list[list[float]],
        *,
        position_std: float = 20.0,
        velocity_std: float = 5.0,
        expected_detections: float = 3.0,
        at: float | None = None,
        timeout: float = 5.0,
    ) -> dict[str, Any]:
        """Start a confirmed extended track by hand (:meth:`ExtendedTracker.start`) on the
        worker, at the time of the last processed batch, or at ``at`` (not before it, nor
        more than ``ingest.max_time_jump`` after it; before the first batch ``at`` is
        required). Returns the new Track; the latest report (same ``seq``, not published
        again) lists it at once. Raises :class:`CommandRefused` (nothing changed) for
        unusable values, a speed above ``extended.max_speed``, a centroid inside an extended
        track's extent, or when extended tracking is switched off, and
        :class:`EngineUnavailable` as :meth:`call_in_worker`."""
        pos, vel, ext = _extended_prior(position, velocity, extent)

        def start(tracker: ExtendedTracker, t: float) -> TrackSnapshot:
            track = tracker.start(
                t,
                pos,
                vel,
                ext,
                position_std=position_std,
                velocity_std=velocity_std,
                expected_detections=expected_detections,
            )
            return snapshot_of(track)

        return self._start_by_hand("extended", ExtendedTracker, start, at, timeout)

    def form_formation(self, members: list[str], *, timeout: float = 5.0) -> dict[str, Any]:
        """Ask for a formation of the live individual tracks ``members`` on the worker
        (:meth:`FormationTracker.request`): it is formed at the next batch from those still
        live then. Returns the formation's Track as of now. Raises :class:`CommandRefused`
        (nothing changed) for an unknown id, a tentative track, one already in a formation, a
        repeated id, members farther apart than ``formation.max_spacing``, or when formation
        tracking is switched off, and :class:`EngineUnavailable` as
        :meth:`call_in_worker`."""

        def command(pipeline: TrackingPipeline) -> dict[str, Any]:
            tracker = _switched_on_peer(pipeline, "formation", FormationTracker)
            last = pipeline.last_time
            if last is None:
                raise CommandRefused("members: no track exists before the first batch")
            try:
                snap = tracker.request(members, pipeline.point.predicted(last))
            except ValueError as exc:
                raise CommandRefused(str(exc)) from None
            log.info(
                "formation %s asked for by hand: members %s, formed at the next batch",
                snap.id,
                ", ".join(members),
            )
            return track_to_dict(snap)

        return self.call_in_worker(command, timeout)

    # -- hand-over between instances (scale-out) ---------------------------------------------

    def hand_in(self, states: list[PointTrackState]) -> None:
        """Take over these individual tracks from another instance at the next batch
        (:meth:`TrackingPipeline.hand_in`); any thread."""
        with self._hand_lock:
            self._handed_in.extend(states)

    def hand_over(self, ids: list[str]) -> None:
        """Drop these individual tracks at the next batch: another instance took them over
        (:meth:`TrackingPipeline.hand_over`); any thread."""
        with self._hand_lock:
            self._handed_over.extend(ids)

    def point_states(self, ids: list[str]) -> tuple[PointTrackState, ...]:
        """The live individual tracks ``ids`` as hand-over records; the worker only (from
        :attr:`on_report`)."""
        return self._pipeline.point_states(ids)

    def reset(self, *, timeout: float = 5.0) -> dict[str, Any]:
        """Start again (``POST /api/v1/reset``). On the worker, after the batches queued
        before it and those the reorder window holds: every track of every kind, the
        two-point candidates, what was learned of each sensor (detection probability,
        coverage, clutter map, usual interval, recent batches) and the tracks waiting to be
        handed over are dropped, and the last processed time is forgotten, so that batches of
        any time are taken again (a recording replayed from its start). The configuration,
        the report ``seq``, the counters and the id counters stay (new ids go on from the
        last). The confirmed tracks dropped are listed in the next Track report's
        ``deleted``, and in the latest report's until then. Answers
        ``{"reset": true, "seq": n, "dropped": k}``, ``k`` the live tracks dropped.
        Raises :class:`EngineUnavailable` like :meth:`call_in_worker`."""

        def command(pipeline: TrackingPipeline) -> dict[str, Any]:
            for held, batch in self._held.drain():
                self._process(held, batch)
            live = pipeline.snapshot()
            self._dropped += tuple(t.id for t in live if t.confirmed)
            pipeline.reset()
            self._resets += 1
            with self._hand_lock:
                self._handed_in, self._handed_over = [], []
            self._clocks = SensorClocks()
            self._recent = RecentBatches()
            self._last_wall = time.monotonic()
            report = {**empty_report(), "seq": self._seq, "deleted": list(self._dropped)}
            self._state = ReportState(report=report, data=dumps(report))
            self.stats.tracks_confirmed = 0
            self.stats.last_time = None  # the time line forgotten, in /api/v1/stats too
            self.view.publish(self._state)
            if self._state_store is not None:
                self._checkpoint = EngineCheckpoint(
                    self._seq, pipeline.checkpoint(), "", self._last_wall, self._resets
                )
            log.info("reset: %d live tracks dropped, the time line forgotten", len(live))
            return {"reset": True, "seq": self._seq, "dropped": len(live)}

        return self.call_in_worker(command, timeout=timeout)

    def _take_handed(self) -> None:
        if not (self._handed_in or self._handed_over):
            return
        with self._hand_lock:
            states, self._handed_in = self._handed_in, []
            ids, self._handed_over = self._handed_over, []
        if states:
            self._pipeline.hand_in(states)
        if ids:
            self._pipeline.hand_over(ids)

    def _refresh_state(self, at: float) -> None:
        """Replace the latest report by one with the same ``seq`` and the pipeline's tracks as
        they are now (the worker, after a command changed them). Not published over Zenoh:
        the next batch's report is; the live view gets it."""
        prev = self._state
        old = prev.result
        tracks = self._pipeline.snapshot()
        confirmed_snaps = tuple(t for t in tracks if t.confirmed)
        if old is not None:
            t, sensor_id, deleted = old.time, old.sensor_id, old.deleted
        else:  # no batch yet (or since a reset): the time of the tracks started by hand
            before = prev.report.get("time")
            t, sensor_id = (at if before is None else max(before, at)), ""
            deleted = self._dropped  # a reset's, until the next batch reports them

        def snapshot(confirmed_only: bool) -> tuple[TrackSnapshot, ...]:
            return confirmed_snaps if confirmed_only else tracks

        result = StepResult(time=t, sensor_id=sensor_id, deleted=deleted, snapshot=snapshot)
        confirmed = [track_to_dict(s) for s in confirmed_snaps]
        report = report_dict(self._seq, result, prev.report.get("processing_ms", 0.0), confirmed)
        if old is None:
            report["sensor_id"] = prev.report.get("sensor_id")
        state = ReportState.of(report, result)
        self._state = state
        self.stats.tracks_confirmed = len(confirmed)
        self.view.publish(state)

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

    @property
    def report_state(self) -> ReportState:
        """The latest report and tracks (replaced as a whole; do not modify it)."""
        return self._state

    def tracks(self, status: str = "confirmed", kinds: set[str] | None = None) -> dict[str, Any]:
        """The latest report with its tracks filtered: ``status`` is ``confirmed``,
        ``tentative`` or ``all``; ``kinds`` keeps only those kinds."""
        return self._state.filtered(status, kinds)

    def track(self, track_id: str) -> dict[str, Any] | None:
        """One live track (tentative too) by id, or ``None``."""
        return self._state.track(track_id)

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
        for held, batch in self._held.drain():  # what the reorder window held, in time order
            self._process(held, batch)
        while True:  # anything queued behind a late sentinel
            try:
                rest = q.get_nowait()
            except queue.Empty:
                break
            if isinstance(rest, Item):
                self._release(len(rest.payload))
                self._refusals.drop(rest, "the service is stopping")
            elif isinstance(rest, _Command):
                rest.refuse("the service is stopping")
        self._refusals.flush_log()

    def _run_once(self, q: queue.Queue[Item | _Command | _Stop]) -> bool:
        """Take at most one batch (or command), then release what the reorder window lets go;
        ``False`` when the worker should stop."""
        ingest = self._applied_ingest
        timeout = self._held.wait_time(
            time.monotonic(), ingest.reorder_window or ingest.sensor_wait
        )
        if self._stopping.is_set():
            timeout = 0.05 if timeout is None else min(timeout, 0.05)
        try:
            item = q.get(timeout=timeout) if timeout is None or timeout > 0 else q.get_nowait()
        except queue.Empty:
            item = None
        if isinstance(item, _Stop):
            return False
        if isinstance(item, Item):
            self._release(len(item.payload))
        try:
            self._apply_pending()
            if isinstance(item, _Command):
                if self._stopping.is_set() and time.monotonic() > self._stop_deadline:
                    item.refuse("the service is stopping")
                else:
                    item.run(self._pipeline)
            elif item is not None:
                if self._stopping.is_set() and time.monotonic() > self._stop_deadline:
                    self._refusals.drop(item, "the service is stopping")
                else:
                    self._safe_handle(item)
            if len(self._held):
                self._release_held()
        except Exception as exc:
            if isinstance(item, _Command):
                if not item.future.done():
                    item.refuse(f"internal error: {type(exc).__name__}: {exc}")
            elif item is not None and not item.future.done():  # refused, never lost
                self._refusals.reject(item, "internal_error", f"{type(exc).__name__}: {exc}", None)
            raise
        return not (self._stopping.is_set() and item is None and q.empty())

    def _release_held(self) -> None:
        """Process the held batches that may go now, in time order: by the reorder window,
        or, without one, once no other sensor is due to send an earlier batch (or they
        waited ``ingest.sensor_wait``)."""
        ingest, now = self._applied_ingest, time.monotonic()
        if ingest.reorder_window > 0:
            due = self._held.due(now, ingest.reorder_window)
        else:
            due = self._held.waited(
                now,
                ingest.sensor_wait,
                lambda t, sensor: self._clocks.expected_before(
                    t, sensor, now, self._held.sensors()
                ),
            )
        for held, batch in due:
            self._process(held, batch)

    def _waits_for_others(self, batch: DetectionBatchIn) -> bool:
        """Without a reorder window: whether a valid batch waits (``ingest.sensor_wait``),
        because batches of its time or earlier wait already, or another sensor is due to
        send one (see :meth:`SensorClocks.expected_before`)."""
        if batch.time >= self._held.oldest_time:
            return True  # behind batches held already (perhaps by an earlier setting)
        if self._applied_ingest.sensor_wait <= 0:
            return False
        return self._clocks.expected_before(
            batch.time, batch.sensor_id, time.monotonic(), self._held.sensors()
        )

    def _safe_handle(self, item: Item) -> None:
        try:
            self._handle(item)
        except Exception as exc:  # a bug: keep the worker alive and say so
            log.exception("batch from %s failed", item.source)
            if not item.future.done():
                self._refusals.reject(item, "internal_error", f"{type(exc).__name__}: {exc}", None)

    def _apply_pending(self) -> None:
        pending = self._config.take_pending()
        if pending is None:
            return
        tracker, ingest = pending
        if tracker != self._pipeline.config:
            self._pipeline.reconfigure(tracker)
        self._applied_ingest = ingest
        log.info("configuration applied")

    def _handle(self, item: Item) -> None:
        ingest = self._applied_ingest
        batch = item.batch
        try:
            # a batch the caller validated is checked again only against a lower limit
            if batch is None or len(batch.detections) > ingest.max_detections_per_batch:
                batch = check_batch(item.payload, item.key_sensor_id, ingest, self.max_batch_bytes)
        except BatchError as exc:
            self._refusals.reject(item, exc.reason, exc.detail, None)
            return
        self.stats.detections_in(len(batch.detections))
        last = self._pipeline.last_time
        digest = None
        if last is None or batch.time >= last:  # an older copy is out of sequence anyway
            digest = batch_digest(item.payload)
            if self._recent.seen(batch.sensor_id, digest):
                detail = (
                    f"the same {len(item.payload)} bytes as a batch of {batch.sensor_id} "
                    f"accepted before (one of its last {self._recent.per_sensor})"
                )
                self._refusals.reject(item, "duplicate_batch", detail, batch)
                return
        if last is not None:
            waited = time.monotonic() - self._last_wall
            revisit = self._clocks.revisit(batch.sensor_id)
            jump = time_jump_detail(
                batch.time, last, ingest.max_time_jump, waited, revisit, ingest.reorder_window
            )
            if jump is not None:
                self._refusals.reject(item, "time_jump", jump, batch)
                return
        if digest is not None:  # accepted: a copy is a duplicate, unless the tracker refuses it
            item.digest = digest
            self._recent.add(batch.sensor_id, digest)
        in_order = last is None or batch.time >= last
        if in_order and (ingest.reorder_window > 0 or self._waits_for_others(batch)):
            self._held.hold(item, batch)
            if item.on_held is not None:
                item.on_held()
            return
        self._process(item, batch)

    def _note_missing_covariance(self, batch: DetectionBatchIn, position_std: float) -> None:
        """Say once per sensor that its detections without a ``cov`` are taken as
        ``position_std`` per axis: a sensor noisier than that is tracked badly, silently."""
        sensor = batch.sensor_id
        if sensor in self._no_cov_sensors or all(d.get("cov") for d in batch.detections):
            return
        self._no_cov_sensors.add(sensor)
        log.warning(
            "sensor %s sends detections without a covariance: measurement.position_std = %g m "
            "per axis is assumed for them (send cov, per batch or per detection, or set "
            "measurement.position_std to the sensor's noise)",
            sensor,
            position_std,
        )

    def _judge_range_rates(self, sensor: str, came: int, fitted: int) -> None:
        """Count a sensor's range-rates that came with confirmed tracks' detections and those
        that fitted them; once RANGE_RATE_SAMPLE have come, say whether too few fitted (once
        per sensor, for at most MAX_NO_COV_NOTES sensors)."""
        total = self._range_rates.get(sensor)
        if total is None:
            if len(self._range_rates) >= MAX_NO_COV_NOTES:
                return
            total = (0, 0)
        if total[0] < 0:  # judged already
            return
        came, fitted = total[0] + came, total[1] + fitted
        if came < RANGE_RATE_SAMPLE:
            self._range_rates[sensor] = (came, fitted)
            return
        self._range_rates[sensor] = (-1, -1)
        if fitted < RANGE_RATE_FIT * came:
            log.warning(
                "sensor %s: %d of the %d range-rates (vr) of its detections that confirmed "
                "tracks took disagree with those tracks and were not used: vr must be the "
                "range-rate in m/s, positive going away, seen from the batch's sensor_position "
                "(a moving sensor also gives sensor_velocity)",
                sensor,
                came - fitted,
                came,
            )

    def _judge_covariances(self, sensor: str, z: np.ndarray, R: np.ndarray) -> None:
        """Count a sensor's batches of COV_MIN_DETECTIONS detections or more whose median
        position standard deviation exceeds the diagonal of the box their detections fill;
        once COV_SAMPLE are counted, say whether COV_WIDE or more did (once per sensor, for at
        most MAX_NO_COV_NOTES sensors)."""
        seen = self._cov_widths.get(sensor)
        if seen is None:
            if len(self._cov_widths) >= MAX_NO_COV_NOTES:
                return
            seen = (0, 0)
        if seen[0] < 0 or z.shape[0] < COV_MIN_DETECTIONS:
            return
        sigma = position_noise(R) or 0.0  # not empty: COV_MIN_DETECTIONS or more
        span = float(np.hypot(*(z.max(axis=0) - z.min(axis=0))))
        judged, wide = seen[0] + 1, seen[1] + (sigma > span)
        if judged < COV_SAMPLE:
            self._cov_widths[sensor] = (judged, wide)
            return
        self._cov_widths[sensor] = (-1, -1)
        if wide >= COV_WIDE:
            log.warning(
                "sensor %s: the position standard deviations of its detections (median %.3g m "
                "in its last batch) exceed the %.3g m over which the batch's %d detections "
                "spread, in %d of its first %d batches of %d detections or more: its cov "
                "(m², the squares of standard deviations; from range and bearing, "
                "J diag(σ_r², σ_θ²) Jᵀ with σ_θ in radians) is likely wrong, and tracks will "
                "not be confirmed",
                sensor,
                sigma,
                span,
                z.shape[0],
                wide,
                judged,
                COV_MIN_DETECTIONS,
            )

    def _forget(self, item: Item, batch: DetectionBatchIn) -> None:
        """A batch accepted, then refused by the tracker, is no duplicate if it comes again."""
        if item.digest is not None:
            self._recent.discard(batch.sensor_id, item.digest)

    def _process(self, item: Item, batch: DetectionBatchIn) -> None:
        pipeline = self._pipeline
        self._take_handed()
        try:
            scan = batch_to_scan(batch, pipeline.config.measurement.position_std)
            t0 = time.perf_counter()
            result = pipeline.process(scan)
            ms = (time.perf_counter() - t0) * 1000.0
            if self._dropped:  # the tracks a reset dropped: reported deleted now
                result = replace(result, deleted=self._dropped + result.deleted)
                self._dropped = ()
        except ScanRejected as exc:
            self._forget(item, batch)
            detail = exc.detail
            last = pipeline.last_time
            if exc.reason == "out_of_sequence" and last is not None:
                if last - batch.time > MAX_REORDER_WINDOW:
                    detail += (
                        f"; {last - batch.time:.6g} s behind is no network delay: this "
                        "sensor's clock and that of the sensors before it differ (all sensors "
                        "must share one time line, such as Unix time in seconds)"
                    )
                else:
                    detail += (
                        "; batches that reach the service later than others of their time are "
                        "taken in time order when ingest.reorder_window (now "
                        f"{self._applied_ingest.reorder_window:g} s) is at least that delay"
                    )
                if last - batch.time > RESET_HINT_LAG:
                    detail += (
                        "; a recording sent again from its start? POST /api/v1/reset (with the "
                        "API token) drops the tracks and the last time, and starts again"
                    )
            self._refusals.reject(item, exc.reason, detail, batch)
            return
        except Exception as exc:  # a tracker bug: report it, keep the worker alive
            log.exception("the tracker failed on a batch from %s", batch.sensor_id)
            self._forget(item, batch)
            self._refusals.reject(item, "internal_error", f"{type(exc).__name__}: {exc}", batch)
            return
        if self._ids is not None:  # before any report shows a new id
            self._ids.check(pipeline)
        if batch.cov is None and len(self._no_cov_sensors) < MAX_NO_COV_NOTES:
            self._note_missing_covariance(batch, pipeline.config.measurement.position_std)
        if result.range_rates[0]:
            self._judge_range_rates(batch.sensor_id, *result.range_rates)
        self._judge_covariances(batch.sensor_id, scan.z, scan.R)
        self._seq += 1
        self._last_wall = time.monotonic()
        self._clocks.accepted(batch.sensor_id, scan.time, self._last_wall)
        seq = self._seq
        confirmed = [track_to_dict(t) for t in result.confirmed()]
        state = ReportState.of(report_dict(seq, result, ms, confirmed), result)
        self._state = state
        if self._state_store is not None:
            self._checkpoint = EngineCheckpoint(
                seq, pipeline.checkpoint(), result.sensor_id, self._last_wall, self._resets
            )
        self.stats.processed(
            seq, result.time, len(batch.detections), ms, len(confirmed), batch.sensor_id
        )
        self._out.tracks(state.data)
        self.view.publish(state, scan.z)
        item.future.set_result(IngestResult(True, seq))
        if self.on_report is not None:
            try:
                self.on_report(state)
            except Exception:
                log.exception("the report hook failed")
