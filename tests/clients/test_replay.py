"""``tracker-replay`` of a recorded file against the real service over Zenoh."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import orjson
import pytest

from clients import replay
from clients.scenarios.multitarget import reference_scenario, simulate
from tests.conftest import RunningService, free_port
from tests.service.helpers import wait_until

pytestmark = pytest.mark.timeout(120)

SCANS = simulate(reference_scenario(5))[:20]


def _record(path: Path, extra: list[bytes] | None = None) -> Path:
    lines = [orjson.dumps(s.to_batch()) for s in SCANS]
    path.write_bytes(b"\n".join(lines + (extra or [])) + b"\n")
    return path


def test_replay_max_rate_gives_the_same_tracks_as_direct_processing(
    service: RunningService, tmp_path: Path
) -> None:
    path = _record(tmp_path / "rec.jsonl")
    assert replay.main([str(path), "--rate", "max", "-e", service.endpoint, "-q"]) == 0
    assert service.engine.seq == len(SCANS)
    got = httpx.get(service.url + "/api/v1/tracks").json()
    assert got["time"] == SCANS[-1].time

    # the same batches straight into a fresh engine give the same tracks
    from service.engine import Engine

    engine = Engine()
    engine.start()
    try:
        for line in path.read_bytes().splitlines():
            engine.submit(line, "radar-1", "test").result(timeout=10)
        direct = engine.latest_report()
    finally:
        engine.stop()
    assert got["tracks"] == direct["tracks"] and got["deleted"] == direct["deleted"]


def test_replay_realtime_with_speed_and_offset(service: RunningService, tmp_path: Path) -> None:
    path = tmp_path / "short.jsonl"
    path.write_bytes(b"\n".join(orjson.dumps(s.to_batch()) for s in SCANS[:4]) + b"\n")
    t0 = time.monotonic()
    code = replay.main(
        [str(path), "--speed", "10", "--time-offset", "500", "-e", service.endpoint, "-q"]
    )
    assert code == 0
    assert time.monotonic() - t0 >= 3 / 10
    wait_until(lambda: service.engine.seq == 4)
    assert httpx.get(service.url + "/api/v1/tracks").json()["time"] == 503.0


def test_replay_skips_unroutable_lines_and_reports_bad_batches(
    service: RunningService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad_batch = orjson.dumps({"sensor_id": "radar-1", "time": 1e6, "detections": [{"x": 1}]})
    path = _record(tmp_path / "mixed.jsonl", [b"not json", b"", b"[1]", bad_batch])
    assert replay.main([str(path), "--rate", "max", "-e", service.endpoint, "-q"]) == 0
    captured = capsys.readouterr()
    assert "mixed.jsonl:21: no usable sensor_id" in captured.err
    assert "mixed.jsonl:23: no usable sensor_id" in captured.err
    assert "replayed 21 batches" in captured.out and "21 answered, 1 error reports" in captured.out
    stats = service.engine.stats.snapshot()
    assert stats["batches_processed"] == 20
    assert stats["rejected_by_reason"] == {"invalid_batch": 1}


def test_replay_missing_file(tmp_path: Path) -> None:
    assert replay.main([str(tmp_path / "nope.jsonl")]) == 2


def test_replay_bad_speed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _record(tmp_path / "rec.jsonl")
    assert replay.main([str(path), "--speed", "-1"]) == 2
    assert capsys.readouterr().err == "tracker-replay: --speed must be > 0\n"


def test_replay_without_service_fails_clearly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _record(tmp_path / "rec.jsonl")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    code = replay.main([str(path), "-e", endpoint, "--wait-matching", "0.3", "-q"])
    assert code == 1
    assert capsys.readouterr().err == (
        "tracker-replay: no subscriber on tracking/detections/radar-1 after 0.3 s: "
        "is the service running?\n"
    )
