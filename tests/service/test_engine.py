"""The engine with the real tracking pipeline: reports, bad input, configuration applied on the
next batch, overload, stopping and failures (no network; reports go to a list)."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pytest

from service.config_store import load_config_file
from service.config_tree import ConfigError
from service.engine import Engine
from service.ingest import IngestResult
from service.schemas import IngestConfig
from trackers.config import TrackerConfig
from trackers.peers import PeerProposal
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan, StepResult

from .helpers import ListSink, batch_payload, check_report, match_truth, run_batches

pytestmark = pytest.mark.timeout(120)


def test_reports_follow_the_truth(engine: Engine, sink: ListSink, scans: list[Any]) -> None:
    results = run_batches(engine, [batch_payload(s) for s in scans[:30]])
    assert [r.seq for r in results] == list(range(1, 31))
    assert [r["seq"] for r in sink.tracks] == list(range(1, 31))
    last = sink.tracks[-1]
    check_report(last)
    assert last == engine.latest_report()
    assert orjson.loads(engine.latest_report_bytes()) == last
    truth = scans[29].truth_states
    matched, errors = match_truth(last["tracks"], truth)
    assert matched >= 0.9 * len(truth), (matched, len(truth))
    assert np.median(errors) < 10.0
    stats = engine.stats.snapshot()
    assert stats["batches_processed"] == 30 and stats["batches_rejected"] == 0
    assert stats["detections_processed"] == sum(s.z.shape[0] for s in scans[:30])
    assert stats["processing_ms"]["window"] == 30
    assert stats["tracks_confirmed"] == len(last["tracks"])


BAD_INPUTS: list[tuple[str, Any, str | None]] = [
    ("invalid_json", b"{oops", "radar-1"),
    ("invalid_batch", b'{"sensor_id": "radar-1", "time": 99.0}', "radar-1"),
    (
        "invalid_batch",
        b'{"sensor_id": "radar-1", "time": 99.0, "detections": [{"x": NaN, "y": 0}]}',
        "radar-1",
    ),
    (
        "invalid_batch",
        orjson.dumps(
            {
                "sensor_id": "radar-1",
                "time": 99.0,
                "detections": [{"x": 1, "y": 1, "cov": [[1, 3], [3, 1]]}],
            }
        ),
        "radar-1",
    ),
    (
        "sensor_mismatch",
        orjson.dumps({"sensor_id": "radar-2", "time": 99.0, "detections": []}),
        "radar-1",
    ),
    (
        "out_of_sequence",
        orjson.dumps({"sensor_id": "radar-1", "time": 0.5, "detections": []}),
        "radar-1",
    ),
]


@pytest.mark.parametrize(("reason", "payload", "key"), BAD_INPUTS)
def test_bad_input_changes_nothing(
    engine: Engine, sink: ListSink, scans: list[Any], reason: str, payload: bytes, key: str
) -> None:
    run_batches(engine, [batch_payload(s) for s in scans[:5]])
    before = engine.latest_report_bytes()
    before_all = engine.tracks("all")
    result = engine.submit(payload, key, "test").result(timeout=10)
    assert not result.accepted and result.error is not None
    assert result.error["error"] == reason
    assert result.error["received_bytes"] == len(payload)
    assert set(result.error) == {"sensor_id", "time", "error", "detail", "received_bytes"}
    assert sink.errors[-1] == ("radar-1", result.error)
    assert engine.latest_report_bytes() == before
    assert engine.tracks("all") == before_all
    assert engine.stats.snapshot()["rejected_by_reason"] == {reason: 1}
    # the next good batch is processed as if nothing had happened
    good = engine.submit(batch_payload(scans[5]), "radar-1", "test").result(timeout=10)
    assert good.accepted and good.seq == 6


def test_config_patch_applies_on_next_batch_and_saves(
    tmp_path: Path, sink: ListSink, scans: list[Any]
) -> None:
    path = tmp_path / "conf" / "tracker.json"
    eng = Engine(sink=sink, config_file=path)
    eng.start()
    try:
        run_batches(eng, [batch_payload(scans[0])])
        doc = eng.patch_config(
            {"measurement": {"position_std": 7.0}, "ingest": {"max_detections_per_batch": 5}}
        )
        assert doc["measurement"]["position_std"] == 7.0
        assert eng.config_document() == doc
        assert orjson.loads(path.read_bytes()) == doc
        loaded = load_config_file(path, IngestConfig())
        assert loaded is not None and loaded[0].measurement.position_std == 7.0
        r = eng.submit(batch_payload(scans[1]), "radar-1", "t").result(timeout=10)
        assert r.error is not None and r.error["error"] == "too_many_detections"
        assert eng._pipeline.config.measurement.position_std == 7.0
        # invalid: nothing changes, not even the file
        saved = path.read_bytes()
        with pytest.raises(ConfigError, match=r"track_management\.pd"):
            eng.patch_config({"track_management": {"pd": 1.5}})
        with pytest.raises(ConfigError, match=r"ingest\.reorder_window"):
            eng.patch_config({"ingest": {"reorder_window": -1}})
        with pytest.raises(ConfigError, match=r"ingest\.reorder_window"):
            eng.patch_config({"ingest": {"reorder_window": 1e10}})  # > 1 hour
        with pytest.raises(ConfigError, match=r"ingest\.max_time_jump"):
            eng.patch_config({"ingest": {"max_time_jump": 0}})
        with pytest.raises(ConfigError, match="unknown"):
            eng.replace_config({"nonsense": {}})
        assert path.read_bytes() == saved and eng.config_document() == doc
        # PUT replaces; missing fields take their defaults; null in PATCH resets
        doc = eng.replace_config({"gating": {"gate_probability": 0.999}})
        assert doc["measurement"]["position_std"] == TrackerConfig().measurement.position_std
        assert doc["ingest"] == IngestConfig().model_dump()
        doc = eng.patch_config({"gating": {"gate_probability": None}})
        assert doc == eng.config_document()
        assert doc["gating"]["gate_probability"] == TrackerConfig().gating.gate_probability
    finally:
        eng.stop()


class SlowPipeline(TrackingPipeline):
    """The real pipeline, made slow to fill the queue."""

    def process(self, scan: Scan) -> StepResult:
        time.sleep(0.2)
        return super().process(scan)


def test_overload_drops_are_counted_and_reported(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, queue_size=1, put_timeout=0.05, pipeline_factory=SlowPipeline)
    eng.start()
    try:
        futures = [eng.submit(batch_payload(s), "radar-1", "t") for s in scans[:5]]
        results = [f.result(timeout=10) for f in futures]
        dropped = [r for r in results if r.error and r.error["error"] == "overloaded"]
        assert dropped, "a 1-slot queue behind a slow tracker must overflow"
        stats = eng.stats.snapshot()
        assert stats["batches_dropped"] == len(dropped)
        assert stats["batches_received"] == 5
        assert stats["batches_processed"] + len(dropped) == 5
        assert sum(1 for _, e in sink.errors if e["error"] == "overloaded") == len(dropped)
    finally:
        eng.stop()


def test_stop_is_quick_and_final(sink: ListSink, scans: list[Any]) -> None:
    eng = Engine(sink=sink, pipeline_factory=SlowPipeline, stop_drain_seconds=0.3)
    eng.start()
    futures = [eng.submit(batch_payload(s), "radar-1", "t") for s in scans[:20]]
    time.sleep(0.05)
    t0 = time.monotonic()
    eng.stop()
    assert time.monotonic() - t0 < 2.0
    assert not eng.running
    results = [f.result(timeout=1) for f in futures]  # every future resolved
    assert any(r.accepted for r in results)
    assert any(r.error and r.error["error"] == "overloaded" for r in results)
    after = eng.submit(batch_payload(scans[25]), "radar-1", "t").result(timeout=1)
    assert after.error is not None and after.error["error"] == "overloaded"


def test_concurrent_submitters(engine: Engine, scans: list[Any]) -> None:
    """Submitting from several threads at once loses nothing."""
    results: list[IngestResult] = []
    lock = threading.Lock()

    def send(part: list[Any]) -> None:
        for s in part:
            r = engine.submit(
                batch_payload(s, sensor_id=f"s{threading.get_ident() % 1000}"), None, "t"
            )
            with lock:
                results.append(r.result(timeout=30))

    threads = [threading.Thread(target=send, args=(scans[i::4],)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert len(results) == len(scans)
    stats = engine.stats.snapshot()
    assert stats["batches_received"] == len(scans)
    assert stats["batches_processed"] + stats["batches_rejected"] == len(scans)


class BrokenPipeline(TrackingPipeline):
    """The real pipeline, failing on one batch time (a stand-in for a tracker bug)."""

    def process(self, scan: Scan) -> StepResult:
        if scan.time == 3.0:
            raise RuntimeError("boom")
        return super().process(scan)


class UnconfigurablePipeline(TrackingPipeline):
    def reconfigure(self, config: TrackerConfig) -> None:
        raise RuntimeError("cannot reconfigure")


def test_a_failure_between_batches_refuses_the_batch_and_the_worker_survives(
    sink: ListSink, scans: list[Any]
) -> None:
    eng = Engine(sink=sink, pipeline_factory=UnconfigurablePipeline)
    eng.start()
    try:
        assert run_batches(eng, [batch_payload(scans[0])])[0].accepted
        eng.patch_config({"track_management": {"pd": 0.8}})
        r = run_batches(eng, [batch_payload(scans[1])])[0]
        assert r.error is not None and r.error["error"] == "internal_error"
        assert "cannot reconfigure" in r.error["detail"]
        assert eng.running
        assert run_batches(eng, [batch_payload(scans[2])])[0].accepted
    finally:
        eng.stop()


def test_a_tracker_failure_is_reported_and_the_worker_survives(
    sink: ListSink, scans: list[Any]
) -> None:
    eng = Engine(sink=sink, pipeline_factory=BrokenPipeline)
    eng.start()
    try:
        results = run_batches(eng, [batch_payload(s) for s in scans[:6]])
        assert [r.accepted for r in results] == [True, True, True, False, True, True]
        err = results[3].error
        assert err is not None and err["error"] == "internal_error" and "boom" in err["detail"]
        assert eng.running and eng.seq == 5
    finally:
        eng.stop()


class _PeerFailingOnce:
    """An extended-kind peer that claims nothing and fails on the scan at ``fail_at``."""

    kind = "extended"

    def __init__(self, fail_at: float) -> None:
        self.fail_at = fail_at
        self.committed = 0

    def propose(self, scan: Scan, view: Any) -> PeerProposal:
        if scan.time == self.fail_at:
            raise ArithmeticError("extent not positive definite")
        return PeerProposal(claimed=np.zeros(scan.size, dtype=bool))

    def commit(self, proposal: Any) -> None:
        self.committed += 1

    def snapshot(self) -> tuple[()]:
        return ()

    def reconfigure(self, config: TrackerConfig) -> None:
        pass


def test_a_failing_peer_is_an_internal_error_naming_it_and_changes_no_track(
    sink: ListSink, scans: list[Any]
) -> None:
    peer = _PeerFailingOnce(fail_at=scans[3].time)
    eng = Engine(sink=sink, pipeline_factory=lambda c: TrackingPipeline(c, peers=[peer]))
    eng.start()
    try:
        results = run_batches(eng, [batch_payload(s) for s in scans[:3]])
        assert all(r.accepted for r in results)
        before = eng.tracks("all")
        r = run_batches(eng, [batch_payload(scans[3])])[0]
        assert r.error is not None and r.error["error"] == "internal_error"
        assert "peer 'extended'" in r.error["detail"] and "positive definite" in r.error["detail"]
        assert eng.tracks("all") == before and eng.seq == 3 and peer.committed == 3
        # The same scan again goes through once the peer copes: nothing had moved on.
        peer.fail_at = -1.0
        assert run_batches(eng, [batch_payload(scans[3])])[0].accepted
        assert eng.seq == 4 and peer.committed == 4
    finally:
        eng.stop()


def test_a_sensor_without_covariances_is_told_once_what_is_assumed(
    engine: Engine, caplog: pytest.LogCaptureFixture
) -> None:
    def batch(sensor: str, t: float, cov: bool) -> bytes:
        det: dict[str, Any] = {"x": 100.0 * t, "y": 0.0}
        if cov:
            det["cov"] = [[25.0, 0.0], [0.0, 25.0]]
        return orjson.dumps({"sensor_id": sensor, "time": t, "detections": [det]})

    with caplog.at_level("WARNING", logger="service.engine"):
        run_batches(engine, [batch("covs", 3.0, True)], key=None)
        # refused (out of sequence): says nothing of the sensor, whose batches are not used
        (late,) = run_batches(engine, [batch("plain", 1.0, False)], key=None)
        assert not late.accepted
        assert not [r for r in caplog.records if "without a covariance" in r.getMessage()]
        run_batches(engine, [batch("plain", 4.0, False), batch("plain", 5.0, False)], key=None)
    notes = [r.getMessage() for r in caplog.records if "without a covariance" in r.getMessage()]
    assert len(notes) == 1
    assert notes[0].startswith("sensor plain sends detections without a covariance")
    assert "measurement.position_std = 10 m" in notes[0]


def test_a_batch_out_of_sequence_is_told_of_the_reorder_window(
    engine: Engine, scans: list[Any]
) -> None:
    run_batches(engine, [batch_payload(s) for s in scans[:3]])
    late = orjson.dumps({"sensor_id": "radar-1", "time": 0.5, "detections": []})
    result = engine.submit(late, "radar-1", "test").result(timeout=10)
    assert result.error is not None and result.error["error"] == "out_of_sequence"
    assert "ingest.reorder_window (now 0 s)" in result.error["detail"]


@pytest.mark.parametrize(("sign", "warned"), [(1.0, False), (-1.0, True)])
def test_a_sensor_whose_range_rates_disagree_is_told_once(
    engine: Engine, caplog: pytest.LogCaptureFixture, sign: float, warned: bool
) -> None:
    """A target receding at 100 m/s; the sensor sends its range-rate with the right sign, or
    the wrong one (approaching positive): the second is said once, the first never."""

    def batch(t: float) -> bytes:
        det = {"x": 5000.0 + 100.0 * t, "y": 0.0, "vr": sign * 100.0, "cov": [[25, 0], [0, 25]]}
        return orjson.dumps(
            {"sensor_id": "doppler", "time": t, "detections": [det], "sensor_position": [0, 0]}
        )

    with caplog.at_level("WARNING", logger="service.engine"):
        run_batches(engine, [batch(float(t)) for t in range(60)], key=None)
    notes = [r.getMessage() for r in caplog.records if "range-rates (vr)" in r.getMessage()]
    assert len(notes) == (1 if warned else 0)
    if warned:
        assert notes[0].startswith("sensor doppler: ") and "positive going away" in notes[0]


@pytest.mark.parametrize(("std", "warned"), [(30.0, False), (100e3, True)])
def test_a_sensor_whose_covariances_are_too_wide_is_told_once(
    engine: Engine, caplog: pytest.LogCaptureFixture, std: float, warned: bool
) -> None:
    """A newcomer's covariances 100 km wide (a range term doubled into the bearing's): every
    batch was taken, nothing was confirmed, and nothing said why. 20 detections a batch over
    60 km: said once, after the first 10 batches; 30 m, never."""
    rng = np.random.default_rng(0)
    cov = [[std**2, 0.0], [0.0, std**2]]

    def batch(t: float) -> bytes:
        xy = rng.uniform(-30e3, 30e3, (20, 2))
        dets = [{"x": float(x), "y": float(y)} for x, y in xy]
        return orjson.dumps({"sensor_id": "wide", "time": t, "detections": dets, "cov": cov})

    with caplog.at_level("WARNING", logger="service.engine"):
        run_batches(engine, [batch(float(t)) for t in range(9)], key=None)
        assert not [r for r in caplog.records if "standard deviations" in r.getMessage()]
        run_batches(engine, [batch(float(t)) for t in range(9, 30)], key=None)
    notes = [r.getMessage() for r in caplog.records if "standard deviations" in r.getMessage()]
    assert len(notes) == (1 if warned else 0)
    if warned:
        assert notes[0].startswith("sensor wide: ") and "in 10 of its first 10 batches" in notes[0]
