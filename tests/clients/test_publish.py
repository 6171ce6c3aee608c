"""``tracker-publish`` against the real service over Zenoh."""

from __future__ import annotations

import re
import time
from pathlib import Path

import httpx
import numpy as np
import orjson
import pytest

from clients import publish
from clients.scenarios.multitarget import reference_scenario, simulate
from service.schemas import decode_batch
from tests.conftest import RunningService, free_port
from tests.service.helpers import wait_until

pytestmark = pytest.mark.timeout(120)


def test_publish_max_rate_loses_nothing_and_records(
    service: RunningService, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record = tmp_path / "run.jsonl"
    code = publish.main(
        ["--rate", "max", "--scans", "40", "-e", service.endpoint, "--record", str(record), "-q"]
    )
    assert code == 0
    assert "published 40 batches" in capsys.readouterr().out
    assert service.engine.seq == 40  # the publisher waited for every answer
    stats = httpx.get(service.url + "/api/v1/stats").json()
    assert stats["batches_received"] == 40 and stats["batches_rejected"] == 0
    lines = record.read_bytes().splitlines()
    assert len(lines) == 40
    expected = simulate(reference_scenario(0))[:40]
    for line, scan in zip(lines, expected, strict=True):
        batch = decode_batch(line)
        assert batch.time == scan.time and len(batch.detections) == scan.z.shape[0]
    report = httpx.get(service.url + "/api/v1/tracks").json()
    assert len(report["tracks"]) >= 45


def test_publish_realtime_paces_by_batch_time(service: RunningService) -> None:
    t0 = time.monotonic()
    code = publish.main(
        [
            "--scans",
            "5",
            "--speed",
            "20",
            "--seed",
            "2",
            "--time-offset",
            "1000",
            "-e",
            service.endpoint,
            "-q",
        ]
    )
    elapsed = time.monotonic() - t0
    assert code == 0
    assert elapsed >= 4 / 20
    wait_until(lambda: service.engine.seq == 5)
    assert httpx.get(service.url + "/api/v1/tracks").json()["time"] == 1004.0


def test_publish_scale_scenario(service: RunningService) -> None:
    code = publish.main(
        [
            "--scenario",
            "scale",
            "--targets",
            "100",
            "--clutter",
            "50",
            "--scans",
            "3",
            "--rate",
            "max",
            "-e",
            service.endpoint,
            "-q",
        ]
    )
    assert code == 0
    wait_until(lambda: service.engine.seq == 3)
    assert service.engine.stats.snapshot()["detections_processed"] > 3 * 100


def test_publish_without_service_fails_clearly(capsys: pytest.CaptureFixture[str]) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    code = publish.main(["--scans", "2", "-e", endpoint, "--wait-matching", "0.3", "-q"])
    assert code == 1
    assert "is the service running?" in capsys.readouterr().err


def test_publish_prints_error_reports(
    service_factory: object, capsys: pytest.CaptureFixture[str]
) -> None:
    svc = service_factory(max_detections_per_batch=5)  # type: ignore[operator]
    code = publish.main(["--scans", "2", "--rate", "max", "-e", svc.endpoint, "-q"])
    assert code == 0
    captured = capsys.readouterr()
    assert "too_many_detections" in captured.err
    assert "2 answered, 2 error reports" in captured.out
    assert orjson.loads(svc.engine.latest_report_bytes())["seq"] == 0


def test_publish_max_rate_waits_for_every_answer(
    service: RunningService, capsys: pytest.CaptureFixture[str]
) -> None:
    """Many more batches than the network buffers hold: all are processed by the time the
    publisher returns (closing a session with puts in flight would lose them)."""
    code = publish.main(
        ["--rate", "max", "--scans", "400", "--max-in-flight", "16", "-e", service.endpoint]
    )
    assert code == 0
    assert "400 answered, 0 error reports" in capsys.readouterr().out
    stats = service.engine.stats.snapshot()
    assert stats["batches_processed"] == 400 and stats["batches_dropped"] == 0


def test_publish_gives_up_when_the_service_stops_answering(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from clients.zenoh_session import open_session

    # a bare subscriber matches the detections key but never answers
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session("peer", [], [endpoint])
    try:
        sub = session.declare_subscriber("tracking/detections/**", lambda sample: None)
        code = publish.main(
            ["--scans", "3", "--rate", "max", "--answer-timeout", "0.5", "-e", endpoint]
        )
        sub.undeclare()
    finally:
        session.close()
    assert code == 1
    assert "did not answer: 3 of 3 batches unanswered" in capsys.readouterr().err


def test_publish_summary_is_what_the_load_benchmark_parses(
    service: RunningService, capsys: pytest.CaptureFixture[str]
) -> None:
    code = publish.main(["--rate", "max", "--scans", "3", "-e", service.endpoint, "-q"])
    assert code == 0
    out = capsys.readouterr().out
    m = re.search(r"published (\d+) batches in ([\d.]+) s", out)  # benchmarks/service_load.py
    assert m is not None and m.group(1) == "3"
    assert re.search(r"\(\d+ batches/s\); 3 answered, 0 error reports\n$", out), out


def test_publish_bad_speed(capsys: pytest.CaptureFixture[str]) -> None:
    assert publish.main(["--speed", "0"]) == 2
    assert capsys.readouterr().err == "tracker-publish: --speed must be > 0\n"


def test_publish_mixed_speeds_and_the_default_service_tracks_jets(service: RunningService) -> None:
    """A newcomer's path: the service as started, the mixed-speed scenario over Zenoh, the
    tracks over REST: airliners and jets get confirmed tracks with the default configuration."""
    from clients.scenarios.airspace import mixed_speed_scenario, simulate_scripted

    n = len(simulate_scripted(mixed_speed_scenario(period=4.0, seed=0)))
    code = publish.main(
        ["--scenario", "mixed-speeds", "--rate", "max", "-e", service.endpoint, "-q"]
    )
    assert code == 0
    wait_until(lambda: service.engine.seq == n)
    tracks = httpx.get(service.url + "/api/v1/tracks").json()["tracks"]
    speeds = sorted(float(np.hypot(*t["velocity"])) for t in tracks)
    assert len(tracks) >= 24  # of 26 targets
    assert sum(s > 150 for s in speeds) >= 9  # 8 airliners and 2 jets
    assert speeds[-1] > 600


def test_publish_scripted_scenario_refuses_flags_that_do_not_apply(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert publish.main(["--scenario", "formations", "--targets", "3"]) == 2
    assert "--targets: not for the scripted scenario formations" in capsys.readouterr().err
