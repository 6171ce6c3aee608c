"""The live view: its files, the server-sent events stream that feeds it, and that a viewer,
however slow, costs the tracker nothing but a slot write; and ``/docs`` served offline."""

from __future__ import annotations

import asyncio
import re
import socket
import time
from typing import Any
from urllib.parse import urlsplit

import httpx
import numpy as np
import orjson
import pytest

from clients.scenarios.multitarget import ScenarioConfig, reference_scenario, simulate
from service.main import view_url
from service.reports import ReportState
from service.viewers import Frame, ViewerHub
from tests.conftest import RunningService

from .helpers import batch_payload, parse_prometheus, run_batches, wait_until

SCANS = simulate(reference_scenario(5))[:20]


def _read_event(lines: Any) -> dict[str, Any]:
    """The next ``report`` event of an SSE line iterator, decoded."""
    event: dict[str, str] = {}
    for line in lines:
        if line == "":
            if event.get("event") == "report":
                frame: dict[str, Any] = orjson.loads(event["data"])
                frame["_id"] = event.get("id")
                return frame
            event = {}
        elif not line.startswith(":"):
            field, _, value = line.partition(":")
            event[field] = value.removeprefix(" ")
    raise AssertionError("the stream ended")


def _metrics(http: httpx.Client) -> dict[str, float]:
    return parse_prometheus(http.get("/metrics").text)


def test_root_redirects_to_view(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.get("/")
        assert r.status_code in (302, 307) and r.headers["location"] == "/view"
        assert http.get("/", follow_redirects=True).url.path == "/view"


def test_view_files_are_served(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        page = http.get("/view")
        assert page.status_code == 200
        assert page.headers["content-type"].startswith("text/html")
        html = page.text
        for element in ('id="plan"', 'id="track-list"', 'id="details"'):
            assert element in html
        assert not re.search(r"https?://", html)  # no CDN: everything from the service
        refs = re.findall(r'(?:src|href)="([^"]+)"', html)
        assert "/view/assets/view.js" in refs and "/view/assets/view.css" in refs
        types = {"js": "javascript", "css": "text/css"}
        for ref in refs:
            r = http.get(ref)
            assert r.status_code == 200, ref
            ext = ref.rsplit(".", 1)[-1]
            if ext in types:
                assert types[ext] in r.headers["content-type"], ref
        js = http.get("/view/assets/view.js").text
        assert "/api/v1/stream" in js and "window.viewState" in js
        assert http.get("/view/assets/missing.js").status_code == 404


def test_view_draws_extended_tracks(service: RunningService) -> None:
    """The view has a drawing code path for extended tracks: their extent ellipse (turned
    for the canvas's downward y axis), picking inside it, their details and a legend key."""
    with httpx.Client(base_url=service.url, timeout=10) as http:
        js = http.get("/view/assets/view.js").text
        html = http.get("/view").text
    kinds = re.search(r"const DRAW_KIND = \{([^}]*)\}", js)
    assert kinds is not None and "extended: drawExtended" in kinds.group(1)
    assert "function drawExtended(" in js and "ctx.ellipse(" in js
    assert "rotation: -axes.angle" in js  # world angles are counter-clockwise, north up
    assert "semi_axes" in js and "orientation" in js and "detection_ids" in js
    assert "insideEllipse(" in js  # a click inside the ellipse selects the track
    assert 'data-kind="extended"' in html  # the legend


def test_stream_delivers_a_frame_per_processed_batch(service: RunningService) -> None:
    engine = service.engine
    with (
        httpx.Client(base_url=service.url, timeout=10) as http,
        http.stream("GET", "/api/v1/stream") as stream,
    ):
        assert stream.status_code == 200
        assert stream.headers["content-type"].startswith("text/event-stream")
        lines = stream.iter_lines()
        first = _read_event(lines)  # the state when the viewer connects
        assert first["report"]["seq"] == 0 and first["report"]["tracks"] == []
        assert first["detections"] == [] and first["_id"] == "0"
        wait_until(lambda: len(engine.view) == 1, what="the viewer is connected")
        assert _metrics(http)["tracker_view_viewers"] == 1

        results = run_batches(engine, [batch_payload(s) for s in SCANS[:1]], key=None)
        assert results[0].accepted
        frame = _read_event(lines)
        assert frame["report"] == orjson.loads(engine.latest_report_bytes())
        assert frame["report"]["seq"] == 1 and frame["_id"] == "1"
        assert np.allclose(np.reshape(frame["detections"], (-1, 2)), SCANS[0].z)
        # every live track is in the frame: the report's confirmed ones and the tentative ones
        everything = engine.tracks("all")["tracks"]
        assert len(frame["report"]["tracks"]) + len(frame["tentative"]) == len(everything)
        assert all(t["status"] == "tentative" for t in frame["tentative"])

        run_batches(engine, [batch_payload(s) for s in SCANS[1:12]], key=None)
        wait_until(lambda: engine.seq == 12)
        seqs = []
        while not seqs or seqs[-1] < 12:  # the newest frame comes; older ones may be dropped
            seqs.append(_read_event(lines)["report"]["seq"])
        assert seqs == sorted(seqs) and seqs[-1] == 12
        dropped = _metrics(http)["tracker_view_frames_dropped_total"]
        assert dropped == 11 - len(seqs)  # frames 2 to 12: those not sent were dropped
        assert http.get("/api/v1/stats").json()["view_frames_dropped"] == dropped
    wait_until(lambda: len(engine.view) == 0, what="the viewer is gone")
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.get("/api/v1/stats").json()["viewers"] == 0


def test_a_viewer_that_never_reads_blocks_nothing(service: RunningService) -> None:
    engine = service.engine
    scans = simulate(ScenarioConfig(n_targets=10, n_scans=500, seed=3))
    payloads = [batch_payload(s) for s in scans]
    host, port = urlsplit(service.url).hostname, urlsplit(service.url).port
    assert host is not None and port is not None
    with socket.create_connection((host, port)) as viewer:  # connects, then never reads
        viewer.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        viewer.sendall(f"GET /api/v1/stream HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
        wait_until(lambda: len(engine.view) == 1, what="the viewer is connected")
        t0 = time.perf_counter()
        results = run_batches(engine, payloads, key=None)
        elapsed = time.perf_counter() - t0
        assert all(r.accepted for r in results)
        assert engine.seq == 500
        # the slow viewer held the tracker up by nothing: 500 batches of 10 targets, well
        # under the 2 s the ingest queue would block a sender for
        assert elapsed < 30
        stats = engine.stats.snapshot()
        assert stats["viewers"] == 1
        assert stats["view_frames_dropped"] >= 400  # replaced while it did not read
        (slot,) = engine.view._viewers
        assert slot.dropped == stats["view_frames_dropped"]
        assert slot._frame is None or slot._frame.seq <= 500  # one frame held at most
        with httpx.Client(base_url=service.url, timeout=5) as http:  # REST answers meanwhile
            assert http.get("/api/v1/tracks").json()["seq"] == 500
    wait_until(lambda: len(engine.view) == 0, timeout=20, what="the vanished viewer is gone")


def test_hub_keeps_one_frame_per_viewer() -> None:
    drops: list[int] = []

    async def scenario() -> None:
        hub = ViewerHub(on_drop=lambda: drops.append(1))
        state = ReportState.empty()
        hub.publish(state)  # no viewer: only remembered as the latest
        assert hub.latest is not None and len(hub) == 0
        slow = hub.connect(asyncio.get_running_loop())  # starts from the latest frame
        fast = hub.connect(asyncio.get_running_loop())
        assert (await fast.next(1.0)) is hub.latest
        for _ in range(1000):
            hub.publish(state, np.zeros((3, 2)))
            assert fast.take() is hub.latest
        assert slow.dropped == 1000 and fast.dropped == 0 and len(drops) == 1000
        frame = await slow.next(1.0)
        assert frame is hub.latest and slow.take() is None
        assert frame is not None and orjson.loads(frame.data)["detections"] == [0.0] * 6
        assert (await slow.next(0.05)) is None  # nothing new: the wait times out
        waiter = asyncio.create_task(slow.next(5.0))
        await asyncio.sleep(0.01)
        hub.publish(state)  # from another thread in the service; wakes the waiting viewer
        assert (await asyncio.wait_for(waiter, 1.0)) is hub.latest
        hub.disconnect(fast)
        assert len(hub) == 1 and fast.closed
        hub.close()
        assert slow.closed and (await slow.next(5.0)) is None
        assert hub.connect(asyncio.get_running_loop()).closed  # none after close

    asyncio.run(scenario())


def test_frame_data_is_built_once() -> None:
    frame = Frame(ReportState.empty(), np.array([[1.0, 2.0], [3.0, 4.0]]))
    data = frame.data
    assert frame.data is data
    decoded = orjson.loads(data)
    assert decoded == {
        "report": orjson.loads(ReportState.empty().data),
        "tentative": [],
        "detections": [1.0, 2.0, 3.0, 4.0],
    }


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_docs_work_offline(service: RunningService, path: str) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.get(path)
        assert r.status_code == 200
        html = r.text
        external = [u for u in re.findall(r"https?://[^\s\"'<>)]+", html)]
        assert external == []
        refs = re.findall(r'(?:src|href|spec-url)="([^"]+)"', html)
        refs += re.findall(r"url: '([^']+)'", html)
        assert any(ref.endswith(".js") for ref in refs)
        assert "/openapi.json" in refs
        for ref in refs:
            assert ref.startswith("/"), ref
            assert http.get(ref).status_code == 200, ref
        if path == "/docs":
            assert http.get("/docs/oauth2-redirect").status_code == 200
            assert "/docs" not in http.get("/openapi.json").json()["paths"]


def test_view_url() -> None:
    assert view_url("127.0.0.1", 8000) == "http://127.0.0.1:8000/view"
    assert view_url("0.0.0.0", 8080) == "http://127.0.0.1:8080/view"
    assert view_url("::", 8000) == "http://[::1]:8000/view"
    assert view_url("tracker.local", 80) == "http://tracker.local:80/view"
