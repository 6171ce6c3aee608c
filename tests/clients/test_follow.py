"""``tracker-follow`` over REST and Zenoh against the real service."""

from __future__ import annotations

import io
import threading

import httpx
import orjson
import pytest

from clients import follow
from clients.scenarios.multitarget import reference_scenario, simulate
from tests.conftest import RunningService, free_port, open_peer
from tests.service.helpers import declare_publisher, wait_until

pytestmark = pytest.mark.timeout(120)

SCANS = simulate(reference_scenario(9))


def _feed(service: RunningService, scans: list) -> None:  # type: ignore[type-arg]
    with httpx.Client(base_url=service.url) as http:
        for s in scans:
            assert http.post("/api/v1/detections", content=orjson.dumps(s.to_batch())).is_success


def test_follow_rest_once_json_and_table(service: RunningService) -> None:
    _feed(service, SCANS[:6])
    out = io.StringIO()
    assert follow.main(["--rest", service.url, "--json"], out=out) == 0
    lines = out.getvalue().splitlines()
    assert len(lines) == 1
    assert orjson.loads(lines[0]) == httpx.get(service.url + "/api/v1/tracks").json()

    out = io.StringIO()
    assert follow.main(["--rest", service.url, "--status", "all"], out=out) == 0
    text = out.getvalue()
    report = httpx.get(service.url + "/api/v1/tracks", params={"status": "all"}).json()
    assert text.startswith(f"seq 6  t={SCANS[5].time:.2f} s")
    assert "tentative" in text and "confirmed" in text
    for t in report["tracks"]:
        assert f"\n{t['id']:<8} " in text


def test_follow_zenoh_query(service: RunningService) -> None:
    _feed(service, SCANS[:5])
    out = io.StringIO()
    code = follow.main(["--zenoh", service.endpoint, "--query", "--json"], out=out)
    assert code == 0
    assert orjson.loads(out.getvalue()) == service.engine.latest_report()
    out = io.StringIO()
    code = follow.main(
        ["--zenoh", service.endpoint, "--query", "--json", "--status", "tentative"], out=out
    )
    assert code == 0
    tracks = orjson.loads(out.getvalue())["tracks"]
    assert tracks and all(t["status"] == "tentative" for t in tracks)


def test_follow_zenoh_subscription(service: RunningService) -> None:
    out = io.StringIO()
    result: list[int] = []
    t = threading.Thread(
        target=lambda: result.append(
            follow.main(
                ["--zenoh", service.endpoint, "--follow", "--json", "--count", "3"], out=out
            )
        )
    )
    t.start()
    session = open_peer(service.endpoint)
    try:
        # the service's track publisher matches once the follower has subscribed
        tracks_pub = service.app.state.runtime.zenoh._tracks_pub
        wait_until(lambda: tracks_pub.matching_status.matching, what="the follower")
        pub = declare_publisher(session, "tracking/detections/radar-1")
        for s in SCANS[:5]:
            pub.put(orjson.dumps(s.to_batch()))
        t.join(20)
        pub.undeclare()
    finally:
        session.close()
    assert result == [0]
    seqs = [orjson.loads(line)["seq"] for line in out.getvalue().splitlines()]
    assert seqs == [1, 2, 3]


def test_follow_rest_follow_mode_sees_new_reports(service: RunningService) -> None:
    _feed(service, SCANS[:2])
    out = io.StringIO()
    result: list[int] = []
    t = threading.Thread(
        target=lambda: result.append(
            follow.main(
                ["--rest", service.url, "--follow", "--json", "--count", "2", "--interval", "0.05"],
                out=out,
            )
        )
    )
    t.start()
    wait_until(lambda: out.getvalue().count("\n") >= 1)
    _feed(service, SCANS[2:3])
    t.join(10)
    assert result == [0]
    seqs = [orjson.loads(line)["seq"] for line in out.getvalue().splitlines()]
    assert seqs == [2, 3]


def test_follow_unreachable(capsys: pytest.CaptureFixture[str]) -> None:
    code = follow.main(["--rest", f"http://127.0.0.1:{free_port()}", "--timeout", "1"])
    assert code == 1
    assert "tracker-follow:" in capsys.readouterr().err
