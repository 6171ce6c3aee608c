"""Counters, percentiles over the last 2048 batches, and the Prometheus text."""

from __future__ import annotations

import numpy as np

from service.schemas import ERROR_REASONS
from service.stats import WINDOW, Stats

from .test_integration import parse_prometheus


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
    snap = stats.snapshot()
    assert snap["batches_received"] == 2 and snap["batches_rejected"] == 2
    assert snap["rejected_by_reason"] == {"invalid_batch": 2}
    assert snap["tracks_confirmed"] == 4 and snap["tracks_tentative"] == 9
    samples = parse_prometheus(stats.prometheus())
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
    assert samples["tracker_processing_seconds_sum"] == 0.0015
    assert samples['tracker_info{instance_id="odd\\"id"}'] == 1
