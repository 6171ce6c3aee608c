"""Formations formed by hand: ``POST /api/v1/tracks/formation`` against the real service."""

from __future__ import annotations

import math
from typing import Any

import httpx
import pytest

from clients.scenarios.formation import environment_1, simulate_formations
from tests.conftest import RunningService

from .helpers import batch_payload, check_track, run_batches

pytestmark = pytest.mark.timeout(120)

URL = "/api/v1/tracks/formation"


def _feed(service: RunningService, sims: list[Any]) -> None:
    results = run_batches(service.engine, [batch_payload(s) for s in sims], key=None)
    assert all(r.accepted for r in results), [r for r in results if not r.accepted][:1]


def _confirmed_individual(http: httpx.Client) -> tuple[list[str], list[str]]:
    """The confirmed individual tracks near the first one (one formation's), and the others."""
    tracks = http.get("/api/v1/tracks", params={"kind": "individual"}).json()["tracks"]
    x0, y0 = tracks[0]["position"]
    near = [math.hypot(t["position"][0] - x0, t["position"][1] - y0) < 5000.0 for t in tracks]
    return (
        [t["id"] for t, n in zip(tracks, near, strict=True) if n],
        [t["id"] for t, n in zip(tracks, near, strict=True) if not n],
    )


def test_a_token_is_required_and_formations_are_off_by_default(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.post(URL, json={"members": ["T1", "T2"]}).status_code == 401
        r = http.post(URL, json={"members": ["T1", "T2"]}, headers=service.auth)
        assert r.status_code == 409 and "formation.enabled" in r.json()["detail"]
        assert http.get(URL).status_code == 405


def test_form_by_ids_then_members_carry_the_formation_id(service: RunningService) -> None:
    sims = simulate_formations(environment_1(seed=2, scans=12))
    with httpx.Client(base_url=service.url, timeout=10) as http:
        # on, but never forming one by itself, so that the request is what forms it
        patch = {"formation": {"enabled": True, "min_speed": 5000.0}}
        r = http.patch("/api/v1/config", json=patch, headers=service.auth)
        assert r.status_code == 200, r.text
        r = http.post(URL, json={"members": ["T1", "T2"]}, headers=service.auth)
        assert r.status_code == 422 and "before the first batch" in r.json()["detail"]
        _feed(service, sims[:30])
        ids, far = _confirmed_individual(http)
        assert len(ids) >= 3 and far
        for body, field in (
            ({}, "members"),
            ({"members": ["T1"]}, "members"),
            ({"members": "T1,T2"}, "members"),
            ({"members": [ids[0], ids[1]], "extra": 1}, "extra"),
            ({"members": [ids[0], "T999"]}, "T999"),
            ({"members": [ids[0], ids[0]]}, "twice"),
            ({"members": [ids[0], far[0]]}, "formation.max_spacing"),
        ):
            r = http.post(URL, json=body, headers=service.auth)
            assert r.status_code == 422 and field in r.json()["detail"], (body, r.text)
        assert http.post(URL, content=b"[", headers=service.auth).status_code == 422
        seq = http.get("/api/v1/tracks").json()["seq"]
        r = http.post(URL, json={"members": ids[:2]}, headers=service.auth)
        assert r.status_code == 201, r.text
        formation = r.json()
        check_track(formation)
        assert formation["kind"] == "formation" and formation["members"] == ids[:2]
        r = http.post(URL, json={"members": [ids[1], ids[2]]}, headers=service.auth)
        assert r.status_code == 422 and "already in formation" in r.json()["detail"]
        assert http.get("/api/v1/tracks").json()["seq"] == seq  # nothing processed
        _feed(service, sims[30:33])
        report = http.get("/api/v1/tracks").json()
        by_id = {t["id"]: t for t in report["tracks"]}
        assert by_id[formation["id"]]["members"] == ids[:2]
        for member in ids[:2]:
            assert by_id[member]["formation_id"] == formation["id"]
            assert by_id[member]["kind"] == "individual"
        r = http.get(f"/api/v1/tracks/{formation['id']}")
        assert r.status_code == 200 and r.json()["kind"] == "formation"
        kinds = http.get("/api/v1/tracks", params={"kind": "formation"}).json()["tracks"]
        assert [t["id"] for t in kinds] == [formation["id"]]
