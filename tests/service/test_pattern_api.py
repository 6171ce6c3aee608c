"""Point-pattern tracks over the public contract: the ``point_patterns`` configuration section
(patterns checked, 422 for bad ones, merged by name, a name's ``null`` removing it), paper
000's bending target fed as Detection batches and listed by ``GET /api/v1/tracks``, and
``POST /api/v1/tracks/pattern`` with its refusals."""

from __future__ import annotations

from typing import Any

import httpx
import orjson
import pytest
import zenoh

from clients.scenarios.bending import BendingRun, bending_scenario
from tests.conftest import RunningService

from .helpers import Collector, check_report, check_track, declare_publisher, run_batches

pytestmark = pytest.mark.timeout(120)

URL = "/api/v1/tracks/pattern"


def _patterns(run: BendingRun) -> dict[str, Any]:
    return {"five": run.patterns[0].tolist(), "four": run.patterns[1].tolist()}


def _configure_patterns(
    http: httpx.Client, service: RunningService, run: BendingRun
) -> httpx.Response:
    """PATCH the run's two patterns into the service's configuration; the 200 response."""
    r = http.patch(
        "/api/v1/config",
        json={"point_patterns": {"patterns": _patterns(run)}},
        headers=service.auth,
    )
    assert r.status_code == 200, r.text
    return r


def _batches(run: BendingRun) -> list[bytes]:
    out = []
    for sc in run.scans:
        dets = [
            {"x": float(x), "y": float(y), "cov": run.R.tolist(), "id": f"k{sc.k}d{i}"}
            for i, (x, y) in enumerate(sc.detections.tolist())
        ]
        out.append(
            orjson.dumps(
                {
                    "sensor_id": "radar-1",
                    "time": float(sc.time),
                    "detections": dets,
                    "pd": run.pd,
                    "clutter_density": run.clutter_density,
                }
            )
        )
    return out


def test_patterns_are_checked_merged_by_name_and_removed_by_null(service: RunningService) -> None:
    run = bending_scenario(0)
    with httpx.Client(base_url=service.url, timeout=10) as http:
        doc = http.get("/api/v1/config").json()
        assert doc["point_patterns"]["patterns"] == {}
        assert doc["point_patterns"]["filter"] == "lmm"
        bad = [
            ({"two": [[0, 0], [1, 1]]}, "two"),
            ({"line": [[0, 0], [1, 1], [2, 2]]}, "line"),
            ({"nan": [[0, 0], [1, "x"], [0, 1]]}, "nan"),
            ({"same": [[0, 0], [0, 0], [0, 1]]}, "same"),
            ({"": [[0, 0], [1, 0], [0, 1]]}, "patterns"),
            ({"far": [[0, 0], [1e9, 0], [0, 1]]}, "far"),
        ]
        for patterns, where in bad:
            r = http.patch(
                "/api/v1/config",
                json={"point_patterns": {"patterns": patterns}},
                headers=service.auth,
            )
            assert r.status_code == 422, (patterns, r.text)
            assert where in r.json()["detail"]
        assert http.get("/api/v1/config").json() == doc  # nothing changed
        r = _configure_patterns(http, service, run)
        assert set(r.json()["point_patterns"]["patterns"]) == {"five", "four"}
        tri = {"tri": [[0, 0], [10, 0], [0, 10]]}
        r = http.patch(
            "/api/v1/config",
            json={"point_patterns": {"patterns": {**tri, "four": None}}},
            headers=service.auth,
        )
        assert r.status_code == 200, r.text
        assert r.json()["point_patterns"]["patterns"] == {
            "five": run.patterns[0].tolist(),
            "tri": [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]],
        }


def test_the_bending_target_is_listed_with_attitude_and_shapes(service: RunningService) -> None:
    run = bending_scenario(1)
    with httpx.Client(base_url=service.url, timeout=10) as http:
        _configure_patterns(http, service, run)
        results = run_batches(service.engine, _batches(run))
        assert all(res.accepted for res in results)
        tracks = http.get("/api/v1/tracks", params={"kind": "extended"}).json()["tracks"]
        [track] = [t for t in tracks if "attitude" in t]
        check_track(track)
        truth = run.scans[-1].state
        assert abs(track["position"][0] - truth[0]) < 2 and abs(track["position"][1] - truth[2]) < 2
        assert set(track["shape_probabilities"]) == {"five", "four"}
        assert track["shape_probabilities"]["four"] > 0.9
        assert track["extent"]["semi_axes"][0] > 1.0
        individual = http.get("/api/v1/tracks", params={"kind": "individual"}).json()["tracks"]
        assert individual == []


def test_start_a_pattern_track_by_hand(service: RunningService) -> None:
    run = bending_scenario(2)
    body = {"pattern": "five", "position": [10.0, 20.0], "velocity": [1, 2], "attitude": 0.5}
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.post(URL, json={**body, "time": 0.0}).status_code == 401
        r = http.post(URL, json={**body, "time": 0.0}, headers=service.auth)
        assert r.status_code == 422 and "five" in r.json()["detail"]  # not configured yet
        _configure_patterns(http, service, run)
        for broken, where in (
            ({**body, "attitude": "x"}, "attitude"),
            ({**body, "position": [1.0]}, "position"),
            ({**body, "pattern": ""}, "pattern"),
            ({**body, "extra": 1}, "extra"),
            (body, "time"),  # before the first batch, a time is needed
        ):
            r = http.post(URL, json=broken, headers=service.auth)
            assert r.status_code == 422, (broken, r.text)
            assert where in r.json()["detail"]
        r = http.post(URL, json={**body, "time": 0.0}, headers=service.auth)
        assert r.status_code == 201, r.text
        track = r.json()
        check_track(track)
        assert track["kind"] == "extended" and track["status"] == "confirmed"
        assert track["position"] == [10.0, 20.0] and track["attitude"] == pytest.approx(0.5)
        assert track["shape_probabilities"]["five"] == pytest.approx(0.8)
        assert http.get(f"/api/v1/tracks/{track['id']}").status_code == 200
        http.patch(
            "/api/v1/config", json={"point_patterns": {"enabled": False}}, headers=service.auth
        )
        r = http.post(URL, json={**body, "time": 0.0}, headers=service.auth)
        assert r.status_code == 409
        assert http.get(URL).status_code == 405


def test_pattern_tracks_over_zenoh(service: RunningService, peer: zenoh.Session) -> None:
    """Detection batches published over Zenoh; the Track reports on ``tracking/tracks`` and
    the state queryable carry the pattern track with ``attitude`` and
    ``shape_probabilities``."""
    run = bending_scenario(3)
    with httpx.Client(base_url=service.url, timeout=10) as http:
        _configure_patterns(http, service, run)
    reports = Collector(peer, "tracking/tracks")
    errors = Collector(peer, "tracking/errors/**")
    try:
        pub = declare_publisher(peer, "tracking/detections/radar-1")
        for payload in _batches(run):
            pub.put(payload)
        pub.undeclare()
        got = reports.wait_for(len(run.scans), timeout=30)
        assert len(got) == len(run.scans)
        last = reports.json()[-1]
        check_report(last)
        [track] = [t for t in last["tracks"] if "attitude" in t]
        check_track(track)
        assert track["kind"] == "extended" and track["id"].startswith("B")
        assert track["shape_probabilities"]["four"] > 0.9
        truth = run.scans[-1].state
        assert abs(track["position"][0] - truth[0]) < 2 and abs(track["position"][1] - truth[2]) < 2
        [reply] = list(peer.get("tracking/state/tracks", timeout=5))
        assert reply.ok is not None
        assert orjson.loads(reply.ok.payload.to_bytes()) == last
        assert errors.items == []
    finally:
        reports.close()
        errors.close()
