"""``python -m service`` restarted with its state file: after SIGTERM and after kill -9 (from
the periodic save) the same tracks come back under the same ids, new ids go on from the
saved counter, and what crashed saves left behind is removed at start."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.engine import Engine
from trackers.state import decode_state

from .helpers import ListSink, batch_payload, run_batches, wait_until
from .test_subprocess import ServiceProcess, _start, processes

__all__ = ["processes"]  # the fixture, used by the tests below

pytestmark = pytest.mark.timeout(120)

JSON = {"Content-Type": "application/json"}


@pytest.fixture(scope="module")
def payloads(scans: list[Any]) -> list[bytes]:
    return [batch_payload(s) for s in scans]


def _post_all(svc: ServiceProcess, payloads: list[bytes]) -> list[int]:
    seqs = []
    with httpx.Client(base_url=svc.url, timeout=10) as http:
        for p in payloads:
            r = http.post("/api/v1/detections", content=p, headers=JSON)
            assert r.status_code == 202, r.text
            seqs.append(r.json()["seq"])
    return seqs


def _tracks(svc: ServiceProcess, status: str = "confirmed") -> dict[str, Any]:
    r = httpx.get(svc.url + "/api/v1/tracks", params={"status": status}, timeout=5)
    assert r.status_code == 200
    return dict(r.json())


def _without_timing(report: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in report.items() if k not in ("processing_ms", "deleted")}


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_sigterm_then_restart_keeps_the_tracks_and_their_ids(
    processes: list[ServiceProcess], tmp_path: Path, payloads: list[bytes]
) -> None:
    conf, state = tmp_path / "tracker.json", tmp_path / "state.npz"
    files = ("--api-token", "t", "--config-file", str(conf), "--state-file", str(state))
    svc = _start(processes, *files)
    assert _post_all(svc, payloads[:40]) == list(range(1, 41))
    before, before_all = _tracks(svc), _tracks(svc, "all")
    assert len(before["tracks"]) >= 40
    code, _, _, err = svc.terminate()
    assert code == 0 and "Traceback" not in err, err
    assert os.listdir(tmp_path) == ["state.npz"]

    # what kill -9 during saves would have left: zero-byte temporary files of both files
    dead = _dead_pid()
    debris = [
        tmp_path / f".state.npz.{dead}-a1b2.tmp",
        tmp_path / f".tracker.json.{dead}-c3d4.tmp",
        tmp_path / ".tracker.json.x7y8z9.tmp",
    ]
    for p in debris:
        p.write_bytes(b"")
    again = _start(processes, *files)
    assert os.listdir(tmp_path) == ["state.npz"]  # the debris is gone
    assert _without_timing(_tracks(again)) == _without_timing(before)  # seq 40, same tracks
    assert _tracks(again, "all")["tracks"] == before_all["tracks"]
    assert _post_all(again, payloads[40:70]) == list(range(41, 71))
    after_all = _tracks(again, "all")
    code, _, _, err = again.terminate()
    assert code == 0, err
    assert "tracker state restored from" in err and "report seq 40" in err
    for p in debris:
        assert f"removed {p}" in err

    # exactly what a service that never stopped has after the same 70 batches
    straight = Engine(sink=ListSink())
    straight.start()
    try:
        run_batches(straight, payloads[:70], key=None)
        assert after_all["tracks"] == straight.tracks("all")["tracks"]
    finally:
        straight.stop()
    top = max(int(t["id"][1:]) for t in before_all["tracks"])
    new = {t["id"] for t in after_all["tracks"]} - {t["id"] for t in before_all["tracks"]}
    assert new and min(int(i[1:]) for i in new) > top


def test_kill_9_then_restart_restores_the_periodic_save(
    processes: list[ServiceProcess], tmp_path: Path, payloads: list[bytes]
) -> None:
    state = tmp_path / "state.npz"
    args = ("--api-token", "t", "--state-file", str(state), "--state-save-interval", "0.2")
    svc = _start(processes, *args)
    _post_all(svc, payloads[:30])
    report = _tracks(svc)

    def saved_seq() -> int:
        try:
            return int(decode_state(state.read_bytes())[1]["seq"])
        except FileNotFoundError:
            return -1

    wait_until(lambda: saved_seq() == 30, timeout=10, what="the periodic save of seq 30")
    svc.kill()  # SIGKILL: no shutdown, no final save
    assert svc.proc.returncode == -9

    again = _start(processes, *args)
    assert _without_timing(_tracks(again)) == _without_timing(report)
    assert _post_all(again, payloads[30:32]) == [31, 32]
    code, _, _, err = again.terminate()
    assert code == 0, err


def test_an_extended_track_survives_a_restart(
    processes: list[ServiceProcess], tmp_path: Path, payloads: list[bytes]
) -> None:
    """An extended track started by hand, tracked through a few batches, comes back after
    SIGTERM under its id with its extent, and the next one started takes the next id."""
    files = ("--api-token", "t", "--state-file", str(tmp_path / "state.npz"))
    auth = {"Authorization": "Bearer t"}
    svc = _start(processes, *files)
    _post_all(svc, payloads[:5])
    body = {
        "position": [5000.0, 5000.0],
        "extent": {"semi_axes": [200.0, 50.0], "orientation": 0.3},
    }
    with httpx.Client(base_url=svc.url, timeout=10) as http:
        r = http.post("/api/v1/tracks/extended", json=body, headers=auth)
        assert r.status_code == 201, r.text
        started = r.json()
    _post_all(svc, payloads[5:8])
    params = {"kind": "extended", "status": "all"}
    before = httpx.get(svc.url + "/api/v1/tracks", params=params, timeout=5).json()["tracks"]
    assert [t["id"] for t in before] == [started["id"]]
    assert svc.terminate()[0] == 0
    again = _start(processes, *files)
    after = httpx.get(again.url + "/api/v1/tracks", params=params, timeout=5).json()["tracks"]
    assert after == before
    with httpx.Client(base_url=again.url, timeout=10) as http:
        elsewhere = {**body, "position": [9000.0, 9000.0]}  # not inside the first one
        r = http.post("/api/v1/tracks/extended", json=elsewhere, headers=auth)
        assert r.status_code == 201 and r.json()["id"] != started["id"]
    assert again.terminate()[0] == 0


def test_without_a_state_file_a_restart_gives_no_id_twice(
    processes: list[ServiceProcess], tmp_path: Path, payloads: list[bytes]
) -> None:
    """No state file: a restart begins with no tracks, but its ids go on past those given
    (the reservation in the state folder): from the next one after a clean stop, from the
    reservation after kill -9."""
    args = ("--api-token", "t", "--state-dir", str(tmp_path))
    reservation = tmp_path / "ids.json"

    def reserved() -> int:
        return int(json.loads(reservation.read_text())["reserved"]["individual"])

    def numbers(svc: ServiceProcess) -> set[int]:
        return {int(t["id"][1:]) for t in _tracks(svc, "all")["tracks"]}

    svc = _start(processes, *args)
    _post_all(svc, payloads[:30])
    first = numbers(svc)
    assert svc.terminate()[0] == 0
    next_id = reserved()  # shrunk at the clean stop to the next id
    assert max(first) < next_id < max(first) + 100

    again = _start(processes, *args)
    assert _tracks(again)["tracks"] == []
    _post_all(again, payloads[:30])  # the same batches: a new time line, new tracks
    second = numbers(again)
    assert min(second) >= next_id and max(second) < next_id + 1000  # no block skipped
    in_force = reserved()
    assert in_force > max(second)
    again.kill()  # SIGKILL: the reservation stays as it was

    third = _start(processes, *args)
    _post_all(third, payloads[:30])
    assert min(numbers(third)) >= in_force
    assert third.terminate()[0] == 0
