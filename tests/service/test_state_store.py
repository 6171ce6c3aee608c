"""The tracker state file: atomic writes and what interrupted ones leave, an engine that goes
on after a restart exactly as one that never stopped, and the states it refuses."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import orjson
import pytest

from service.engine import Engine
from service.files import STALE_AFTER, atomic_write, remove_stale_temporaries, temporaries_of
from service.schemas import IngestConfig
from service.state_store import StateStore
from trackers.config import TrackerConfig
from trackers.state import decode_state

from .helpers import ListSink, batch_payload, run_batches, wait_until

ROOT = Path(__file__).resolve().parents[2]


# -- files ----------------------------------------------------------------------------------


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_temporaries_are_removed_and_live_writes_kept(tmp_path: Path) -> None:
    path = tmp_path / "state.npz"
    atomic_write(path, b"old")
    parent = os.getppid()  # a live process that is not this one
    stale = [
        tmp_path / f".state.npz.{_dead_pid()}-abc.tmp",  # its writer is gone
        tmp_path / f".state.npz.{os.getpid()}-def.tmp",  # this pid, from a former life
        tmp_path / ".state.npz.k3j2h1.tmp",  # the earlier naming, with no pid
    ]
    old_live = tmp_path / f".state.npz.{parent}-old.tmp"  # live pid, but far too old
    live = tmp_path / f".state.npz.{parent}-new.tmp"
    others = [tmp_path / ".other.npz.1-x.tmp", tmp_path / "state.npz.tmp"]
    for p in [*stale, old_live, live, *others]:
        p.write_bytes(b"")
    os.utime(old_live, (time.time() - STALE_AFTER - 5,) * 2)
    assert temporaries_of(path) == sorted([*stale, old_live, live])
    removed = remove_stale_temporaries(path)
    assert sorted(removed) == sorted([*stale, old_live])
    assert temporaries_of(path) == [live]
    assert all(p.exists() for p in others) and path.read_bytes() == b"old"


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "state.npz"
    atomic_write(path, b"one")
    atomic_write(path, b"two")
    assert path.read_bytes() == b"two" and os.listdir(tmp_path) == ["state.npz"]
    with pytest.raises(TypeError):
        atomic_write(path, "not bytes")  # type: ignore[arg-type]
    assert path.read_bytes() == b"two" and os.listdir(tmp_path) == ["state.npz"]


#: A child that saves state A, then starts saving state B with a disk that never finishes
#: its fsync, and says so: the test kills it (-9) right there, in the middle of the save.
_CHILD = """
import os, sys, time
from pathlib import Path
import service.files as files
from service.engine import Engine
from service.state_store import StateStore
from tests.service.helpers import batch_payload, run_batches
from clients.scenarios.multitarget import reference_scenario, simulate

path, marker = Path(sys.argv[1]), Path(sys.argv[2])
store = StateStore(path, max_age=600, save_interval=0)
engine = Engine(state_store=store)
engine.start()
scans = simulate(reference_scenario(3))
run_batches(engine, [batch_payload(s) for s in scans[:20]])
store.save(engine._checkpoint)  # state A: seq 20

def stuck(fd):
    marker.write_text(str(os.getpid()))
    time.sleep(60)

files.os.fsync = stuck
run_batches(engine, [batch_payload(s) for s in scans[20:25]])
store.save(engine._checkpoint)  # state B: never gets there
"""


def test_a_kill_during_a_save_leaves_the_old_state_and_start_up_cleans_up(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path, marker = tmp_path / "state.npz", tmp_path / "fsync-reached"
    child = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(_CHILD), str(path), str(marker)],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        wait_until(marker.exists, timeout=60, what="the child in the middle of its second save")
        os.kill(child.pid, signal.SIGKILL)
        child.wait(10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(10)
    left = temporaries_of(path)
    assert len(left) == 1 and left[0].stat().st_size > 0  # the interrupted save's file
    _, meta = decode_state(path.read_bytes())
    assert meta["seq"] == 20  # the old state, whole
    caplog.set_level(logging.INFO, logger="service")
    engine = Engine(state_store=StateStore(path, max_age=600, save_interval=0))
    engine.start()
    try:
        assert temporaries_of(path) == []
        assert engine.seq == 20 and len(engine.latest_report()["tracks"]) > 0
        assert f"removed {left[0]}" in caplog.text
    finally:
        engine.stop()


# -- the engine across a restart ------------------------------------------------------------


@pytest.fixture
def payloads(scans: list[Any]) -> list[bytes]:
    return [batch_payload(s) for s in scans]


class Engines:
    """Engines started by a test, all stopped after it."""

    def __init__(self) -> None:
        self.started: list[Engine] = []

    def __call__(self, path: Path | None = None, **kw: Any) -> Engine:
        store_kw = {k: kw.pop(k) for k in ("max_age", "save_interval", "wall_clock") if k in kw}
        store = None
        if path is not None:
            store = StateStore(
                path,
                max_age=store_kw.pop("max_age", 600.0),
                save_interval=store_kw.pop("save_interval", 0.0),
                **store_kw,
            )
        engine = Engine(state_store=store, sink=kw.pop("sink", ListSink()), **kw)
        engine.start()
        self.started.append(engine)
        return engine


@pytest.fixture
def engines() -> Iterator[Engines]:
    made = Engines()
    try:
        yield made
    finally:
        for e in made.started:
            e.stop()


def _same_report(a: dict[str, Any], b: dict[str, Any]) -> bool:
    keep = ("seq", "time", "sensor_id", "tracks")
    return {k: a[k] for k in keep} == {k: b[k] for k in keep}


def test_a_restarted_engine_goes_on_as_if_it_had_not_stopped(
    tmp_path: Path, payloads: list[bytes], engines: Engines
) -> None:
    path = tmp_path / "state.npz"
    first = engines(path)
    run_batches(first, payloads[:40])
    before = first.latest_report()
    everything_before = first.tracks("all")["tracks"]
    first.stop()
    assert os.listdir(tmp_path) == ["state.npz"]

    sink = ListSink()
    second = engines(path, sink=sink)
    assert second.seq == 40
    assert _same_report(second.latest_report(), before)  # readers see the restored tracks
    assert second.tracks("all")["tracks"] == everything_before
    assert second.stats.snapshot()["seq"] == 40
    results = run_batches(second, payloads[40:70])
    assert [r.seq for r in results] == list(range(41, 71))

    straight = engines(sink=(straight_sink := ListSink()))
    run_batches(straight, payloads[:70])
    for got, want in zip(sink.tracks, straight_sink.tracks[40:], strict=True):
        assert _same_report(got, want) and got["deleted"] == want["deleted"]
    top = max(int(t["id"][1:]) for t in everything_before)
    after = second.tracks("all")["tracks"]
    assert after == straight.tracks("all")["tracks"]
    new = {t["id"] for t in after} - {t["id"] for t in everything_before}
    assert new and min(int(i[1:]) for i in new) > top  # the id counter went on


def test_a_restored_engine_keeps_time_order_and_the_time_jump_guard(
    tmp_path: Path, scans: list[Any], engines: Engines
) -> None:
    path = tmp_path / "state.npz"
    ingest = IngestConfig(max_time_jump=10.0)
    first = engines(path, ingest=ingest)
    run_batches(first, [batch_payload(s) for s in scans[:20]])
    first.stop()
    # restarted 200 s later (wall clock): a batch 150 s on is the sensors' time moving on
    later = engines(path, ingest=ingest, wall_clock=lambda: time.time() + 200.0)
    old = run_batches(later, [batch_payload(scans[10])])[0]
    assert not old.accepted and old.error is not None
    assert old.error["error"] == "out_of_sequence"
    on = run_batches(later, [batch_payload(scans[20], time=scans[19].time + 150.0)])[0]
    assert on.accepted and on.seq == 21
    far = run_batches(later, [batch_payload(scans[21], time=scans[19].time + 1000.0)])[0]
    assert far.error is not None and far.error["error"] == "time_jump"


def test_a_stop_after_a_quiet_spell_saves_the_time_it_stopped(
    tmp_path: Path, scans: list[Any], engines: Engines
) -> None:
    """Sensors quiet for 400 s (longer than state_max_age), then a stop and a restart 10 s
    later: the file says when the service stopped, so the tracks are restored; the time-jump
    guard counts the quiet spell, so the sensors' next batch 410 s on is taken."""
    path = tmp_path / "state.npz"
    wall = [0.0]
    ingest = IngestConfig(max_time_jump=10.0)
    first = engines(path, ingest=ingest, max_age=300.0, wall_clock=lambda: time.time() + wall[0])
    run_batches(first, [batch_payload(s) for s in scans[:20]])
    store = first._state_store
    assert store is not None and store.save(first._checkpoint) is not None  # a periodic save
    assert store.save(first._checkpoint) is None  # nothing new since: skipped
    wall[0] = 400.0  # the sensors fall quiet for 400 s; then the service is stopped
    first._checkpoint = replace(first._checkpoint, processed_at=time.monotonic() - 400.0)
    tracks = first.latest_report()["tracks"]
    first.stop()
    meta = decode_state(path.read_bytes())[1]
    assert meta["seq"] == 20 and meta["since_last_batch"] >= 400.0

    later = engines(path, ingest=ingest, max_age=300.0, wall_clock=lambda: time.time() + 410.0)
    assert later.seq == 20 and later.latest_report()["tracks"] == tracks and tracks
    on = run_batches(later, [batch_payload(scans[20], time=scans[19].time + 410.0)])[0]
    assert on.accepted and on.seq == 21


def test_states_that_are_not_restored_say_why(
    tmp_path: Path,
    payloads: list[bytes],
    engines: Engines,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="service")
    path = tmp_path / "state.npz"
    missing = engines(path)
    assert "no saved tracker state" in caplog.text and missing.seq == 0
    run_batches(missing, payloads[:15])
    missing.stop()

    old = engines(path, max_age=60.0, wall_clock=lambda: time.time() + 61.0)
    assert old.seq == 0 and old.latest_report()["tracks"] == []
    assert "more than state_max_age = 60 s" in caplog.text
    old.stop()  # nothing processed: the saved state stays as it was
    assert decode_state(path.read_bytes())[1]["seq"] == 15

    path.write_bytes(b"not a state")
    bad = engines(path)
    assert bad.seq == 0 and "is not used: not a state file" in caplog.text
    run_batches(bad, payloads[:3])
    bad.stop()  # replaced by a good one
    assert decode_state(path.read_bytes())[1]["seq"] == 3


def test_a_state_saved_under_other_motion_models_is_re_moded(
    tmp_path: Path, payloads: list[bytes], engines: Engines
) -> None:
    path = tmp_path / "state.npz"
    first = engines(path)
    run_batches(first, payloads[:30])
    ids = [t["id"] for t in first.latest_report()["tracks"]]
    first.stop()
    cv = TrackerConfig().merged(
        {"motion": {"models": ["cv"], "sojourn_times": [30.0], "initial_mode_probabilities": [1]}}
    )
    second = engines(path, config=cv)
    tracks = second.latest_report()["tracks"]
    assert [t["id"] for t in tracks] == ids
    assert {tuple(t["model_probabilities"]) for t in tracks} == {("cv",)}
    results = run_batches(second, payloads[30:40])
    assert all(r.accepted for r in results)


def test_periodic_saves_happen_off_the_worker_and_only_after_changes(
    tmp_path: Path, payloads: list[bytes], engines: Engines
) -> None:
    path = tmp_path / "state.npz"
    engine = engines(path, save_interval=0.05)
    run_batches(engine, payloads[:25])

    def saved_seq() -> int:
        try:
            return int(decode_state(path.read_bytes())[1]["seq"])
        except FileNotFoundError:
            return -1

    wait_until(lambda: saved_seq() == 25, timeout=10, what="a periodic save of seq 25")
    store = engine._state_store
    assert store is not None and store.last_save is not None and store.last_save.size > 0
    mtime = path.stat().st_mtime_ns
    time.sleep(0.3)  # idle: nothing new to save
    assert path.stat().st_mtime_ns == mtime
    meta = decode_state(path.read_bytes())[1]
    assert meta["sensor_id"] == "radar-1" and meta["since_last_batch"] >= 0
    assert orjson.loads(orjson.dumps(meta))["service_version"]


def test_a_point_tracker_that_cannot_be_saved_turns_the_state_file_off(
    tmp_path: Path, engines: Engines, caplog: pytest.LogCaptureFixture
) -> None:
    from trackers.pipeline import TrackingPipeline

    class Opaque:
        """A point tracker without the persistence methods (delegating the rest)."""

        def __init__(self, config: TrackerConfig) -> None:
            from trackers.individual import IndividualTracker

            self._inner = IndividualTracker(config)
            self.kind = "opaque"

        def __getattr__(self, name: str) -> Any:
            if name in ("checkpoint", "check_state", "restore_state"):
                raise AttributeError(name)
            return getattr(self._inner, name)

    factory: Callable[[TrackerConfig], TrackingPipeline] = lambda c: TrackingPipeline(  # noqa: E731
        c,
        point_tracker=Opaque(c),  # type: ignore[arg-type]
    )
    caplog.set_level(logging.WARNING, logger="service")
    engine = engines(tmp_path / "state.npz", pipeline_factory=factory)
    assert "the tracker state is not saved" in caplog.text
    engine.stop()
    assert not (tmp_path / "state.npz").exists()


def test_the_restore_counts_every_kind_and_warns_of_tracks_the_configuration_ends(
    tmp_path: Path, engines: Engines, caplog: pytest.LogCaptureFixture
) -> None:
    """Formations saved while on (as ``--demo formation`` has them), restored with them
    off: the log counts the restored tracks of every kind and says the formations end at
    the next batch, and why."""
    from clients.scenarios.formation import environment_1, simulate_formations

    caplog.set_level(logging.INFO, logger="service")
    path = tmp_path / "state.npz"
    on = TrackerConfig().merged({"formation": {"enabled": True}})
    first = engines(path, config=on)
    sims = simulate_formations(environment_1(seed=0, scans=30))
    run_batches(first, [batch_payload(s) for s in sims[:75]], key=None)
    formations = [t for t in first.tracks("all")["tracks"] if t["kind"] == "formation"]
    assert len(formations) == 2
    first.stop()
    caplog.clear()
    second = engines(path)
    assert "2 formation" in caplog.text and "individual" in caplog.text
    assert "2 restored formations end at the next batch: formation.enabled is off" in caplog.text
    run_batches(second, [batch_payload(sims[75])], key=None)
    assert not [t for t in second.tracks("all")["tracks"] if t["kind"] == "formation"]
