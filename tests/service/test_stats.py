"""Counters, gauges and histograms through prometheus_client; the JSON document with its
percentiles over the last 2048 batches; one registry per instance."""

from __future__ import annotations

import numpy as np

from service.schemas import ERROR_REASONS, MAX_SENSOR_SERIES
from service.stats import BATCH_SIZE_BUCKETS, PROCESSING_BUCKETS, SETTLED_BATCHES, WINDOW, Stats

from .helpers import parse_prometheus


def test_percentiles_over_a_sliding_window() -> None:
    stats = Stats("x")
    assert stats.percentiles()["window"] == 0
    for i in range(3000):
        stats.processed(i + 1, float(i), 10, 1000.0 if i < 952 else float(i % 100), 3)
    pct = stats.percentiles()
    assert pct["window"] == WINDOW == 2048
    recent = np.array([float(i % 100) for i in range(952, 3000)])
    assert pct["p50"] == round(float(np.percentile(recent, 50)), 4)
    assert pct["p99"] == round(float(np.percentile(recent, 99)), 4)
    assert pct["max"] == 99.0  # the 1000 ms batches slid out
    # the histogram keeps every batch
    samples = parse_prometheus(stats.prometheus().decode())
    assert samples["tracker_processing_seconds_count"] == 3000
    assert samples['tracker_processing_seconds_bucket{le="0.5"}'] == 3000 - 952
    assert samples['tracker_processing_seconds_bucket{le="+Inf"}'] == 3000


def test_snapshot_and_prometheus() -> None:
    stats = Stats('odd"id')
    stats.received(100)
    stats.received(50)
    stats.detections_in(7)
    stats.rejected_batch("invalid_batch")
    stats.rejected_batch("invalid_batch")
    stats.dropped()
    stats.processed(1, 2.0, 7, 1.5, 4)
    stats.tracks_tentative = lambda: 9
    stats.queue_depth = lambda: 3
    snap = stats.snapshot()
    assert snap["batches_received"] == 2 and snap["batches_rejected"] == 2
    assert snap["rejected_by_reason"] == {"invalid_batch": 2}
    assert snap["tracks_confirmed"] == 4 and snap["tracks_tentative"] == 9
    assert (snap["seq"], snap["last_time"], snap["queue_depth"]) == (1, 2.0, 3)
    samples = parse_prometheus(stats.prometheus().decode())
    assert samples["tracker_batches_received_total"] == 2
    assert samples['tracker_batches_rejected_total{reason="invalid_batch"}'] == 2
    # every reason has its series from the start, and no made-up ones
    reasons = {k for k in samples if k.startswith("tracker_batches_rejected_total{")}
    assert reasons == {
        f'tracker_batches_rejected_total{{reason="{r}"}}'
        for r in ERROR_REASONS
        if r != "overloaded"
    }
    assert samples['tracker_batches_rejected_total{reason="time_jump"}'] == 0
    assert samples["tracker_batches_dropped_total"] == 1
    assert samples["tracker_received_bytes_total"] == 150
    assert samples['tracker_tracks{status="tentative"}'] == 9
    assert samples['tracker_tracks{status="confirmed"}'] == 4
    assert samples["tracker_ingest_queue_depth"] == 3
    assert samples["tracker_last_seq"] == 1
    assert samples["tracker_processing_seconds_sum"] == 0.0015
    assert samples['tracker_info{instance_id="odd\\"id"}'] == 1
    assert not [k for k in samples if "_created" in k]


def test_histograms_of_time_and_batch_size() -> None:
    stats = Stats("x")
    for n, ms in [(0, 0.2), (3, 0.7), (55, 1.5), (55, 30.0), (12000, 4000.0)]:
        stats.processed(1, 1.0, n, ms, 0)
    samples = parse_prometheus(stats.prometheus().decode())

    def buckets(name: str, bounds: tuple[float, ...]) -> list[float]:
        return [samples[f'{name}_bucket{{le="{float(b)}"}}'] for b in bounds] + [
            samples[f'{name}_bucket{{le="+Inf"}}']
        ]

    assert buckets("tracker_processing_seconds", PROCESSING_BUCKETS) == [
        1, 2, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 5, 5
    ]  # fmt: skip
    assert buckets("tracker_batch_detections", BATCH_SIZE_BUCKETS) == [
        1, 1, 2, 2, 2, 2, 4, 4, 4, 4, 4, 4, 4, 5
    ]  # fmt: skip
    assert samples["tracker_batch_detections_sum"] == 12113
    assert samples["tracker_batch_detections_count"] == 5


def test_each_instance_counts_apart() -> None:
    a, b = Stats("a"), Stats("b")
    a.received(10)
    a.processed(1, 1.0, 5, 1.0, 2)
    assert b.snapshot()["batches_received"] == 0 and b.snapshot()["batches_processed"] == 0
    assert parse_prometheus(b.prometheus().decode())["tracker_batches_received_total"] == 0
    assert parse_prometheus(a.prometheus().decode())["tracker_batches_received_total"] == 1


def test_a_quiet_feed_shows_as_time_since_the_last_batch_of_each_sensor(monkeypatch) -> None:
    """Seconds since the last batch, overall and per sensor (the most recently heard
    MAX_SENSOR_SERIES, the most recent first), in the JSON and as Unix times in /metrics; a
    sensor pushed out has no series left, and a restored state's last batch counts."""
    import service.stats as module

    now = [1_000_000.0]
    monkeypatch.setattr(module.time, "time", lambda: now[0])
    stats = Stats("x")
    snap = stats.snapshot()
    assert snap["seconds_since_last_batch"] is None and snap["sensors"] == []
    assert (
        parse_prometheus(stats.prometheus().decode())["tracker_last_batch_timestamp_seconds"] == 0
    )
    stats.processed(1, 10.0, 5, 1.0, 2, "radar-a")
    now[0] += 4.0
    stats.processed(2, 12.0, 5, 1.0, 2, "radar-b")
    stats.processed(3, 13.0, 5, 1.0, 2, "radar-b")
    now[0] += 300.0  # the feeds fall quiet
    snap = stats.snapshot()
    assert snap["seconds_since_last_batch"] == 300.0
    assert snap["sensors"] == [
        {
            "sensor_id": "radar-b",
            "seconds_since_last_batch": 300.0,
            "last_time": 13.0,
            "batches": 2,
        },
        {
            "sensor_id": "radar-a",
            "seconds_since_last_batch": 304.0,
            "last_time": 10.0,
            "batches": 1,
        },
    ]
    samples = parse_prometheus(stats.prometheus().decode())
    assert samples["tracker_last_batch_timestamp_seconds"] == 1_000_004.0
    assert samples['tracker_sensor_last_batch_timestamp_seconds{sensor_id="radar-a"}'] == 1e6
    for i in range(MAX_SENSOR_SERIES):  # one-off sensors push the old ones out
        stats.processed(4 + i, 20.0, 1, 1.0, 2, f"cam-{i}")
    snap = stats.snapshot()
    assert len(snap["sensors"]) == MAX_SENSOR_SERIES
    assert snap["sensors"][0]["sensor_id"] == f"cam-{MAX_SENSOR_SERIES - 1}"
    series = [
        k
        for k in parse_prometheus(stats.prometheus().decode())
        if k.startswith("tracker_sensor_last_batch_timestamp_seconds{")
    ]
    assert len(series) == MAX_SENSOR_SERIES and not [k for k in series if "radar-" in k]

    for k in range(SETTLED_BATCHES):  # a radar heard often, then quiet amid one-off ids
        stats.processed(100 + k, 30.0 + k, 1, 1.0, 2, "radar-c")
    for i in range(3 * MAX_SENSOR_SERIES):
        stats.processed(200 + i, 50.0, 1, 1.0, 2, f"once-{i}")
    listed = [e["sensor_id"] for e in stats.snapshot()["sensors"]]
    assert len(listed) == MAX_SENSOR_SERIES and listed[-1] == "radar-c"
    assert 'sensor_id="radar-c"' in stats.prometheus().decode()

    restored = Stats("y")
    restored.restored(40, 99.0, 3, since_last_batch=120.0)
    assert restored.snapshot()["seconds_since_last_batch"] == 120.0
