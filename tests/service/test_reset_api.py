"""Starting again: ``POST /api/v1/reset`` against the real service, and the engine's reset."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from service.engine import Engine
from service.state_store import StateStore
from tests.conftest import RunningService

from .helpers import ListSink, batch_payload, run_batches

pytestmark = pytest.mark.timeout(120)

URL = "/api/v1/reset"


def test_a_token_is_required_and_only_post_resets(service: RunningService) -> None:
    with httpx.Client(base_url=service.url, timeout=10) as http:
        assert http.post(URL).status_code == 401
        assert http.post(URL, headers={"Authorization": "Bearer wrong"}).status_code == 401
        for method in ("GET", "PUT", "PATCH", "DELETE"):
            assert http.request(method, URL, headers=service.auth).status_code == 405
        r = http.post(URL, headers=service.auth)  # before any batch: nothing to drop
        assert r.status_code == 200 and r.json() == {"reset": True, "seq": 0, "dropped": 0}


def test_a_recording_sent_again_after_a_reset_is_tracked_again(
    service: RunningService, scans: list[Any]
) -> None:
    """A newcomer's replay: the recording sent a second time was refused batch by batch
    (`out_of_sequence`, or as exact duplicates); after a reset it is taken as at first, with
    new ids (none of the dropped tracks' comes back) and the first report lists the dropped
    tracks as deleted."""
    payloads = [batch_payload(s) for s in scans[:20]]
    first = run_batches(service.engine, payloads)
    assert all(r.accepted for r in first)
    with httpx.Client(base_url=service.url, timeout=10) as http:
        before = http.get("/api/v1/tracks").json()
        confirmed = {t["id"] for t in before["tracks"]}
        assert len(confirmed) >= 20
        again = run_batches(service.engine, payloads[5:6])[0]
        assert not again.accepted  # a replay without a reset: refused
        r = http.post(URL, headers=service.auth)
        assert r.status_code == 200, r.text
        answer = r.json()
        assert answer["reset"] and answer["seq"] == 20 and answer["dropped"] >= len(confirmed)
        empty = http.get("/api/v1/tracks", params={"status": "all"}).json()
        assert empty["tracks"] == [] and empty["seq"] == 20
        assert sorted(empty["deleted"]) == sorted(confirmed)
        # the stats forget the time line too (a newcomer's trial saw the last time before)
        stats = http.get("/api/v1/stats").json()
        assert stats["last_time"] is None and stats["tracks_confirmed"] == 0
        second = run_batches(service.engine, payloads)
        assert all(r.accepted for r in second), [r for r in second if not r.accepted][:1]
        assert [r.seq for r in second] == list(range(21, 41))
        after = http.get("/api/v1/tracks").json()
    # the same detections give the same tracks as the first time, under new ids
    assert sorted(tuple(t["position"]) for t in after["tracks"]) == sorted(
        tuple(t["position"]) for t in before["tracks"]
    )
    assert not {t["id"] for t in after["tracks"]} & confirmed


def test_the_next_report_lists_the_dropped_tracks_as_deleted(
    sink: ListSink, scans: list[Any]
) -> None:
    engine = Engine(sink=sink)
    engine.start()
    try:
        run_batches(engine, [batch_payload(s) for s in scans[:15]])
        confirmed = {t["id"] for t in engine.latest_report()["tracks"]}
        assert confirmed
        assert engine.reset()["dropped"] >= len(confirmed)
        (result,) = run_batches(engine, [batch_payload(scans[0])])
        assert result.accepted and result.seq == 16
        report = sink.tracks[-1]
        assert report["seq"] == 16 and set(report["deleted"]) >= confirmed
        (result,) = run_batches(engine, [batch_payload(scans[1])])
        assert sink.tracks[-1]["deleted"] == []  # listed once
    finally:
        engine.stop()


def test_an_old_batch_is_told_about_the_reset(service: RunningService, scans: list[Any]) -> None:
    run_batches(service.engine, [batch_payload(s) for s in scans[:15]])
    with httpx.Client(base_url=service.url, timeout=10) as http:
        r = http.post(
            "/api/v1/detections",
            content=batch_payload(scans[0]),
            headers={"Content-Type": "application/json"},
        )
        assert r.status_code == 422
        detail = r.json()["detail"]
        assert "out_of_sequence" in str(r.json()) and "POST /api/v1/reset" in str(detail)


def test_a_reset_is_what_the_state_file_keeps(tmp_path: Path, scans: list[Any]) -> None:
    """With a state file, the reset's empty state is saved (under the same ``seq``, which a
    save would otherwise skip as saved already): a restart does not bring the tracks back."""
    path = tmp_path / "state.bin"
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        run_batches(engine, [batch_payload(s) for s in scans[:15]])
    finally:
        engine.stop()
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        assert engine.seq == 15 and engine.latest_report()["tracks"]
        engine.reset()
    finally:
        engine.stop()
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        assert engine.seq == 15 and engine.latest_report()["tracks"] == []
        (result,) = run_batches(engine, [batch_payload(scans[0])])
        assert result.accepted  # the time line was forgotten too
    finally:
        engine.stop()


def test_a_save_of_the_state_before_the_reset_does_not_undo_it(
    tmp_path: Path, scans: list[Any]
) -> None:
    """The saver reads the latest checkpoint, then saves it: a reset between the two under
    the same ``seq`` must still be saved afterwards (a review's case: before, the stale save
    marked that ``seq`` saved and the reset's empty state was never written)."""
    path = tmp_path / "state.bin"
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        run_batches(engine, [batch_payload(s) for s in scans[:12]])
        stale = engine._checkpoint
        engine.reset()
        assert engine._state_store is not None
        engine._state_store.save(stale)  # what a save that began before the reset writes
    finally:
        engine.stop()
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        assert engine.latest_report()["tracks"] == []
        assert run_batches(engine, [batch_payload(scans[0])])[0].accepted
    finally:
        engine.stop()
