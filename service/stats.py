"""What the service has done since it started, as Prometheus metrics (``/metrics``, through
``prometheus_client``) and as the JSON document of ``/api/v1/stats``.

Each :class:`Stats` has its own ``CollectorRegistry`` (two services in one process, as in the
tests, count apart). The counters, gauges and histograms are the one record; the JSON reads
them, and adds processing-time percentiles over the latest :data:`WINDOW` batches. Every
method is thread-safe: the engine's worker, the Zenoh callback threads and the REST handlers
all touch the same :class:`Stats`.

``prometheus_client``'s ``*_created`` series are turned off for the whole process (they say
when each series was created, which the service's uptime already tells).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from typing import Any

import numpy as np
from prometheus_client import (
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    Info,
    disable_created_metrics,
    generate_latest,
)

from service.schemas import ERROR_REASONS, MAX_SENSOR_SERIES

__all__ = [
    "BATCH_SIZE_BUCKETS",
    "MAX_SENSOR_SERIES",
    "PROCESSING_BUCKETS",
    "SETTLED_BATCHES",
    "WINDOW",
    "Stats",
]

disable_created_metrics()

#: A sensor with this many batches processed is kept in the table of recently heard sensors
#: over those with fewer (:meth:`Stats._evicted`).
SETTLED_BATCHES = 10

#: How many of the latest batches the JSON's processing-time percentiles are over.
WINDOW = 2048

#: Upper bounds of ``tracker_processing_seconds``: 0.5 ms to 5 s.
PROCESSING_BUCKETS = (
    0.0005,
    0.001,
    0.002,
    0.005,
    0.01,
    0.02,
    0.05,
    0.1,
    0.2,
    0.5,
    1.0,
    2.0,
    5.0,
)

#: Upper bounds of ``tracker_batch_detections``.
BATCH_SIZE_BUCKETS = (0, 1, 5, 10, 25, 50, 100, 250, 500, 1000, 2500, 5000, 10000)

#: Reasons with a ``tracker_batches_rejected_total`` series from the start; drops
#: (``overloaded``) have a counter of their own.
_REJECT_REASONS = tuple(reason for reason in ERROR_REASONS if reason != "overloaded")


class Stats:
    """Counters, gauges and histograms of one service instance."""

    def __init__(self, instance_id: str, queue_capacity: int = 0) -> None:
        self.instance_id = instance_id
        self.queue_capacity = queue_capacity
        self.started = time.time()
        self._started_mono = time.monotonic()
        #: Read when asked: tentative tracks (building them all each batch is not free), the
        #: batches waiting in the queue and those held by the reorder window.
        self.tracks_tentative: Callable[[], int] = lambda: 0
        self.queue_depth: Callable[[], int] = lambda: 0
        self.held_for_reorder: Callable[[], int] = lambda: 0
        self.viewers: Callable[[], int] = lambda: 0  # live view streams connected
        self.seq = 0
        self.last_time: float | None = None
        self.tracks_confirmed = 0
        self._times: deque[float] = deque(maxlen=WINDOW)
        self._lock = threading.Lock()  # the window and the last batch's figures
        #: wall-clock (Unix) time the last batch was processed, or that a restored state's
        #: last batch was; and each recently heard sensor's [that time, batch time, batches]
        self._last_batch_wall: float | None = None
        self._sensors: OrderedDict[str, list[float]] = OrderedDict()

        r = self.registry = CollectorRegistry(auto_describe=True)
        Info("tracker", "Constant 1, labelled with this instance's id.", registry=r).info(
            {"instance_id": instance_id}
        )
        Gauge("tracker_uptime_seconds", "Seconds since start-up.", registry=r).set_function(
            self.uptime
        )
        self._received = Counter(
            "tracker_batches_received",
            "Detection batches received over Zenoh and REST.",
            registry=r,
        )
        self._processed = Counter(
            "tracker_batches_processed", "Detection batches the tracker processed.", registry=r
        )
        self._rejected = Counter(
            "tracker_batches_rejected",
            "Detection batches refused with an Error report, by reason.",
            ["reason"],
            registry=r,
        )
        for reason in _REJECT_REASONS:  # every series from the start: rates need no absent ones
            self._rejected.labels(reason=reason)
        self._dropped = Counter(
            "tracker_batches_dropped",
            "Detection batches dropped because the ingest queue stayed full.",
            registry=r,
        )
        self._detections_received = Counter(
            "tracker_detections_received",
            "Detections in the batches that could be read.",
            registry=r,
        )
        self._detections_processed = Counter(
            "tracker_detections_processed",
            "Detections in the batches the tracker processed.",
            registry=r,
        )
        self._bytes = Counter(
            "tracker_received_bytes", "Bytes of detection batch payloads received.", registry=r
        )
        tracks = Gauge(
            "tracker_tracks",
            "Live tracks after the last processed batch, by status.",
            ["status"],
            registry=r,
        )
        tracks.labels(status="confirmed").set_function(lambda: self.tracks_confirmed)
        tracks.labels(status="tentative").set_function(lambda: self.tracks_tentative())
        Gauge(
            "tracker_ingest_queue_depth", "Batches waiting for the tracker.", registry=r
        ).set_function(lambda: self.queue_depth())
        Gauge(
            "tracker_reorder_held_batches", "Batches held back by the reorder window.", registry=r
        ).set_function(lambda: self.held_for_reorder())
        Gauge("tracker_last_seq", "seq of the last Track report.", registry=r).set_function(
            lambda: self.seq
        )
        Gauge(
            "tracker_view_viewers", "Live view streams connected (GET /api/v1/stream).", registry=r
        ).set_function(lambda: self.viewers())
        self._view_dropped = Counter(
            "tracker_view_frames_dropped",
            "Live view frames replaced by a newer one before their viewer took them.",
            registry=r,
        )
        Gauge(
            "tracker_last_batch_timestamp_seconds",
            "Unix time the last detection batch was processed (0: none yet). A feed gone "
            "quiet shows as time() minus this growing: the tracks then are as of that batch.",
            registry=r,
        ).set_function(lambda: self._last_batch_wall or 0.0)
        self._sensor_last = Gauge(
            "tracker_sensor_last_batch_timestamp_seconds",
            f"Unix time each sensor's last batch was processed (the {MAX_SENSOR_SERIES} most "
            "recently heard sensors).",
            ["sensor_id"],
            registry=r,
        )
        self._processing = Histogram(
            "tracker_processing_seconds",
            "Tracker time per processed batch.",
            buckets=PROCESSING_BUCKETS,
            registry=r,
        )
        self._batch_size = Histogram(
            "tracker_batch_detections",
            "Detections per processed batch.",
            buckets=BATCH_SIZE_BUCKETS,
            registry=r,
        )

    # -- recording ------------------------------------------------------------------------

    def received(self, nbytes: int) -> None:
        self._received.inc()
        self._bytes.inc(nbytes)

    def detections_in(self, n: int) -> None:
        self._detections_received.inc(n)

    def rejected_batch(self, reason: str) -> None:
        self._rejected.labels(reason=reason).inc()

    def dropped(self) -> None:
        self._dropped.inc()

    def view_frame_dropped(self) -> None:
        self._view_dropped.inc()

    def processed(
        self,
        seq: int,
        time_: float,
        n_detections: int,
        processing_ms: float,
        confirmed: int,
        sensor_id: str | None = None,
    ) -> None:
        self._processed.inc()
        self._detections_processed.inc(n_detections)
        self._processing.observe(processing_ms / 1000.0)
        self._batch_size.observe(n_detections)
        wall = time.time()
        gone: list[str] = []
        with self._lock:
            self.seq = seq
            self.last_time = time_
            self.tracks_confirmed = confirmed
            self._times.append(processing_ms)
            self._last_batch_wall = wall
            if sensor_id is not None:
                entry = self._sensors.pop(sensor_id, None)
                self._sensors[sensor_id] = [wall, time_, (entry[2] if entry else 0) + 1]
                while len(self._sensors) > MAX_SENSOR_SERIES:
                    gone.append(self._evicted(sensor_id))
            # (the gauge's series change under the lock too: a sensor evicted by one batch
            # and heard again in the next keeps its series)
            for old in gone:
                self._sensor_last.remove(old)
            if sensor_id is not None:
                self._sensor_last.labels(sensor_id=sensor_id).set(wall)

    def _evicted(self, keep: str) -> str:
        """Drop one sensor from the table (under the lock) and give its id: the least
        recently heard of those with fewer than :data:`SETTLED_BATCHES` batches other than
        ``keep`` (one-off ids), else the least recently heard. A radar gone quiet while a
        stream of new ids comes in keeps its series, for the alert on its silence."""
        for sensor_id, entry in self._sensors.items():
            if entry[2] < SETTLED_BATCHES and sensor_id != keep:
                del self._sensors[sensor_id]
                return sensor_id
        return self._sensors.popitem(last=False)[0]

    def restored(
        self, seq: int, time_: float, confirmed: int, since_last_batch: float | None = None
    ) -> None:
        """The report counter, time and confirmed tracks of a state restored at start, and
        the wall-clock seconds since its last batch was processed."""
        with self._lock:
            self.seq = seq
            self.last_time = time_
            self.tracks_confirmed = confirmed
            if since_last_batch is not None:
                self._last_batch_wall = time.time() - since_last_batch

    # -- reading --------------------------------------------------------------------------

    def uptime(self) -> float:
        return time.monotonic() - self._started_mono

    def percentiles(self) -> dict[str, float | int]:
        """Processing times, ms, over the latest :data:`WINDOW` batches."""
        with self._lock:
            times = np.fromiter(self._times, dtype=float, count=len(self._times))
        if times.size == 0:
            return {"p50": 0.0, "p90": 0.0, "p99": 0.0, "max": 0.0, "mean": 0.0, "window": 0}
        p50, p90, p99 = np.percentile(times, [50, 90, 99])
        return {
            "p50": round(float(p50), 4),
            "p90": round(float(p90), 4),
            "p99": round(float(p99), 4),
            "max": round(float(times.max()), 4),
            "mean": round(float(times.mean()), 4),
            "window": int(times.size),
        }

    def snapshot(self) -> dict[str, Any]:
        """The ``/api/v1/stats`` document (see :class:`service.schemas.StatsOut`)."""
        rejected: dict[str, int] = {}
        for sample in self._rejected.collect()[0].samples:
            if sample.name.endswith("_total") and sample.value:
                rejected[sample.labels["reason"]] = int(sample.value)
        now = time.time()
        with self._lock:
            seq, last_time, confirmed = self.seq, self.last_time, self.tracks_confirmed
            last_wall = self._last_batch_wall
            sensors = [
                {
                    "sensor_id": sensor_id,
                    "seconds_since_last_batch": round(max(now - wall, 0.0), 3),
                    "last_time": t,
                    "batches": int(n),
                }
                for sensor_id, (wall, t, n) in reversed(self._sensors.items())
            ]
        return {
            "instance_id": self.instance_id,
            "uptime_s": round(self.uptime(), 3),
            "seq": seq,
            "last_time": last_time,
            "seconds_since_last_batch": (
                None if last_wall is None else round(max(now - last_wall, 0.0), 3)
            ),
            "sensors": sensors,
            "batches_received": _count(self._received),
            "batches_processed": _count(self._processed),
            "batches_rejected": sum(rejected.values()),
            "rejected_by_reason": dict(sorted(rejected.items())),
            "batches_dropped": _count(self._dropped),
            "detections_received": _count(self._detections_received),
            "detections_processed": _count(self._detections_processed),
            "tracks_confirmed": confirmed,
            "tracks_tentative": int(self.tracks_tentative()),
            "queue_depth": int(self.queue_depth()),
            "queue_capacity": self.queue_capacity,
            "held_for_reorder": int(self.held_for_reorder()),
            "processing_ms": self.percentiles(),
            "viewers": int(self.viewers()),
            "view_frames_dropped": _count(self._view_dropped),
        }

    def prometheus(self) -> bytes:
        """The Prometheus text exposition format (version 0.0.4)."""
        return generate_latest(self.registry)


def _count(counter: Counter) -> int:
    """An unlabelled counter's value."""
    for sample in counter.collect()[0].samples:
        if sample.name.endswith("_total"):
            return int(sample.value)
    return 0
