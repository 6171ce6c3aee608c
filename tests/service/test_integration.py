"""The real service (uvicorn in this process, a real Zenoh peer on a loopback port) driven from
a second Zenoh session and over HTTP: tracks out over the subscriber, the queryable, the
liveliness token and REST; bad input; configuration; metrics."""

from __future__ import annotations

import json
import time
from typing import Any

import httpx
import numpy as np
import orjson
import pytest
import zenoh

from clients.scenarios.multitarget import reference_scenario, simulate
from clients.zenoh_session import open_session
from tests.conftest import RunningService, free_port

from .helpers import (
    Collector,
    check_report,
    check_track,
    declare_publisher,
    match_truth,
    parse_prometheus,
    wait_until,
)

pytestmark = pytest.mark.timeout(120)

SCANS = simulate(reference_scenario(7))


def _publish(peer: zenoh.Session, scans: list[Any], prefix: str = "tracking") -> None:
    pubs: dict[str, zenoh.Publisher] = {}
    for scan in scans:
        key = f"{prefix}/detections/{scan.sensor_id}"
        if key not in pubs:
            pubs[key] = declare_publisher(peer, key)
        pubs[key].put(orjson.dumps(scan.to_batch()))
    for pub in pubs.values():
        pub.undeclare()


def test_tracks_over_zenoh_queryable_liveliness_and_rest(
    service: RunningService, peer: zenoh.Session
) -> None:
    reports = Collector(peer, "tracking/tracks")
    errors = Collector(peer, "tracking/errors/**")
    try:
        n = 25
        _publish(peer, SCANS[:n])
        got = reports.wait_for(n, timeout=30)
        assert len(got) == n
        assert all(key == "tracking/tracks" for key, _ in got)
        published = reports.json()
        assert [r["seq"] for r in published] == list(range(1, n + 1))
        assert [r["time"] for r in published] == [s.time for s in SCANS[:n]]
        for rep in published:
            check_report(rep)
        last = published[-1]

        # the confirmed tracks are the targets
        truth = SCANS[n - 1].truth_states
        matched, errs = match_truth(last["tracks"], truth)
        assert matched >= 0.9 * len(truth), (matched, len(truth))
        assert len(last["tracks"]) <= len(truth) + 3
        assert np.median(errs) < 10.0

        # the queryable answers the latest report, filters by selector parameters
        replies = list(peer.get("tracking/state/tracks", timeout=5))
        assert len(replies) == 1 and replies[0].ok is not None
        assert str(replies[0].ok.key_expr) == "tracking/state/tracks"
        assert str(replies[0].ok.encoding).startswith("application/json")
        assert orjson.loads(replies[0].ok.payload.to_bytes()) == last
        replies = list(peer.get("tracking/state/tracks?status=all", timeout=5))
        assert replies[0].ok is not None
        every = orjson.loads(replies[0].ok.payload.to_bytes())
        assert len(every["tracks"]) > len(last["tracks"])
        replies = list(peer.get("tracking/state/tracks?status=bogus", timeout=5))
        assert len(replies) == 1 and replies[0].err is not None
        assert "status: one of confirmed, tentative, all" in replies[0].err.payload.to_string()
        replies = list(peer.get("tracking/state/tracks?kind=Extended", timeout=5))
        assert len(replies) == 1 and replies[0].err is not None
        assert "got 'Extended'" in replies[0].err.payload.to_string()
        assert {t["status"] for t in every["tracks"]} == {"confirmed", "tentative"}

        # the liveliness token
        alive = [r.ok for r in peer.liveliness().get("tracking/alive/**", timeout=5)]
        instance = service.app.state.settings.instance_id
        assert [str(s.key_expr) for s in alive if s is not None] == [f"tracking/alive/{instance}"]

        # REST: the same report, byte for byte when unfiltered
        with httpx.Client(base_url=service.url, timeout=10) as http:
            r = http.get("/api/v1/tracks")
            assert r.status_code == 200
            assert r.headers["content-type"] == "application/json"
            assert r.json() == last
            r = http.get("/api/v1/tracks", params={"status": "all"})
            assert r.json()["tracks"] == every["tracks"]
            for t in r.json()["tracks"]:
                check_track(t)
            r = http.get("/api/v1/tracks", params={"kind": "individual"})
            assert r.json()["tracks"] == last["tracks"]
            r = http.get("/api/v1/tracks", params={"kind": "formation,extended"})
            assert r.json()["tracks"] == [] and r.json()["seq"] == n
            tentative = [t for t in every["tracks"] if t["status"] == "tentative"]
            r = http.get("/api/v1/tracks", params={"status": "tentative"})
            assert r.json()["tracks"] == tentative
            assert http.get("/api/v1/tracks", params={"status": "bogus"}).status_code == 422
            r = http.get("/api/v1/tracks", params={"kind": "individual,bogus"})
            assert r.status_code == 422 and "got 'bogus'" in r.json()["detail"][0]["msg"]
            one = last["tracks"][0]
            assert http.get(f"/api/v1/tracks/{one['id']}").json() == one
            assert http.get(f"/api/v1/tracks/{tentative[0]['id']}").json() == tentative[0]
            r = http.get("/api/v1/tracks/T999999")
            assert r.status_code == 404
            stats = http.get("/api/v1/stats").json()
            assert stats["batches_received"] == n and stats["batches_processed"] == n
            assert stats["seq"] == n and stats["last_time"] == SCANS[n - 1].time
            assert stats["detections_processed"] == sum(s.z.shape[0] for s in SCANS[:n])
            assert stats["tracks_confirmed"] == len(last["tracks"])
            assert stats["processing_ms"]["p50"] > 0
        assert errors.items == []
    finally:
        reports.close()
        errors.close()


def _bad_inputs(t: float) -> list[tuple[str, str, bytes, str]]:
    """(reason, key's sensor id, payload, text in the detail)"""
    good = SCANS[0].to_batch()
    dets = good["detections"]
    nan = orjson.dumps({**good, "time": t}).replace(orjson.dumps(dets[3]["x"]), b"NaN", 1)
    return [
        ("invalid_json", "radar-1", b'{"sensor_id": "radar-1", ', "invalid JSON"),
        (
            "invalid_batch",
            "radar-1",
            orjson.dumps({"sensor_id": "radar-1", "time": t}),
            "detections: missing",
        ),
        ("invalid_batch", "radar-1", nan, "detections[3].x: not a finite number"),
        (
            "invalid_batch",
            "radar-1",
            orjson.dumps(
                {
                    **good,
                    "time": t,
                    "detections": [{"x": 1.0, "y": 2.0, "cov": [[1.0, 0.0], [0.0, -4.0]]}],
                }
            ),
            "detections[0].cov: not symmetric positive definite",
        ),
        (
            "invalid_batch",
            "radar-1",
            orjson.dumps({**good, "time": t, "extra": 1}),
            "extra: unknown field",
        ),
        ("sensor_mismatch", "radar-9", orjson.dumps({**good, "time": t}), "radar-9"),
        ("out_of_sequence", "radar-1", orjson.dumps({**good, "time": 0.0}), "older"),
    ]


def test_bad_input_over_zenoh_is_reported_and_changes_nothing(
    service: RunningService, peer: zenoh.Session
) -> None:
    errors = Collector(peer, "tracking/errors/**")
    reports = Collector(peer, "tracking/tracks")
    try:
        _publish(peer, SCANS[:8])
        reports.wait_for(8)
        t = SCANS[8].time
        bad = _bad_inputs(t)
        with httpx.Client(base_url=service.url, timeout=10) as http:
            before = http.get("/api/v1/tracks", params={"status": "all"}).content
            for i, (reason, key_sensor, payload, detail) in enumerate(bad, start=1):
                pub = declare_publisher(peer, f"tracking/detections/{key_sensor}")
                pub.put(payload)
                got = errors.wait_for(i)
                key, data = got[-1]
                assert key == f"tracking/errors/{key_sensor}"
                report = orjson.loads(data)
                assert set(report) == {"sensor_id", "time", "error", "detail", "received_bytes"}
                assert report["error"] == reason, report
                assert detail in report["detail"], report
                assert report["sensor_id"] == key_sensor
                assert report["received_bytes"] == len(payload)
                pub.undeclare()
                stats = http.get("/api/v1/stats").json()
                assert stats["rejected_by_reason"].get(reason, 0) >= 1
                assert http.get("/api/v1/tracks", params={"status": "all"}).content == before
            stats = http.get("/api/v1/stats").json()
            assert stats["batches_rejected"] == len(bad)
            assert stats["batches_processed"] == 8
            assert len(reports.items) == 8
            # still working: the next good batch is processed
            _publish(peer, SCANS[8:9])
            reports.wait_for(9)
            assert reports.json()[-1]["seq"] == 9
            metrics = parse_prometheus(http.get("/metrics").text)
            assert metrics['tracker_batches_rejected_total{reason="invalid_batch"}'] == 4
            assert metrics["tracker_batches_processed_total"] == 9
    finally:
        errors.close()
        reports.close()


def test_rest_ingest(service: RunningService, peer: zenoh.Session) -> None:
    errors = Collector(peer, "tracking/errors/**")
    try:
        with httpx.Client(base_url=service.url, timeout=10) as http:
            for i, scan in enumerate(SCANS[:4], start=1):
                r = http.post("/api/v1/detections", content=orjson.dumps(scan.to_batch()))
                assert r.status_code == 202, r.text
                assert r.json() == {"accepted": True, "seq": i}
            assert http.get("/api/v1/tracks").json()["seq"] == 4
            bad = {**SCANS[4].to_batch(), "pd": 2}
            r = http.post("/api/v1/detections", content=orjson.dumps(bad))
            assert r.status_code == 422
            assert r.json()["error"] == "invalid_batch"
            assert r.json()["detail"] == "pd: must be <= 1.0"
            r = http.post("/api/v1/detections", content=b"nope")
            assert r.status_code == 422 and r.json()["error"] == "invalid_json"
            old = SCANS[1].to_batch()
            r = http.post("/api/v1/detections", content=orjson.dumps(old))
            assert r.status_code == 422 and r.json()["error"] == "out_of_sequence"
            assert http.get("/api/v1/tracks").json()["seq"] == 4
            stats = http.get("/api/v1/stats").json()
            assert stats["batches_received"] == 7
            assert stats["rejected_by_reason"] == {
                "invalid_batch": 1,
                "invalid_json": 1,
                "out_of_sequence": 1,
            }
        got = errors.wait_for(3)
        assert [k for k, _ in got] == [
            "tracking/errors/radar-1",
            "tracking/errors/unknown",
            "tracking/errors/radar-1",
        ]
    finally:
        errors.close()


def test_rest_config(service: RunningService, peer: zenoh.Session) -> None:
    errors = Collector(peer, "tracking/errors/**")
    try:
        with httpx.Client(base_url=service.url, timeout=10) as http:
            doc = http.get("/api/v1/config").json()
            assert doc["ingest"] == {
                "max_detections_per_batch": 10000,
                "reorder_window": 0.0,
                "sensor_wait": 0.2,
                "max_time_jump": 10.0,
            }
            assert "track_management" in doc and "measurement" in doc
            # Targets of every speed start with the default configuration.
            assert doc["initiation"]["method"] == "two_point"
            assert doc["initiation"]["max_speed"] == 700.0
            assert doc["initiation"]["max_pairs_per_candidate"] == 8
            assert doc["gating"] == {
                "gate_probability": 0.9999,
                "manoeuvre_acceleration": 50.0,
                "manoeuvre_turn_rate": 0.1,
                "manoeuvre_speed_change": 3.0,
            }
            assert doc["motion"]["cv_turn_rate_std"] == 0.05
            patch = {"ingest": {"max_detections_per_batch": 10}}

            r = http.patch("/api/v1/config", json=patch)
            assert r.status_code == 401
            assert r.headers["www-authenticate"].startswith("Bearer")
            r = http.put("/api/v1/config", json=doc, headers={"Authorization": "Bearer wrong"})
            assert r.status_code == 401 and "www-authenticate" in r.headers
            r = http.patch("/api/v1/config", json=patch, headers={"Authorization": "Basic x"})
            assert r.status_code == 401

            for invalid in (
                {"track_management": {"pd": 0}},
                {"ingest": {"max_detections_per_batch": 0}},
                {"motion": {"models": ["cv", "xx"]}},
                {"nonsense": 1},
            ):
                r = http.patch("/api/v1/config", json=invalid, headers=service.auth)
                assert r.status_code == 422, invalid
                assert isinstance(r.json()["detail"], str)
                assert http.get("/api/v1/config").json() == doc
            r = http.patch("/api/v1/config", json=invalid, headers=service.auth)
            assert "nonsense" in r.json()["detail"]
            r = http.patch(
                "/api/v1/config", json={"track_management": {"pd": 2}}, headers=service.auth
            )
            assert r.json()["detail"].startswith("track_management.pd")
            r = http.put("/api/v1/config", content=b"{", headers=service.auth)
            assert r.status_code == 422
            assert "x-config-changed" not in r.headers

            # the answer is the document; its headers say what changed and where it was saved
            r = http.patch("/api/v1/config", json={"motion": {"q_cv": 1.0}}, headers=service.auth)
            assert r.status_code == 200 and r.json()["motion"]["q_cv"] == 1.0
            assert r.headers["x-config-changed"] == "motion.q_cv 0.5 -> 1.0"
            saved = service.engine.config_file
            assert saved is not None and r.headers["x-config-saved-to"] == str(saved)
            assert orjson.loads(saved.read_bytes()) == r.json()
            r = http.put("/api/v1/config", json=doc, headers=service.auth)
            assert r.json() == doc and r.headers["x-config-changed"] == "motion.q_cv 1.0 -> 0.5"
            r = http.patch("/api/v1/config", json={}, headers=service.auth)
            assert r.headers["x-config-changed"] == "none"

            # PATCH is effective on the next batch
            _publish(peer, SCANS[:2])
            wait_until(lambda: service.engine.seq == 2)
            r = http.patch("/api/v1/config", json=patch, headers=service.auth)
            assert r.status_code == 200
            assert r.json()["ingest"]["max_detections_per_batch"] == 10
            assert http.get("/api/v1/config").json() == r.json()
            _publish(peer, SCANS[2:3])
            err = orjson.loads(errors.wait_for(1)[0][1])
            assert err["error"] == "too_many_detections"
            assert service.engine.seq == 2

            r = http.patch(
                "/api/v1/config",
                json={
                    "measurement": {"position_std": 4.0},
                    "ingest": {"max_detections_per_batch": None},
                },
                headers=service.auth,
            )
            assert r.status_code == 200 and r.json()["ingest"]["max_detections_per_batch"] == 10000
            _publish(peer, SCANS[3:4])
            wait_until(lambda: service.engine.seq == 3)
            assert service.engine._pipeline.config.measurement.position_std == 4.0

            # PUT replaces the whole document
            r = http.put("/api/v1/config", json={}, headers=service.auth)
            assert r.status_code == 200 and r.json() == doc
    finally:
        errors.close()


def test_health_metrics_and_docs(service: RunningService, peer: zenoh.Session) -> None:
    _publish(peer, SCANS[:3])
    wait_until(lambda: service.engine.seq == 3)
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.get("/health").json() == {"status": "ok"}
        r = http.get("/metrics")
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/plain")
        samples = parse_prometheus(r.text)
        assert samples["tracker_batches_received_total"] == 3
        assert samples["tracker_batches_processed_total"] == 3
        assert samples["tracker_processing_seconds_count"] == 3
        assert samples['tracker_processing_seconds_bucket{le="+Inf"}'] == 3
        assert samples["tracker_processing_seconds_sum"] > 0
        assert samples["tracker_batch_detections_count"] == 3
        assert samples['tracker_tracks{status="confirmed"}'] >= 0
        spec = http.get("/openapi.json").json()
        for path in (
            "/health",
            "/api/v1/tracks",
            "/api/v1/tracks/{track_id}",
            "/api/v1/detections",
            "/api/v1/config",
            "/api/v1/stats",
            "/metrics",
        ):
            assert path in spec["paths"], path
        schemas = spec["components"]["schemas"]
        for name in (
            "DetectionBatchIn",
            "DetectionIn",
            "TrackOut",
            "ErrorReportOut",
            "ConfigDocument",
        ):
            assert name in schemas, name
        # The configuration document is typed down to each tracker field, from one tree.
        assert schemas["InitiationSection"]["properties"]["max_speed"]["default"] == 700.0
        assert schemas["ConfigDocument"]["additionalProperties"] is False
        assert "sensor_velocity" in schemas["DetectionBatchIn"]["properties"]
        assert json.dumps(spec).count("#/components/schemas/") > 5
        assert http.get("/docs").status_code == 200


def test_empty_service_answers(service: RunningService, peer: zenoh.Session) -> None:
    replies = list(peer.get("tracking/state/tracks", timeout=5))
    assert replies[0].ok is not None
    empty = orjson.loads(replies[0].ok.payload.to_bytes())
    assert empty == {
        "seq": 0,
        "time": None,
        "sensor_id": None,
        "processing_ms": 0.0,
        "tracks": [],
        "deleted": [],
    }
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.get("/api/v1/tracks").json() == empty
        assert http.get("/api/v1/tracks", params={"status": "all"}).json() == empty


def test_custom_prefix_and_reorder_window(service_factory: Any) -> None:
    svc = service_factory(key_prefix="site/a", reorder_window=5.0)
    from tests.conftest import open_peer

    session = open_peer(svc.endpoint)
    try:
        reports = Collector(session, "site/a/tracks")
        order = [0, 1, 3, 2, 4, 6, 5, 7, 8, 9, 10, 11, 12]
        _publish(session, [SCANS[i] for i in order], prefix="site/a")
        got = reports.wait_for(len(order) - 5, timeout=10)
        times = [orjson.loads(p)["time"] for _, p in got]
        assert times == sorted(times) and len(set(times)) == len(times)
        with httpx.Client(base_url=svc.url, timeout=10) as http:
            assert http.get("/api/v1/config").json()["ingest"]["reorder_window"] == 5.0
            stats = http.get("/api/v1/stats").json()
            assert stats["batches_rejected"] == 0
            assert stats["held_for_reorder"] >= 1
        reports.close()
    finally:
        session.close()


def test_rest_answers_a_held_batch_at_once(service_factory: Any) -> None:
    """With a reorder window, a batch held back is answered 202 with seq null at once, not
    after the window; a batch that is processed gets its seq."""
    svc = service_factory(reorder_window=60.0)
    with httpx.Client(base_url=svc.url, timeout=10) as http:
        t0 = time.monotonic()
        r = http.post("/api/v1/detections", content=orjson.dumps(SCANS[0].to_batch()))
        assert r.status_code == 202 and r.json() == {"accepted": True, "seq": None}
        assert time.monotonic() - t0 < 5.0
        # a batch 60 s newer releases the first one
        late = {**SCANS[1].to_batch(), "time": SCANS[0].time + 61.0}
        r = http.post("/api/v1/detections", content=orjson.dumps(late))
        assert r.status_code == 202
        wait_until(lambda: svc.engine.seq == 1)


def _round_trip(session: zenoh.Session, n: int = 5) -> None:
    """Publish ``n`` scans from ``session`` and read their reports back on it."""
    reports = Collector(session, "tracking/tracks")
    try:
        _publish(session, SCANS[:n])
        got = reports.wait_for(n, timeout=20)
        assert [orjson.loads(p)["seq"] for _, p in got] == list(range(1, n + 1))
        replies = list(session.get("tracking/state/tracks", timeout=5))
        assert len(replies) == 1 and replies[0].ok is not None
        assert orjson.loads(replies[0].ok.payload.to_bytes())["seq"] == n
    finally:
        reports.close()


def test_service_as_a_router_serves_zenoh_clients(service_factory: Any) -> None:
    svc = service_factory(zenoh_mode="router")
    client = open_session("client", connect=[svc.endpoint])
    try:
        _round_trip(client)
    finally:
        client.close()


def test_service_as_a_client_of_a_router(service_factory: Any) -> None:
    """The service and a sensor are both clients of a router; nothing connects them directly."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = open_session("router", connect=[], listen=[endpoint])
    try:
        service_factory(zenoh_mode="client", zenoh_connect=endpoint, zenoh_listen="none")
        sensor = open_session("client", connect=[endpoint])
        try:
            _round_trip(sensor)
        finally:
            sensor.close()
    finally:
        router.close()


def _counters_agree(stats: dict[str, Any]) -> None:
    assert stats["batches_received"] == (
        stats["batches_processed"] + stats["batches_rejected"] + stats["batches_dropped"]
    ), stats


def test_hostile_input_over_zenoh(service_factory: Any) -> None:
    """A key with an extra chunk, a time of 400 digits, the same batch twice, a payload over
    max_batch_bytes, one over the transport's largest message: one Error report each where
    one can be made, no track changed, and the counters agree."""
    from tests.conftest import open_peer

    svc = service_factory(max_batch_bytes=65536, zenoh_max_message_bytes=131072)
    peer = open_peer(svc.endpoint)
    errors = Collector(peer, "tracking/errors/**")
    reports = Collector(peer, "tracking/tracks")
    try:
        _publish(peer, SCANS[:4])
        reports.wait_for(4)
        good = SCANS[4].to_batch()
        with httpx.Client(base_url=svc.url, timeout=10) as http:
            before = http.get("/api/v1/tracks", params={"status": "all"}).content
            huge = b"1" + b"0" * 399
            cases: list[tuple[str, bytes, str, str]] = [
                ("tracking/detections/x/radar-1", orjson.dumps(good), "unknown", "invalid_key"),
                ("tracking/detections/radar@1", orjson.dumps(good), "unknown", "invalid_key"),
                (
                    "tracking/detections/radar-1",
                    orjson.dumps(good).replace(b'"time":4.0', b'"time":' + huge, 1),
                    "radar-1",
                    "invalid_batch",
                ),
                (
                    "tracking/detections/radar-1",
                    orjson.dumps(SCANS[3].to_batch()),  # processed already
                    "radar-1",
                    "duplicate_batch",
                ),
                (
                    "tracking/detections/radar-1",
                    orjson.dumps({**good, "detections": good["detections"] * 15}),
                    "radar-1",
                    "batch_too_large",
                ),
            ]
            assert 65536 < len(cases[-1][1]) <= 131072
            for i, (key, payload, sensor, reason) in enumerate(cases, start=1):
                pub = declare_publisher(peer, key)
                pub.put(payload)
                got = errors.wait_for(i)
                assert got[-1][0] == f"tracking/errors/{sensor}"
                report = orjson.loads(got[-1][1])
                assert (report["error"], report["sensor_id"]) == (reason, sensor), report
                assert report["received_bytes"] == len(payload)
                pub.undeclare()
            assert "tracking/detections/{sensor_id}" in orjson.loads(errors.items[0][1])["detail"]
            assert orjson.loads(errors.items[2][1])["detail"] == "time: not a finite number"
            assert orjson.loads(errors.items[4][1])["time"] is None  # not read
            # over the transport's largest message: Zenoh drops it as it arrives, unreported
            pub = declare_publisher(peer, "tracking/detections/radar-1")
            dropped = orjson.dumps({**good, "detections": good["detections"] * 60})
            assert len(dropped) > 131072
            pub.put(dropped)
            pub.undeclare()
            assert http.get("/api/v1/tracks", params={"status": "all"}).content == before
            _publish(peer, SCANS[4:5])
            assert orjson.loads(reports.wait_for(5)[-1][1])["seq"] == 5
            assert len(reports.items) == 5 and len(errors.items) == len(cases)
            stats = http.get("/api/v1/stats").json()
            assert stats["batches_received"] == 5 + len(cases)
            assert stats["rejected_by_reason"] == {
                "invalid_key": 2,
                "invalid_batch": 1,
                "duplicate_batch": 1,
                "batch_too_large": 1,
            }
            _counters_agree(stats)
    finally:
        errors.close()
        reports.close()
        peer.close()


def test_hostile_input_over_rest(service_factory: Any) -> None:
    svc = service_factory(max_batch_bytes=65536)
    with httpx.Client(base_url=svc.url, timeout=10) as http:
        for scan in SCANS[:3]:
            assert http.post("/api/v1/detections", content=orjson.dumps(scan.to_batch())).is_success
        good = orjson.dumps(SCANS[3].to_batch())
        huge = b'"time":1' + b"0" * 399
        cases = [
            (good.replace(b'"time":3.0', huge, 1), "invalid_batch", "time: not a finite number"),
            (
                good.replace(b'"pd":', b'"pd":0.5,"pd":', 1),
                "invalid_batch",
                "duplicate key 'pd' in one object (a JSON parser keeps only the last)",
            ),
            (orjson.dumps(SCANS[1].to_batch()), "out_of_sequence", "older"),
            (
                b"[" + good * 20 + b"]",
                "batch_too_large",
                f"payload: {len(good) * 20 + 2} bytes, more than max_batch_bytes = 65536",
            ),
        ]
        for payload, reason, detail in cases:
            r = http.post("/api/v1/detections", content=payload)
            assert r.status_code == 422, r.text
            assert (r.json()["error"], r.json()["received_bytes"]) == (reason, len(payload))
            assert detail in r.json()["detail"]
        assert http.post("/api/v1/detections", content=good).status_code == 202
        r = http.post("/api/v1/detections", content=good)
        assert r.status_code == 422 and r.json()["error"] == "duplicate_batch"
        stats = http.get("/api/v1/stats").json()
        assert stats["batches_processed"] == 4 and stats["batches_rejected"] == len(cases) + 1
        _counters_agree(stats)


def test_health_answers_while_a_large_batch_is_validated(service: RunningService) -> None:
    """The batch is read and validated off the event loop (it took /health 5.7 s to answer
    behind an 18 MB batch checked inside the handler)."""
    import threading
    import time

    dets = [
        {"x": float(i), "y": -float(i), "cov": [[25.5, 0.5], [0.5, 25.5]], "id": f"d-{i:06d}"}
        for i in range(10_000)
    ]
    dets[-1]["cov"] = [[1.0, 2.0], [2.0, 1.0]]  # found last: the whole batch is validated
    payload = orjson.dumps({"sensor_id": "big-1", "time": 1.0, "detections": dets})
    latencies: list[float] = []
    answers: list[httpx.Response] = []

    def post() -> None:
        with httpx.Client(base_url=service.url, timeout=30) as http:
            for _ in range(3):
                answers.append(http.post("/api/v1/detections", content=payload))

    with httpx.Client(base_url=service.url, timeout=10) as http:
        sender = threading.Thread(target=post)
        sender.start()
        while sender.is_alive():
            t0 = time.perf_counter()
            assert http.get("/health").status_code == 200
            latencies.append(time.perf_counter() - t0)
            time.sleep(0.005)
        sender.join()
    assert [r.status_code for r in answers] == [422] * 3
    assert answers[0].json()["detail"] == "detections[9999].cov: not symmetric positive definite"
    assert len(latencies) >= 3 and max(latencies) < 1.0, max(latencies)
