"""``python -m clients.demo`` against the real service over Zenoh: it publishes the reference
scenario, starts after the service's latest time, logs summaries read from the service's
queryable, and stops on request or when its parent is gone."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import orjson
import pytest

from clients.demo import Demo, summary_line
from clients.zenoh_session import open_session
from service.keys import Keys
from tests.conftest import RunningService
from tests.service.helpers import declare_publisher, wait_until

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]


def test_summary_line() -> None:
    track = {"id": "T3", "position": [120.4, -40.0], "velocity": [3.0, 4.0]}
    report = {"seq": 42, "time": 41.0, "tracks": [track] * 7}
    assert summary_line(report, limit=2) == (
        "seq 42 t=41.0 s: 7 confirmed tracks: T3 (120, -40) 5.0 m/s, T3 (120, -40) 5.0 m/s, +5 more"
    )
    assert summary_line({"seq": 0, "time": None, "tracks": []}) == (
        "seq 0 t=- s: 0 confirmed tracks"
    )


def test_demo_publishes_after_the_latest_time_and_logs_summaries(
    service: RunningService, caplog: pytest.LogCaptureFixture
) -> None:
    session = open_session("peer", [service.endpoint])
    stop = threading.Event()
    try:
        # another sensor is ahead: the demo's first loop starts after its time
        pub = declare_publisher(session, "tracking/detections/other")
        pub.put(orjson.dumps({"sensor_id": "other", "time": 500.0, "detections": []}))
        wait_until(lambda: service.engine.seq == 1)
        demo = Demo(session, Keys(), stop=stop, speed=10.0, summary_interval=0.3)
        with caplog.at_level(logging.INFO, logger="clients.demo"):
            thread = threading.Thread(target=demo.run)
            thread.start()
            try:
                wait_until(lambda: service.engine.seq >= 12, timeout=20, what="demo batches")
                wait_until(
                    lambda: any("confirmed tracks: T" in r.getMessage() for r in caplog.records),
                    timeout=5,
                    what="a summary naming tracks",
                )
            finally:
                stop.set()
                thread.join(10)
        assert not thread.is_alive()
        wait_until(lambda: service.engine.seq == demo.published + 1, what="every batch tracked")
        stats = httpx.get(service.url + "/api/v1/stats").json()
        assert stats["batches_rejected"] == 0 and stats["batches_dropped"] == 0
        report = service.engine.latest_report()
        assert report["sensor_id"] == "radar-1" and report["time"] > 500.0
        assert len(report["tracks"]) >= 25
        demo.close()
    finally:
        session.close()


def test_demo_stops_when_its_parent_is_gone(service: RunningService) -> None:
    session = open_session("peer", [service.endpoint])
    try:
        demo = Demo(session, Keys(), stop=threading.Event(), parent=-1)
        t0 = time.monotonic()
        demo.run()
        assert time.monotonic() - t0 < 2.0 and demo.published == 0
        demo.close()
    finally:
        session.close()


def test_demo_process_stops_cleanly_on_sigterm(service: RunningService) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "clients.demo", "-e", service.endpoint, "--speed", "10"],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_until(lambda: service.engine.seq >= 3, timeout=20, what="demo batches")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=5)
        assert proc.returncode == 0, err
        assert "demo: publishing the continuous scenario to" in err
        assert "demo: stopped after" in err and "Traceback" not in err
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(5)
