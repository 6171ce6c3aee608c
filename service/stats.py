"""Counters and processing-time percentiles, as JSON (``/api/v1/stats``) and as Prometheus
text (``/metrics``).

Every method is thread-safe: the engine's worker, the Zenoh callback threads and the REST
handlers all touch the same :class:`Stats`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import numpy as np

from service.schemas import ERROR_REASONS

_REJECT_REASONS = {reason: 0 for reason in ERROR_REASONS if reason != "overloaded"}

__all__ = ["WINDOW", "Stats"]

#: How many of the latest batches the processing-time percentiles are over.
WINDOW = 2048


class Stats:
    """What the service has done since it started."""

    def __init__(self, instance_id: str, queue_capacity: int = 0) -> None:
        self.instance_id = instance_id
        self.queue_capacity = queue_capacity
        self.started = time.time()
        self._started_mono = time.monotonic()
        self._lock = threading.Lock()
        self.batches_received = 0
        self.batches_processed = 0
        self.batches_dropped = 0
        self.rejected: dict[str, int] = {}
        self.detections_received = 0
        self.detections_processed = 0
        self.bytes_received = 0
        self.tracks_confirmed = 0
        #: Tentative tracks are counted on demand: building them all each batch is not free.
        self.tracks_tentative: Callable[[], int] = lambda: 0
        self.seq = 0
        self.last_time: float | None = None
        self.processing_seconds_sum = 0.0
        self._times: deque[float] = deque(maxlen=WINDOW)
        self.queue_depth = lambda: 0
        self.held_for_reorder = lambda: 0

    # -- recording ------------------------------------------------------------------------

    def received(self, nbytes: int) -> None:
        with self._lock:
            self.batches_received += 1
            self.bytes_received += nbytes

    def detections_in(self, n: int) -> None:
        with self._lock:
            self.detections_received += n

    def rejected_batch(self, reason: str) -> None:
        with self._lock:
            self.rejected[reason] = self.rejected.get(reason, 0) + 1

    def dropped(self) -> None:
        with self._lock:
            self.batches_dropped += 1

    def processed(
        self,
        seq: int,
        time_: float,
        n_detections: int,
        processing_ms: float,
        confirmed: int,
    ) -> None:
        with self._lock:
            self.batches_processed += 1
            self.detections_processed += n_detections
            self.seq = seq
            self.last_time = time_
            self.tracks_confirmed = confirmed
            self.processing_seconds_sum += processing_ms / 1000.0
            self._times.append(processing_ms)

    # -- reading --------------------------------------------------------------------------

    def percentiles(self) -> dict[str, float | int]:
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
        pct = self.percentiles()
        tentative = int(self.tracks_tentative())
        with self._lock:
            return {
                "instance_id": self.instance_id,
                "uptime_s": round(time.monotonic() - self._started_mono, 3),
                "seq": self.seq,
                "last_time": self.last_time,
                "batches_received": self.batches_received,
                "batches_processed": self.batches_processed,
                "batches_rejected": sum(self.rejected.values()),
                "rejected_by_reason": dict(sorted(self.rejected.items())),
                "batches_dropped": self.batches_dropped,
                "detections_received": self.detections_received,
                "detections_processed": self.detections_processed,
                "tracks_confirmed": self.tracks_confirmed,
                "tracks_tentative": tentative,
                "queue_depth": int(self.queue_depth()),
                "queue_capacity": self.queue_capacity,
                "held_for_reorder": int(self.held_for_reorder()),
                "processing_ms": pct,
            }

    def prometheus(self) -> str:
        """The Prometheus text exposition format (version 0.0.4)."""
        snap = self.snapshot()
        with self._lock:
            seconds_sum = self.processing_seconds_sum
            nbytes = self.bytes_received
        lines: list[str] = []

        def metric(name: str, kind: str, help_text: str, samples: list[tuple[str, Any]]) -> None:
            lines.append(f"# HELP {name} {help_text}")
            lines.append(f"# TYPE {name} {kind}")
            for labels, value in samples:
                lines.append(f"{name}{labels} {_number(value)}")

        metric(
            "tracker_info",
            "gauge",
            "Constant 1, labelled with this instance's id.",
            [(f'{{instance_id="{_escape(self.instance_id)}"}}', 1)],
        )
        metric(
            "tracker_uptime_seconds", "gauge", "Seconds since start-up.", [("", snap["uptime_s"])]
        )
        metric(
            "tracker_batches_received_total",
            "counter",
            "Detection batches received over Zenoh and REST.",
            [("", snap["batches_received"])],
        )
        metric(
            "tracker_batches_processed_total",
            "counter",
            "Detection batches the tracker processed.",
            [("", snap["batches_processed"])],
        )
        metric(
            "tracker_batches_rejected_total",
            "counter",
            "Detection batches refused with an Error report, by reason.",
            # every reason from the start, so that rates need no absent series; drops
            # ("overloaded") have a counter of their own
            [
                (f'{{reason="{_escape(r)}"}}', n)
                for r, n in {**_REJECT_REASONS, **snap["rejected_by_reason"]}.items()
            ],
        )
        metric(
            "tracker_batches_dropped_total",
            "counter",
            "Detection batches dropped because the ingest queue stayed full.",
            [("", snap["batches_dropped"])],
        )
        metric(
            "tracker_detections_received_total",
            "counter",
            "Detections in the batches that could be read.",
            [("", snap["detections_received"])],
        )
        metric(
            "tracker_detections_processed_total",
            "counter",
            "Detections in the batches the tracker processed.",
            [("", snap["detections_processed"])],
        )
        metric(
            "tracker_received_bytes_total",
            "counter",
            "Bytes of detection batch payloads received.",
            [("", nbytes)],
        )
        metric(
            "tracker_tracks",
            "gauge",
            "Live tracks after the last processed batch, by status.",
            [
                ('{status="confirmed"}', snap["tracks_confirmed"]),
                ('{status="tentative"}', snap["tracks_tentative"]),
            ],
        )
        metric(
            "tracker_ingest_queue_depth",
            "gauge",
            "Batches waiting for the tracker.",
            [("", snap["queue_depth"])],
        )
        metric(
            "tracker_reorder_held_batches",
            "gauge",
            "Batches held back by the reorder window.",
            [("", snap["held_for_reorder"])],
        )
        metric(
            "tracker_last_seq",
            "gauge",
            "seq of the last Track report.",
            [("", snap["seq"])],
        )
        pct = snap["processing_ms"]
        metric(
            "tracker_processing_seconds",
            "summary",
            f"Tracker time per batch; quantiles over the last {WINDOW} batches.",
            [
                ('{quantile="0.5"}', pct["p50"] / 1000.0),
                ('{quantile="0.9"}', pct["p90"] / 1000.0),
                ('{quantile="0.99"}', pct["p99"] / 1000.0),
                ('{quantile="1"}', pct["max"] / 1000.0),
            ],
        )
        lines.append(f"tracker_processing_seconds_sum {_number(seconds_sum)}")
        lines.append(f"tracker_processing_seconds_count {snap['batches_processed']}")
        return "\n".join(lines) + "\n"


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace("\n", "\\n").replace('"', '\\"')


def _number(value: Any) -> str:
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))
