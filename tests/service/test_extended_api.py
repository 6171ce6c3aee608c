"""Starting extended tracks by hand: ``POST /api/v1/tracks/extended`` against the real service,
and the engine's commands on its worker (:meth:`Engine.call_in_worker`) underneath it."""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import httpx
import numpy as np
import pytest

from service.engine import CommandRefused, Engine, EngineUnavailable
from tests.conftest import RunningService

from .helpers import ListSink, batch_payload, check_track, run_batches

pytestmark = pytest.mark.timeout(120)

URL = "/api/v1/tracks/extended"
MATRIX = [[400.0, 120.0], [120.0, 100.0]]


def _extended(http: httpx.Client) -> list[dict[str, Any]]:
    """Every live extended track, tentative too."""
    r = http.get("/api/v1/tracks", params={"kind": "extended", "status": "all"})
    assert r.status_code == 200
    tracks: list[dict[str, Any]] = r.json()["tracks"]
    return tracks


def _feed(service: RunningService, scans: list[Any], n: int) -> float:
    """Process the first ``n`` scans; the last one's time."""
    results = run_batches(service.engine, [batch_payload(s) for s in scans[:n]])
    assert all(r.accepted for r in results)
    return float(scans[n - 1].time)


def test_a_token_is_required(service: RunningService) -> None:
    body = {"position": [0, 0], "extent": {"matrix": MATRIX}, "time": 1.0}
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.post(URL, json=body)
        assert r.status_code == 401
        assert r.headers["www-authenticate"].startswith("Bearer")
        r = http.post(URL, json=body, headers={"Authorization": "Bearer wrong"})
        assert r.status_code == 401
        # the token is checked before the body is read
        assert http.post(URL, content=b"{", headers={"Authorization": "Basic x"}).status_code == 401
        assert _extended(http) == []


def test_start_with_either_form_then_list_and_get(
    service: RunningService, scans: list[Any]
) -> None:
    t = _feed(service, scans, 5)
    published = len(service.engine.report_state.report["tracks"])
    with httpx.Client(base_url=service.url, timeout=10) as http:
        before = {tr["id"] for tr in _extended(http)}
        seq = http.get("/api/v1/tracks").json()["seq"]

        r = http.post(
            URL,
            json={"position": [1500.0, -200.0], "velocity": [5, -1], "extent": {"matrix": MATRIX}},
            headers=service.auth,
        )
        assert r.status_code == 201, r.text
        a = r.json()
        check_track(a)
        assert a["kind"] == "extended" and a["status"] == "confirmed"
        assert a["time"] == t and a["created"] == t
        assert a["position"] == [1500.0, -200.0] and a["velocity"] == [5.0, -1.0]
        assert np.allclose(a["extent"]["matrix"], MATRIX)
        assert np.allclose(np.diag(a["covariance"]), [400, 400, 25, 25])

        r = http.post(
            URL,
            json={
                "position": [-3000, 800],
                "extent": {"semi_axes": [60.0, 15.0], "orientation": 0.5},
                "position_std": 10,
                "velocity_std": 2.5,
                "expected_detections": 6,
                "time": t + 0.5,
            },
            headers=service.auth,
        )
        assert r.status_code == 201, r.text
        b = r.json()
        check_track(b)
        assert b["time"] == t + 0.5 and b["velocity"] == [0.0, 0.0]
        assert np.allclose(b["extent"]["semi_axes"], [60.0, 15.0])
        assert math.isclose(b["extent"]["orientation"], 0.5, abs_tol=1e-9)
        assert np.allclose(np.diag(b["covariance"]), [100, 100, 6.25, 6.25])
        assert a["id"] != b["id"] and not {a["id"], b["id"]} & before

        # listed at once, in the same report (same seq), confirmed and with their extent
        listed = {tr["id"]: tr for tr in _extended(http)}
        assert listed[a["id"]] == a and listed[b["id"]] == b
        report = http.get("/api/v1/tracks", params={"kind": "extended"}).json()
        assert report["seq"] == seq and {a["id"], b["id"]} <= {tr["id"] for tr in report["tracks"]}
        full = http.get("/api/v1/tracks").json()
        assert full["seq"] == seq and a in full["tracks"] and b in full["tracks"]
        for track in (a, b):
            r = http.get(f"/api/v1/tracks/{track['id']}")
            assert r.status_code == 200 and r.json() == track
            assert "extent" in r.json()

    # not published over Zenoh until the next batch, whose report carries them
    sink_reports = service.engine.report_state.report
    assert sink_reports["seq"] == seq and len(sink_reports["tracks"]) == published + 2
    results = run_batches(service.engine, [batch_payload(scans[5])])
    assert results[0].accepted and results[0].seq == seq + 1
    ids = {tr["id"] for tr in service.engine.latest_report()["tracks"]}
    assert {a["id"], b["id"]} <= ids


def test_before_the_first_batch_time_is_needed(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        body: dict[str, Any] = {"position": [0, 0], "extent": {"semi_axes": [20, 10]}}
        r = http.post(URL, json=body, headers=service.auth)
        assert r.status_code == 422 and r.json()["detail"].startswith("time:")
        assert _extended(http) == []
        r = http.post(URL, json={**body, "time": 12.5}, headers=service.auth)
        assert r.status_code == 201, r.text
        track = r.json()
        assert track["time"] == 12.5 and track["extent"]["semi_axes"] == [20.0, 10.0]
        report = http.get("/api/v1/tracks").json()
        assert report["seq"] == 0 and report["time"] == 12.5 and report["tracks"] == [track]
        assert http.get(f"/api/v1/tracks/{track['id']}").json() == track


BAD: list[tuple[str, Any, str]] = [
    ("non-SPD matrix", {"extent": {"matrix": [[1, 2], [2, 1]]}}, "extent.matrix"),
    ("asymmetric matrix", {"extent": {"matrix": [[4, 1], [0, 4]]}}, "extent.matrix"),
    ("singular matrix", {"extent": {"matrix": [[4, 2], [2, 1]]}}, "extent.matrix"),
    (
        "both forms",
        {"extent": {"matrix": MATRIX, "semi_axes": [2, 1], "orientation": 0}},
        "extent: give exactly one form",
    ),
    ("neither form", {"extent": {}}, "extent: give exactly one form"),
    ("orientation only", {"extent": {"orientation": 0.2}}, "extent.semi_axes: missing"),
    ("no extent", {"extent": None}, "extent"),
    ("negative semi-axis", {"extent": {"semi_axes": [-2, 1]}}, "extent.semi_axes[0]"),
    ("huge semi-axis", {"extent": {"semi_axes": [2e5, 1]}}, "extent.semi_axes[0]"),
    ("unknown extent field", {"extent": {"semi_axes": [2, 1], "x": 1}}, "extent.x: unknown"),
    ("NaN", b'{"position": [NaN, 0], "extent": {"semi_axes": [2, 1]}}', "position[0]"),
    ("Infinity", b'{"position": [0, 0], "extent": {"semi_axes": [Infinity, 1]}}', "extent"),
    ("string number", {"position": ["1", 0]}, "position[0]: not a number"),
    ("boolean", {"velocity": [True, 0]}, "velocity[0]: not a number"),
    ("position too far", {"position": [2e9, 0]}, "position[0]"),
    ("one coordinate", {"position": [1]}, "position"),
    ("negative position_std", {"position_std": -1}, "position_std: must be > 0"),
    ("zero velocity_std", {"velocity_std": 0}, "velocity_std: must be > 0"),
    ("negative expected_detections", {"expected_detections": -3}, "expected_detections"),
    ("unknown field", {"colour": "red"}, "colour: unknown field"),
    ("not an object", [1, 2], "the body must be a JSON object"),
    ("not JSON", b"{oops", "invalid JSON"),
    ("time before the last batch", {"time": -1.0}, "time:"),
    ("time far ahead", {"time": 1e6}, "time:"),
    ("faster than max_speed", {"velocity": [5000.0, 0.0]}, "velocity: 5000 m/s is faster"),
]


@pytest.mark.parametrize(("case", "change", "named"), BAD, ids=[c for c, _, _ in BAD])
def test_bad_input_is_refused_and_changes_nothing(
    service: RunningService, scans: list[Any], case: str, change: Any, named: str
) -> None:
    _feed(service, scans, 3)
    good = {"position": [100.0, 50.0], "extent": {"semi_axes": [30.0, 10.0]}}
    with httpx.Client(base_url=service.url, timeout=10) as http:
        before = http.get("/api/v1/tracks", params={"status": "all"}).json()
        if isinstance(change, bytes):
            r = http.post(URL, content=change, headers=service.auth)
        elif isinstance(change, dict):
            r = http.post(URL, json={**good, **change}, headers=service.auth)
        else:
            r = http.post(URL, json=change, headers=service.auth)
        assert r.status_code == 422, (case, r.text)
        detail = r.json()["detail"]
        assert isinstance(detail, str) and detail.startswith(named), (case, detail)
        assert http.get("/api/v1/tracks", params={"status": "all"}).json() == before
        # the id that a refused request would have had is still free
        r = http.post(URL, json=good, headers=service.auth)
        assert r.status_code == 201
        assert r.json()["id"] == "E1"


def test_switched_off_is_a_conflict(service: RunningService, scans: list[Any]) -> None:
    _feed(service, scans, 2)
    body = {"position": [0, 0], "extent": {"matrix": MATRIX}}
    with httpx.Client(base_url=service.url, timeout=10) as http:
        off = {"extended": {"enabled": False}}
        assert http.patch("/api/v1/config", json=off, headers=service.auth).status_code == 200
        r = http.post(URL, json=body, headers=service.auth)
        assert r.status_code == 409 and "extended.enabled" in r.json()["detail"]
        assert _extended(http) == []
        on = {"extended": {"enabled": True}}
        assert http.patch("/api/v1/config", json=on, headers=service.auth).status_code == 200
        assert http.post(URL, json=body, headers=service.auth).status_code == 201


def test_other_methods_are_not_allowed(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.options(URL)
        assert r.status_code == 204 and r.headers["allow"] == "OPTIONS, POST"
        for method in ("GET", "PUT", "PATCH", "DELETE"):
            r = http.request(method, URL, headers=service.auth)
            assert r.status_code == 405, method
            assert r.headers["allow"] == "OPTIONS, POST"
        assert http.get("/api/v1/tracks/T1").status_code == 404  # ids still answer


def test_the_stopped_service_answers_503(service: RunningService) -> None:
    service.engine.stop()
    body = {"position": [0, 0], "extent": {"matrix": MATRIX}, "time": 1.0}
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.post(URL, json=body, headers=service.auth)
        assert r.status_code == 503 and "not running" in r.json()["detail"]


# -- the engine's commands ----------------------------------------------------------------


def test_a_command_on_an_idle_engine_completes(
    engine: Engine, caplog: pytest.LogCaptureFixture
) -> None:
    t0 = time.monotonic()
    assert engine.call_in_worker(lambda p: p.last_time, timeout=5.0) is None
    worker = engine.call_in_worker(lambda p: threading.current_thread().name)
    assert worker == "tracker-engine"
    with caplog.at_level("INFO", logger="service.engine"):
        track = engine.start_extended_track((0.0, 0.0), (1.0, 0.0), np.eye(2) * 100.0, at=3.0)
    assert track["id"] == "E1" and track["time"] == 3.0
    assert time.monotonic() - t0 < 2.0
    assert engine.track("E1") == track
    assert "extended track E1 started by hand at t=3.0: position (0.0, 0.0) m" in caplog.text
    with pytest.raises(CommandRefused, match="inside the extent of extended track 'E1'"):
        engine.start_extended_track((5.0, 0.0), (1.0, 0.0), np.eye(2) * 100.0, at=3.0)


def test_the_worker_goes_on_after_a_failed_command(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    run_batches(engine, [batch_payload(s) for s in scans[:3]])

    def boom(pipeline: Any) -> None:
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        engine.call_in_worker(boom)
    with pytest.raises(ValueError, match=r"extent\.matrix"):
        engine.start_extended_track((0.0, 0.0), (0.0, 0.0), [[1.0, 2.0], [2.0, 1.0]])
    results = run_batches(engine, [batch_payload(s) for s in scans[3:8]])
    assert [r.seq for r in results] == [4, 5, 6, 7, 8]
    assert [r["seq"] for r in sink.tracks] == list(range(1, 9))
    assert engine.stats.snapshot()["batches_rejected"] == 0
    assert engine.running


def test_commands_run_in_order_with_batches(
    engine: Engine, sink: ListSink, scans: list[Any]
) -> None:
    gate = threading.Event()
    seen: list[Any] = []
    blocker = threading.Thread(target=engine.call_in_worker, args=(lambda p: gate.wait(10),))
    blocker.start()
    time.sleep(0.1)  # the worker waits in the blocking command
    futures = [engine.submit(batch_payload(s), "radar-1", "test") for s in scans[:2]]
    reader = threading.Thread(
        target=lambda: seen.append(engine.call_in_worker(lambda p: p.last_time))
    )
    reader.start()
    time.sleep(0.1)
    gate.set()
    blocker.join(5)
    reader.join(5)
    assert all(f.result(5).accepted for f in futures)
    assert seen == [scans[1].time]  # after the batches queued before it
    assert engine._queued_bytes == 0  # commands take none of the queue's bytes


def test_a_full_queue_or_a_late_worker_refuses_and_the_command_never_runs(
    sink: ListSink,
) -> None:
    engine = Engine(sink=sink, queue_size=1)
    engine.start()
    try:
        gate = threading.Event()
        ran: list[str] = []
        blocker = threading.Thread(target=engine.call_in_worker, args=(lambda p: gate.wait(10),))
        blocker.start()
        time.sleep(0.1)  # the worker holds the blocking command; the queue is empty

        # queued, but not taken in time: withdrawn, never run
        with pytest.raises(EngineUnavailable, match="did not take"):
            engine.call_in_worker(lambda p: ran.append("late"), timeout=0.2)
        # the withdrawn command still holds the one slot until the worker takes it: full
        with pytest.raises(EngineUnavailable, match="stayed full"):
            engine.call_in_worker(lambda p: ran.append("full"), timeout=0.2)
        gate.set()
        blocker.join(5)

        def after(pipeline: Any) -> str:
            ran.append("after")
            return "ok"

        assert engine.call_in_worker(after) == "ok"
        assert ran == ["after"]
    finally:
        engine.stop()
    with pytest.raises(EngineUnavailable, match="not running"):
        engine.call_in_worker(lambda p: None)
