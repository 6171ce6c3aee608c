"""What leaves the tracker: where reports go (:class:`ReportSink`), the state readers see
(:class:`ReportState`, the latest Track report and every live track), and the Error report
of a refused batch (:func:`error_report_for`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Protocol

from service.convert import dumps, empty_report, error_report, track_to_dict
from trackers.types import StepResult, TrackSnapshot

__all__ = ["NullSink", "ReportOut", "ReportSink", "ReportState", "error_report_for"]

log = logging.getLogger("service.reports")


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


class ReportOut:
    """Hands reports to the current sink; a sink that fails is logged, never raised to the
    tracker's worker or a submitter."""

    def __init__(self, sink: ReportSink | None = None) -> None:
        self.sink: ReportSink = sink or NullSink()

    def tracks(self, data: bytes) -> None:
        try:
            self.sink.publish_tracks(data)
        except Exception:
            log.exception("publishing a report failed")

    def error(self, report: dict[str, Any]) -> None:
        try:
            self.sink.publish_error(report["sensor_id"], dumps(report))
        except Exception:
            log.exception("publishing a report failed")


def error_report_for(
    received_bytes: int,
    reason: str,
    detail: str,
    *,
    key_sensor_id: str | None,
    sensor_id: str | None,
    time: float | None,
) -> dict[str, Any]:
    """The Error report of a refused batch. Its sensor is the Zenoh key's last chunk, else
    the batch's own (``sensor_id``, what could be read of it), else ``unknown``."""
    return error_report(
        key_sensor_id or sensor_id or "unknown", time, reason, detail, received_bytes
    )


@dataclass
class ReportState:
    """The latest report and tracks; replaced as a whole, so readers need no lock."""

    report: dict[str, Any]
    data: bytes
    result: StepResult | None = None
    confirmed: dict[str, dict[str, Any]] = field(default_factory=dict)
    _all: list[dict[str, Any]] | None = None

    @classmethod
    def empty(cls) -> ReportState:
        """The state before any batch."""
        report = empty_report()
        return cls(report=report, data=dumps(report))

    @classmethod
    def of(cls, report: dict[str, Any], result: StepResult) -> ReportState:
        """The state after a processed batch: ``report`` holds its confirmed tracks."""
        return cls(
            report=report,
            data=dumps(report),
            result=result,
            confirmed={t["id"]: t for t in report["tracks"]},
        )

    def snapshots(self) -> tuple[TrackSnapshot, ...]:
        """Every live track, tentative too, as the tracker's snapshots."""
        return () if self.result is None else self.result.tracks

    def tentative_count(self) -> int:
        return len(self.snapshots()) - len(self.confirmed)

    def all_tracks(self) -> list[dict[str, Any]]:
        """Confirmed tracks as in the report, then the tentative ones (converted on first use;
        the step's state is immutable, so any thread may build it)."""
        if self._all is None:
            tentative = [track_to_dict(t) for t in self.snapshots() if t.status != "confirmed"]
            self._all = list(self.report["tracks"]) + tentative
        return self._all

    def filtered(self, status: str = "confirmed", kinds: set[str] | None = None) -> dict[str, Any]:
        """The report with its tracks filtered: ``status`` is ``confirmed``, ``tentative`` or
        ``all``; ``kinds`` keeps only those kinds."""
        if status == "confirmed":
            tracks = self.report["tracks"]
        else:
            tracks = self.all_tracks()
            if status == "tentative":
                tracks = [t for t in tracks if t["status"] == "tentative"]
        if kinds:
            tracks = [t for t in tracks if t["kind"] in kinds]
        return {**self.report, "tracks": tracks}

    def track(self, track_id: str) -> dict[str, Any] | None:
        """One live track (tentative too) by id, or ``None``."""
        found = self.confirmed.get(track_id)
        if found is not None:
            return found
        for t in self.snapshots():
            if t.id == track_id:
                return track_to_dict(t)
        return None
