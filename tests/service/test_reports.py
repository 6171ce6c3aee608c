"""After the tracker: the report state readers see (latest report, every live track, filters,
lookup), the sink hand-off, and the Error report's sensor."""

from __future__ import annotations

import logging
from typing import Any

import orjson
import pytest

from service.convert import batch_to_scan, empty_report, report_dict, track_to_dict
from service.engine import Engine
from service.ingest import check_batch
from service.reports import ReportOut, ReportState, error_report_for
from service.schemas import IngestConfig
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline

from .helpers import ListSink, batch_payload, run_batches


def test_the_state_before_any_batch() -> None:
    state = ReportState.empty()
    assert state.report == empty_report() and orjson.loads(state.data) == empty_report()
    assert state.snapshots() == () and state.tentative_count() == 0
    assert state.filtered("all") == empty_report()
    assert state.track("T1") is None


def test_state_of_a_step(scans: list[Any]) -> None:
    pipeline = TrackingPipeline(TrackerConfig())
    for scan in scans[:8]:
        batch = check_batch(batch_payload(scan), None, IngestConfig())
        result = pipeline.process(batch_to_scan(batch, 10.0))
    confirmed = [track_to_dict(t) for t in result.confirmed()]
    state = ReportState.of(report_dict(8, result, 1.0, confirmed), result)
    assert orjson.loads(state.data) == state.report and state.report["seq"] == 8
    assert confirmed and set(state.confirmed) == {t["id"] for t in confirmed}
    tentative = [t for t in result.tracks if t.status != "confirmed"]
    assert tentative and state.tentative_count() == len(tentative)
    every = state.all_tracks()
    assert every[: len(confirmed)] == confirmed
    assert [t["id"] for t in every[len(confirmed) :]] == [t.id for t in tentative]
    assert state.all_tracks() is every  # converted once
    assert state.filtered("tentative")["tracks"] == every[len(confirmed) :]
    assert state.filtered("confirmed", {"individual"})["tracks"] == confirmed
    assert state.filtered("all", {"extended"})["tracks"] == []
    assert state.track(tentative[0].id) == track_to_dict(tentative[0])


class FailingSink:
    def publish_tracks(self, data: bytes) -> None:
        raise RuntimeError("network down")

    def publish_error(self, sensor_id: str, data: bytes) -> None:
        raise RuntimeError("network down")


def test_a_failing_sink_is_logged_not_raised(caplog: pytest.LogCaptureFixture) -> None:
    out = ReportOut(FailingSink())
    with caplog.at_level(logging.ERROR, logger="service.reports"):
        out.tracks(b"{}")
        out.error(
            error_report_for(3, "invalid_json", "d", key_sensor_id=None, sensor_id=None, time=None)
        )
    assert [r.getMessage() for r in caplog.records] == ["publishing a report failed"] * 2
    sink = ListSink()
    out.sink = sink
    report = error_report_for(3, "invalid_json", "d", key_sensor_id="k", sensor_id="s", time=1.0)
    out.error(report)
    assert sink.errors == [("k", report)]


def test_error_report_sensor_precedence() -> None:
    def sensor(key: str | None, own: str | None) -> str:
        return error_report_for(1, "x", "d", key_sensor_id=key, sensor_id=own, time=None)[
            "sensor_id"
        ]

    assert (sensor("key", "own"), sensor(None, "own"), sensor(None, None)) == (
        "key",
        "own",
        "unknown",
    )


def test_all_tracks_and_lookup_include_tentative(engine: Engine, scans: list[Any]) -> None:
    run_batches(engine, [batch_payload(s) for s in scans[:6]])
    every = engine.tracks("all")["tracks"]
    confirmed = engine.tracks("confirmed")["tracks"]
    tentative = engine.tracks("tentative")["tracks"]
    assert len(every) == len(confirmed) + len(tentative)
    assert tentative, "clutter should leave tentative tracks"
    assert all(t["status"] == "tentative" for t in tentative)
    assert engine.track(tentative[0]["id"]) == tentative[0]
    assert engine.track(confirmed[0]["id"]) == confirmed[0]
    assert engine.track("nope") is None
    assert engine.tracks("all", {"formation"})["tracks"] == []
    assert engine.tracks("all", {"individual"})["tracks"] == every
