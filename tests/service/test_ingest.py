"""Before the tracker: edge checks, the time-jump guard, the reorder window, refusals and
payload peeking; on their own, and through a running engine with the real pipeline."""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future
from typing import Any

import orjson
import pytest

from service.engine import Engine
from service.ingest import (
    PEEK_PARSE_UP_TO,
    IngestResult,
    Item,
    RecentBatches,
    Refusals,
    ReorderBuffer,
    SensorClocks,
    batch_digest,
    check_batch,
    peek,
    time_jump_detail,
)
from service.reports import ReportOut
from service.schemas import BatchError, DetectionBatchIn, IngestConfig
from service.stats import Stats
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan, StepResult

from .helpers import ListSink, batch_payload, run_batches

pytestmark = pytest.mark.timeout(120)


def _batch(t: float, sensor: str = "radar-1", n: int = 0) -> DetectionBatchIn:
    dets = [{"x": float(i), "y": 0.0} for i in range(n)]
    return check_batch(
        orjson.dumps({"sensor_id": sensor, "time": t, "detections": dets}), None, IngestConfig()
    )


def _item(arrived: float, payload: bytes = b"{}", key: str | None = "radar-1") -> Item:
    return Item(payload, key, "test", Future(), arrived=arrived)


def test_check_batch_applies_the_key_and_the_limit() -> None:
    payload = orjson.dumps(
        {"sensor_id": "radar-1", "time": 1.0, "detections": [{"x": 1, "y": 2}, {"x": 3, "y": 4}]}
    )
    batch = check_batch(payload, "radar-1", IngestConfig())
    assert (batch.sensor_id, batch.time, len(batch.detections)) == ("radar-1", 1.0, 2)
    with pytest.raises(BatchError) as mismatch:
        check_batch(payload, "radar-2", IngestConfig())
    assert mismatch.value.reason == "sensor_mismatch"
    assert "'radar-1' differs from the key's last chunk 'radar-2'" in mismatch.value.detail
    with pytest.raises(BatchError) as many:
        check_batch(payload, None, IngestConfig(max_detections_per_batch=1))
    assert many.value.reason == "too_many_detections"
    assert many.value.detail == (
        "detections: 2 detections, more than ingest.max_detections_per_batch = 1"
    )
    with pytest.raises(BatchError) as bad:
        check_batch(b"[1, 2]", None, IngestConfig())
    assert bad.value.reason == "invalid_batch"


def test_time_jump_allows_twice_the_sensors_interval_and_the_reorder_window() -> None:
    assert time_jump_detail(30.0, 10.0, 5.0, 0.0, revisit=10.0) is None
    detail = time_jump_detail(30.5, 10.0, 5.0, 0.0, revisit=10.0)
    assert detail is not None and "2 times the sensor's usual 10 s between batches" in detail
    assert time_jump_detail(30.5, 10.0, 5.0, 0.0, revisit=10.0, window=1.0) is None
    detail = time_jump_detail(40.0, 10.0, 5.0, 0.0, revisit=10.0, window=1.0)
    assert detail is not None and "plus the 1 s reorder window" in detail


def test_sensor_clocks_give_the_median_interval_of_each_sensor() -> None:
    clocks = SensorClocks(gaps=4, sensors=2)
    assert clocks.revisit("a") == 0.0
    for t in (0.0, 1.0, 2.0, 3.0, 13.0):  # one long gap does not move the median
        clocks.accepted("a", t)
    assert clocks.revisit("a") == 1.0
    clocks.accepted("b", 0.0)
    clocks.accepted("b", 4.0)
    assert clocks.revisit("b") == 4.0
    clocks.accepted("c", 0.0)  # a third sensor: the least recently seen is forgotten
    assert clocks.revisit("a") == 0.0 and clocks.revisit("b") == 4.0


def test_time_jump_counts_the_wall_time_waited() -> None:
    assert time_jump_detail(110.0, 10.0, 100.0, 0.0) is None
    assert time_jump_detail(111.0, 10.0, 100.0, 2.0) is None
    detail = time_jump_detail(111.0, 10.0, 100.0, 0.5)
    assert detail is not None
    assert detail.startswith("time 111.0 is 101 s after the last processed time 10.0: ")
    assert "ingest.max_time_jump = 100.0 s plus the 0.5 s of wall time since" in detail
    assert "raise ingest.max_time_jump: PATCH /api/v1/config; " in detail  # the remedies
    assert detail.endswith(
        "if every sensor moved on to a new run or recording: POST /api/v1/reset (with the "
        "API token) drops the tracks and the last time first)"
    )


def test_reorder_buffer_releases_in_time_order_behind_the_newest() -> None:
    buf = ReorderBuffer()
    assert buf.wait_time(0.0, 2.0) is None and list(buf.due(0.0, 2.0)) == []
    for t in (3.0, 1.0, 2.0, 5.0, 4.0):
        buf.hold(_item(arrived=100.0), _batch(t))
    assert len(buf) == 5 and buf.newest_time == 5.0
    # window 2: what is at least 2 s older than the newest time (5) goes, oldest first
    assert [b.time for _, b in buf.due(100.5, 2.0)] == [1.0, 2.0, 3.0]
    assert len(buf) == 2
    assert buf.wait_time(100.5, 2.0) == pytest.approx(1.5)
    assert list(buf.due(101.0, 2.0)) == []
    # two seconds of wall time since the oldest arrival: the rest goes
    assert [b.time for _, b in buf.due(102.0, 2.0)] == [4.0, 5.0]
    assert len(buf) == 0


def test_reorder_buffer_wall_time_releases_the_expired_and_everything_older() -> None:
    buf = ReorderBuffer()
    buf.hold(_item(arrived=10.0), _batch(7.0))  # arrived first, newer time
    buf.hold(_item(arrived=11.0), _batch(5.0))
    buf.hold(_item(arrived=11.0), _batch(9.0))
    assert buf.wait_time(10.0, 3.0) == pytest.approx(3.0)
    # at 13 only the 7.0 batch has waited 3 s: it goes with the older 5.0, not the newer 9.0
    assert [b.time for _, b in buf.due(13.0, 3.0)] == [5.0, 7.0]
    assert [b.time for _, b in buf.drain()] == [9.0]
    # a window set to 0 since: everything goes at once
    buf.hold(_item(arrived=20.0), _batch(12.0))
    buf.hold(_item(arrived=20.0), _batch(11.0))
    assert [b.time for _, b in buf.due(20.0, 0.0)] == [11.0, 12.0]


def test_refusals_count_report_and_resolve() -> None:
    stats, sink = Stats("x"), ListSink()
    refusals = Refusals(stats, ReportOut(sink))
    batch = _batch(4.0, sensor="s-1")
    item = _item(0.0, payload=b"x" * 10, key=None)
    refusals.reject(item, "out_of_sequence", "too old", batch)
    assert item.future.result(0) == IngestResult(False, error=sink.errors[-1][1])
    assert sink.errors[-1] == (
        "s-1",
        {
            "sensor_id": "s-1",
            "time": 4.0,
            "error": "out_of_sequence",
            "detail": "too old",
            "received_bytes": 10,
        },
    )
    # the key's last chunk names the sensor over Zenoh, whatever the payload says
    report = refusals.refuse(b'{"sensor_id": "s-2", "time": 1}', "radar-9", "invalid_batch", "d")
    assert (report["sensor_id"], report["time"]) == ("radar-9", 1.0)
    report = refusals.refuse(b"garbage", None, "invalid_json", "d")
    assert (report["sensor_id"], report["time"]) == ("unknown", None)
    assert stats.snapshot()["rejected_by_reason"] == {
        "invalid_batch": 1,
        "invalid_json": 1,
        "out_of_sequence": 1,
    }
    assert stats.snapshot()["batches_dropped"] == 0


def test_drops_are_logged_at_most_once_a_second(caplog: pytest.LogCaptureFixture) -> None:
    stats, sink = Stats("x"), ListSink()
    refusals = Refusals(stats, ReportOut(sink))
    items = [_item(0.0, payload=b'{"sensor_id": "s-3", "time": 2.0}') for _ in range(5)]
    with caplog.at_level(logging.WARNING, logger="service.ingest"):
        for item in items:
            refusals.drop(item, "queue full")
        refusals.flush_log()
        refusals.flush_log()  # nothing more to say
    assert [r.getMessage() for r in caplog.records] == [
        "1 batch(es) dropped: queue full",
        "4 more batch(es) dropped",
    ]
    assert stats.snapshot()["batches_dropped"] == 5
    assert stats.snapshot()["rejected_by_reason"] == {}
    assert [e["error"] for _, e in sink.errors] == ["overloaded"] * 5
    assert all(i.future.result(0).error["sensor_id"] == "radar-1" for i in items)  # type: ignore[index]


def test_refusals_are_logged_once_per_reason_and_interval(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A newcomer sees refused batches in the log at warning level; a flood of them gives one
    line per reason every REFUSAL_LOG_INTERVAL seconds, with the count since the last."""
    import service.ingest as ingest

    clock = [100.0]
    monkeypatch.setattr(ingest.time, "monotonic", lambda: clock[0])
    refusals = Refusals(Stats("x"), ReportOut(ListSink()))
    nan = b'{"sensor_id": "s-1", "time": 3.0, "detections": [{"x": NaN, "y": 0}]}'
    with caplog.at_level(logging.WARNING, logger="service.ingest"):
        for _ in range(5):
            refusals.refuse(nan, None, "invalid_batch", "detections[0].x: not a number")
        refusals.refuse(b"{", "radar-2", "invalid_json", "EOF" + "x" * 1000)
        clock[0] += ingest.REFUSAL_LOG_INTERVAL
        refusals.refuse(nan, None, "invalid_batch", "detections[0].x: not a number")
        refusals.refuse(nan, None, "invalid_batch", "detections[0].x: not a number")
        refusals.refuse(b"{", "radar-3", "sensor_mismatch", "a\nWARNING fake line")
        refusals.flush_log()  # the refusals counted since the last line
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0] == (
        "batch refused, invalid_batch, sensor s-1, time 3.0: detections[0].x: not a number"
    )
    # a sender's text cannot start a log line of its own
    assert (
        lines[-2]
        == "batch refused, sensor_mismatch, sensor radar-3, time None: a\\nWARNING fake line"
    )
    assert lines[-1] == "1 more batch(es) refused, invalid_batch"
    lines = lines[:-2]
    assert lines[1].startswith("batch refused, invalid_json, sensor radar-2, time None: EOFxx")
    assert len(lines[1]) < 300  # the detail is cut short
    assert lines[2].endswith("(4 more invalid_batch since the last such line)")
    assert len(lines) == 3


def test_refusals_counted_in_an_interval_are_logged_when_it_ends(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A burst of refused batches followed by silence: the count of those after the first is
    logged once the interval is over (a newcomer's trial saw it only at shutdown, 66 s
    later), and not again at shutdown."""
    import service.ingest as ingest

    monkeypatch.setattr(ingest, "REFUSAL_LOG_INTERVAL", 0.2)
    refusals = Refusals(Stats("x"), ReportOut(ListSink()))
    nan = b'{"sensor_id": "s-1", "time": 3.0, "detections": [{"x": NaN, "y": 0}]}'
    with caplog.at_level(logging.WARNING, logger="service.ingest"):
        for _ in range(3):
            refusals.refuse(nan, None, "invalid_batch", "detections[0].x: not a number")
        deadline = time.monotonic() + 5.0
        while len(caplog.records) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        lines = [r.getMessage() for r in caplog.records]
        assert lines[0].startswith("batch refused, invalid_batch, sensor s-1")
        assert lines[1:] == ["2 more batch(es) refused, invalid_batch"]
        refusals.flush_log()
    assert len(caplog.records) == 2


@pytest.mark.parametrize(
    ("payload", "expected"),
    [
        (b'{"sensor_id": "s-9", "time": 5.0, "detections": [{"x": NaN}]}', ("s-9", 5.0)),
        (b'{"sensor_id": "s-9", "time": 3}', ("s-9", 3.0)),
        (b'{"sensor_id": "bad id!", "time": true}', (None, None)),
        (b'{"sensor_id": 7, "time": Infinity}', (None, None)),
        (b"[1, 2]", (None, None)),
        (b"\xff\xfe garbage", (None, None)),
        (b"[" * 100_000, (None, None)),
        # an integer of 400 digits is no float (the standard parser reads it; float() fails)
        (b'{"sensor_id": "s-9", "time": 1' + b"0" * 399 + b"}", ("s-9", None)),
        (b'{"sensor_id": "s-9", "time": -1' + b"0" * 399 + b".5e3}", ("s-9", None)),
        (b'{"sensor_id": "s-9", "time": 1e999}', ("s-9", None)),
        # a large payload is searched, not parsed
        (
            b'{"sensor_id": "big-1", "time": 12.5e2, "detections": ['
            + b'{"x": 1, "y": 2},' * (PEEK_PARSE_UP_TO // 16)
            + b"]}",
            ("big-1", 1250.0),
        ),
        (b'{"time": 1' + b"0" * 399 + b', "x": "' + b"a" * PEEK_PARSE_UP_TO + b'"}', (None, None)),
    ],
)
def test_peek_reads_what_it_can(payload: bytes, expected: tuple[Any, Any]) -> None:
    assert peek(payload) == expected


def test_error_report_names_what_it_can(engine: Engine, sink: ListSink) -> None:
    r = engine.submit(b'{"sensor_id": "s-9", "time": 4.0, "detections": 3}', None, "rest")
    err = r.result(timeout=10).error
    assert err is not None
    assert (err["sensor_id"], err["time"], err["error"]) == ("s-9", 4.0, "invalid_batch")
    assert err["detail"] == "detections: not a list"
    r = engine.submit(b"\xff\xfe garbage", None, "rest")
    err = r.result(timeout=10).error
    assert err is not None and err["sensor_id"] == "unknown" and err["time"] is None
    # NaN is no JSON, but the report still names the sensor and the time
    nan = b'{"sensor_id": "s-9", "time": 5.0, "detections": [{"x": NaN, "y": 1.0}]}'
    err = engine.submit(nan, None, "rest").result(timeout=10).error
    assert err is not None
    assert (err["sensor_id"], err["time"], err["error"]) == ("s-9", 5.0, "invalid_batch")
    assert err["detail"] == "detections[0].x: not a finite number"


def test_a_time_far_ahead_is_refused_and_blocks_nothing(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    """A clock gone wrong (a year ahead) would put every later batch out of sequence; it is
    refused, and the right times go on. Nanoseconds sent as seconds are beyond any time a
    batch may have."""
    run_batches(engine, [batch_payload(s) for s in scans[:3]])
    before = engine.latest_report_bytes()
    ahead = scans[3].time + 3.2e7
    bad = engine.submit(batch_payload(scans[3], time=ahead), "radar-1", "t").result(timeout=10)
    assert bad.error is not None and bad.error["error"] == "time_jump"
    assert "ingest.max_time_jump = 10.0 s" in bad.error["detail"]
    # a year ahead is no pause: the clocks differ (a newcomer's Unix-time sensor after one
    # counting from 0 was told to raise max_time_jump)
    assert "all sensors must share one time line" in bad.error["detail"]
    nanos = engine.submit(batch_payload(scans[3], time=1.7e18), "radar-1", "t").result(10)
    assert nanos.error is not None and nanos.error["error"] == "invalid_batch"
    assert nanos.error["detail"] == (
        "time: must be <= 1e+12 (seconds: a time in milliseconds, microseconds or "
        "nanoseconds is out of range)"
    )
    date = batch_payload(scans[3]).replace(
        orjson.dumps({"time": scans[3].time})[1:-1], b'"time":"2026-11-26T01:00:00Z"', 1
    )
    iso = engine.submit(date, "radar-1", "t").result(10)
    assert iso.error is not None and "not a date" in iso.error["detail"]
    behind = engine.submit(batch_payload(scans[0], time=-1.8e9), "radar-1", "t").result(10)
    assert behind.error is not None and behind.error["error"] == "out_of_sequence"
    assert "no network delay: this sensor's clock" in behind.error["detail"]
    assert engine.latest_report_bytes() == before
    assert all(r.accepted for r in run_batches(engine, [batch_payload(s) for s in scans[3:6]]))
    # a jump within max_time_jump is a pause, not an error
    later = engine.submit(batch_payload(scans[6], time=scans[5].time + 9.0), "radar-1", "t")
    assert later.result(timeout=10).accepted


def test_max_time_jump_counts_the_wall_time_waited(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(max_time_jump=1.0))
    eng.start()
    try:
        run_batches(eng, [batch_payload(scans[0])])
        r = eng.submit(batch_payload(scans[1], time=scans[0].time + 5.0), "radar-1", "t")
        assert r.result(timeout=10).error["error"] == "time_jump"  # type: ignore[index]
        time.sleep(0.5)  # 5 s ahead after 0.5 s of waiting: still too far
        r = eng.submit(batch_payload(scans[1], time=scans[0].time + 5.0), "radar-1", "t")
        assert r.result(timeout=10).error["error"] == "time_jump"  # type: ignore[index]
        r = eng.submit(batch_payload(scans[1], time=scans[0].time + 1.4), "radar-1", "t")
        assert r.result(timeout=10).accepted
    finally:
        eng.stop()


def test_too_many_detections(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(max_detections_per_batch=3))
    eng.start()
    try:
        r = eng.submit(batch_payload(scans[0]), "radar-1", "test").result(timeout=10)
        assert r.error is not None and r.error["error"] == "too_many_detections"
        assert "more than ingest.max_detections_per_batch = 3" in r.error["detail"]
        assert eng.seq == 0
    finally:
        eng.stop()


def test_reorder_window_puts_late_batches_in_order(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(reorder_window=1.5))
    eng.start()
    try:
        order = [0, 2, 1, 3, 5, 4, 6, 7]
        futures = [eng.submit(batch_payload(scans[i]), "radar-1", "t") for i in order]
        # held batches wait for newer times, or W seconds of wall time
        results = [f.result(timeout=10) for f in futures]
        assert all(r.accepted for r in results), [r.error for r in results]
        assert [r["time"] for r in sink.tracks] == [float(i) for i in range(8)]
        # older than the last processed time: still out of sequence
        late = eng.submit(batch_payload(scans[2]), "radar-1", "t").result(timeout=10)
        assert late.error is not None and late.error["error"] == "out_of_sequence"
    finally:
        eng.stop()


def test_reorder_window_releases_after_wall_time(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(reorder_window=0.3))
    eng.start()
    try:
        t0 = time.monotonic()
        fut = eng.submit(batch_payload(scans[0]), "radar-1", "t")
        time.sleep(0.1)
        assert not fut.done() and eng.stats.snapshot()["held_for_reorder"] == 1
        assert fut.result(timeout=5).accepted
        assert 0.25 <= time.monotonic() - t0 < 2.0
    finally:
        eng.stop()


def _counters_agree(engine: Engine) -> None:
    s = engine.stats.snapshot()
    assert s["batches_received"] == (
        s["batches_processed"] + s["batches_rejected"] + s["batches_dropped"]
    ), s


def test_a_time_of_400_digits_is_one_error_and_the_counters_agree(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    """It overflowed the float of the Error report's time: the refusal raised, was counted
    again as internal_error, and the received and refused counts parted."""
    run_batches(engine, [batch_payload(s) for s in scans[:2]])
    huge = b"1" + b"0" * 399
    payload = batch_payload(scans[2]).replace(
        orjson.dumps({"time": scans[2].time})[1:-1], b'"time":' + huge, 1
    )
    assert huge in payload
    result = engine.submit(payload, "radar-1", "zenoh").result(timeout=10)
    assert result.error is not None
    assert (result.error["error"], result.error["detail"]) == (
        "invalid_batch",
        "time: not a finite number",
    )
    assert result.error["time"] is None
    assert [e["error"] for _, e in sink.errors] == ["invalid_batch"]
    _counters_agree(engine)
    assert engine.stats.snapshot()["rejected_by_reason"] == {"invalid_batch": 1}


def test_a_batch_sent_twice_is_processed_once(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    run_batches(engine, [batch_payload(s) for s in scans[:6]])
    hits = {t["id"]: t["hits"] for t in engine.tracks("all")["tracks"]}
    again = engine.submit(batch_payload(scans[5]), "radar-1", "zenoh").result(timeout=10)
    assert again.error is not None and again.error["error"] == "duplicate_batch"
    assert again.error["time"] == scans[5].time
    assert "accepted before" in again.error["detail"]
    assert {t["id"]: t["hits"] for t in engine.tracks("all")["tracks"]} == hits
    assert engine.seq == 6
    # the same detections at the same time, written otherwise, are another batch
    other = orjson.dumps(scans[5].to_batch(), option=orjson.OPT_INDENT_2)
    assert engine.submit(other, "radar-1", "rest").result(timeout=10).accepted
    # an older copy is out of sequence, as it was
    old = engine.submit(batch_payload(scans[2]), "radar-1", "zenoh").result(timeout=10)
    assert old.error is not None and old.error["error"] == "out_of_sequence"
    _counters_agree(engine)


def test_a_copy_of_a_held_batch_is_a_duplicate(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(reorder_window=0.5))
    eng.start()
    try:
        first = eng.submit(batch_payload(scans[0]), "radar-1", "t")
        copy = eng.submit(batch_payload(scans[0]), None, "t").result(timeout=10)
        assert copy.error is not None and copy.error["error"] == "duplicate_batch"
        assert first.result(timeout=10).accepted and eng.seq == 1
    finally:
        eng.stop()


def test_recent_batches_are_bounded() -> None:
    recent = RecentBatches(per_sensor=3, sensors=2)
    digests = [batch_digest(bytes([i])) for i in range(5)]
    for d in digests:
        recent.add("a", d)
    assert [recent.seen("a", d) for d in digests] == [False, False, True, True, True]
    recent.add("b", digests[0])
    recent.add("a", digests[0])  # "a" seen last: "b" is the one forgotten next
    recent.add("c", digests[1])
    assert not recent.seen("b", digests[0]) and recent.seen("a", digests[0])
    assert recent.seen("c", digests[1]) and len(recent) == 4
    recent.discard("c", digests[1])
    assert not recent.seen("c", digests[1])
    recent.discard("nobody", digests[1])
    assert batch_digest(b"x") == batch_digest(b"x") != batch_digest(b"x ")


def test_a_payload_over_max_batch_bytes_is_refused_unread(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, max_batch_bytes=4096)
    eng.start()
    try:
        small = batch_payload(scans[0], detections=scans[0].to_batch()["detections"][:5])
        big = batch_payload(scans[1])
        assert len(small) <= 4096 < len(big)
        assert eng.submit(small, "radar-1", "t").result(timeout=10).accepted
        r = eng.submit(big, "radar-1", "t").result(timeout=10)
        assert r.error == {
            "sensor_id": "radar-1",
            "time": None,  # not read
            "error": "batch_too_large",
            "detail": f"payload: {len(big)} bytes, more than max_batch_bytes = 4096",
            "received_bytes": len(big),
        }
        with pytest.raises(BatchError) as info:
            eng.check(big)
        assert info.value.reason == "batch_too_large"
        report = eng.refuse_unread(10**9, None, "invalid_key", "key 'x': names no sensor")
        assert (report["sensor_id"], report["received_bytes"]) == ("unknown", 10**9)
        assert sink.errors[-1] == ("unknown", report)
        _counters_agree(eng)
    finally:
        eng.stop()


class _GatedPipeline(TrackingPipeline):
    """The real pipeline, holding each scan until the test lets it go."""

    gate = threading.Event()

    def process(self, scan: Scan) -> StepResult:
        assert self.gate.wait(30)
        return super().process(scan)


def test_the_queue_holds_a_bounded_number_of_bytes(sink: ListSink, scans: list[Any]) -> None:
    """Batches wait in the queue up to ``queue_bytes`` of payloads; past that a sender
    waits as for a full queue, and after ``put_timeout`` the batch is dropped."""
    payloads = [batch_payload(s) for s in scans[:4]]
    size = max(len(p) for p in payloads)
    gate = threading.Event()
    pipeline = type("Gated", (_GatedPipeline,), {"gate": gate})
    eng = Engine(sink=sink, queue_bytes=2 * size, put_timeout=0.3, pipeline_factory=pipeline)
    eng.start()
    try:
        first = eng.submit(payloads[0], "radar-1", "t")  # taken by the worker, held at the gate
        deadline = time.monotonic() + 10
        while eng.stats.snapshot()["queue_depth"] and time.monotonic() < deadline:
            time.sleep(0.01)
        queued = [eng.submit(p, "radar-1", "t") for p in payloads[1:3]]  # 2 x size: full
        t0 = time.monotonic()
        late = eng.submit(payloads[3], "radar-1", "t").result(timeout=10)
        assert time.monotonic() - t0 >= 0.25
        assert late.error is not None and late.error["error"] == "overloaded"
        assert f"ingest queue's {2 * size} bytes stayed full" in late.error["detail"]
        gate.set()
        assert first.result(timeout=10).accepted
        assert all(f.result(timeout=10).accepted for f in queued)
        # the budget is given back: the dropped batch goes in now
        assert eng.submit(payloads[3], "radar-1", "t").result(timeout=10).accepted
        _counters_agree(eng)
    finally:
        gate.set()
        eng.stop()


def test_a_sensor_whose_clock_runs_ahead_deletes_no_track_and_blocks_nothing(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    """Radar 1 reports every second; radar 2's clock jumps 50 minutes ahead for one batch,
    then runs right again. The bad batch is refused; radar 1's tracks are all kept, and
    both radars' later batches go on."""
    assert all(r.accepted for r in run_batches(engine, [batch_payload(s) for s in scans[:15]]))
    held = {t["id"] for t in engine.tracks()["tracks"]}
    assert len(held) > 30
    bad = batch_payload(scans[15], sensor_id="radar-2", time=scans[14].time + 3000.0)
    r = run_batches(engine, [bad], key="radar-2")[0]
    assert r.error is not None and r.error["error"] == "time_jump"
    assert {t["id"] for t in engine.tracks()["tracks"]} == held
    later = [batch_payload(scans[k], sensor_id="radar-2") for k in (15, 17)]
    assert all(r.accepted for r in run_batches(engine, later[:1], key="radar-2"))
    assert run_batches(engine, [batch_payload(scans[16])])[0].accepted
    assert run_batches(engine, later[1:], key="radar-2")[0].accepted
    assert len(held & {t["id"] for t in engine.tracks()["tracks"]}) >= len(held) - 2
    # A sensor that reports every 10 s, replayed faster than real time, is not a bad clock.
    slow = [
        batch_payload(scans[18], sensor_id="radar-3", time=scans[17].time + 9.5 * k)
        for k in range(1, 4)
    ]
    assert all(r.accepted for r in run_batches(engine, slow, key="radar-3"))


def test_sensor_clocks_say_which_sensor_is_due_before_a_time() -> None:
    clocks = SensorClocks()
    for t in (0.0, 0.5, 1.0):
        clocks.accepted("a", t, wall=100.0)
        clocks.accepted("b", t + 0.01, wall=100.0)
    # a's next batch is due at 1.5: a batch of b at 1.5 waits for it, one at 1.2 does not
    assert clocks.expected_before(1.5, "b", 100.2, set())
    assert not clocks.expected_before(1.2, "b", 100.2, set())
    assert not clocks.expected_before(1.5, "b", 100.2, {"a"})  # a's batch is held already
    assert clocks.expected_before(1.5, "a", 100.2, set())  # b's at 1.51: within 5 % of a tick
    for t in (0.1, 0.6, 1.1):
        clocks.accepted("c", t, wall=100.0)
    assert not clocks.expected_before(1.5, "a", 100.2, {"b"})  # c's is due at 1.6
    assert not clocks.expected_before(2.1, "b", 100.2, set())  # a is late a whole interval
    assert not clocks.expected_before(1.5, "b", 111.0, set())  # a not heard from for 11 s
    # on Unix time, a batch a quarter tick before a's next one does not wait (a tolerance
    # that grew with the clock's value made every batch wait)
    unix = SensorClocks()
    for t in (1.8e9, 1.8e9 + 0.5, 1.8e9 + 1.0):
        unix.accepted("a", t, wall=100.0)
    assert not unix.expected_before(1.8e9 + 1.375, "b", 100.2, set())
    assert unix.expected_before(1.8e9 + 1.49, "b", 100.2, set())  # within 5 % of a tick
    assert unix.expected_before(1.8e9 + 1.5, "b", 100.2, set())


def _on_one_tick(k: int, sensor: str, skew: float) -> bytes:
    """Batch ``k`` of a sensor on a 2 Hz tick of Unix time, stamped ``skew`` after it."""
    t = 1.8e9 + 0.5 * k + skew
    det = {"x": 100.0 * k, "y": 0.0, "cov": [[25.0, 0.0], [0.0, 25.0]]}
    return orjson.dumps({"sensor_id": sensor, "time": t, "detections": [det]})


@pytest.mark.parametrize("wait", [0.2, 0.0])
def test_two_sensors_on_one_tick_are_taken_in_time_order(sink: ListSink, wait: float) -> None:
    """A newcomer's two sensors on one tick, each batch reaching the service 5-50 ms late:
    with no reorder window 23 % were refused as out of sequence, some by 30 µs. The batch
    stamped later waits (at most ``sensor_wait``) for its rival due before it."""
    eng = Engine(sink=sink, ingest=IngestConfig(sensor_wait=wait))
    eng.start()
    try:
        for k in range(3):  # both sensors' usual intervals, in order
            assert eng.submit(_on_one_tick(k, "a", 0.0), None, "t").result(timeout=5).accepted
            assert eng.submit(_on_one_tick(k, "b", 3e-5), None, "t").result(timeout=5).accepted
        results = []
        for k in range(3, 9):  # b's stamped 30 µs later but arriving first
            first = eng.submit(_on_one_tick(k, "b", 3e-5), None, "t")
            time.sleep(0.02)
            second = eng.submit(_on_one_tick(k, "a", 0.0), None, "t")
            results += [first.result(timeout=5), second.result(timeout=5)]
        refused = [r.error["error"] for r in results if r.error is not None]
        if wait:
            assert refused == [] and eng.seq == 18
            assert [r["sensor_id"] for r in sink.tracks[6:]] == ["a", "b"] * 6
        else:
            assert refused == ["out_of_sequence"] * 6
    finally:
        eng.stop()


def test_a_lone_sensor_never_waits_and_a_silent_one_is_not_waited_for(sink: ListSink) -> None:
    eng = Engine(sink=sink, ingest=IngestConfig(sensor_wait=0.5))
    eng.start()
    try:
        for k in range(3):
            r = eng.submit(_on_one_tick(k, "a", 0.0), None, "t").result(timeout=5)
            assert r.accepted and r.seq == k + 1  # processed at once, not held
        t0 = time.monotonic()
        # b is due with a's next tick: a batch of b's at it waits for a, at most 0.5 s ...
        r = eng.submit(_on_one_tick(3, "b", 0.0), None, "t").result(timeout=5)
        assert r.accepted and 0.4 <= time.monotonic() - t0 < 2.0
        # ... and once a is late by a whole interval, nothing waits for it
        t0 = time.monotonic()
        for k in (5, 6):
            eng.submit(_on_one_tick(k, "b", 0.0), None, "t").result(timeout=5)
        assert time.monotonic() - t0 < 0.3
    finally:
        eng.stop()


def test_batches_held_under_an_earlier_setting_stay_in_time_order(sink: ListSink) -> None:
    """Held under a reorder window that is then set to 0 (and sensor_wait too), a later
    batch must not overtake them: they were acknowledged and would be refused."""
    eng = Engine(sink=sink, ingest=IngestConfig(reorder_window=30.0))
    eng.start()
    try:
        held = [eng.submit(_on_one_tick(k, "a", 0.0), None, "t") for k in range(2)]
        time.sleep(0.2)
        assert not any(f.done() for f in held)
        eng.patch_config({"ingest": {"reorder_window": 0.0, "sensor_wait": 0.0}})
        later = eng.submit(_on_one_tick(2, "a", 0.0), None, "t").result(timeout=5)
        results = [f.result(timeout=5) for f in held] + [later]
        assert all(r.accepted for r in results), [r.error for r in results]
        assert [r["time"] for r in sink.tracks] == [1.8e9, 1.8e9 + 0.5, 1.8e9 + 1.0]
    finally:
        eng.stop()
