"""The track id reservation (:mod:`service.id_reserve`): ids a restart does not give again."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import pytest

from clients.scenarios.multitarget import reference_scenario, simulate
from service.engine import Engine
from service.id_reserve import ID_BLOCK, IdReservation, id_file
from trackers.pipeline import TrackingPipeline

from .helpers import ListSink, batch_payload, run_batches


@pytest.fixture(scope="module")
def scans() -> list[Any]:
    return [s.to_scan() for s in simulate(reference_scenario(1))[:12]]


def _ids(pipeline: TrackingPipeline) -> set[str]:
    return {t.id for t in pipeline.snapshot()}


def _number(track_id: str) -> int:
    return int(track_id[1:])


def _saved(path: Path) -> dict[str, int]:
    doc = json.loads(path.read_text())
    assert doc["version"] == 1
    return dict(doc["reserved"])


def test_a_fresh_folder_reserves_a_block_and_leaves_the_counters(tmp_path: Path) -> None:
    path = id_file(tmp_path / "state")
    assert path == tmp_path / "state" / "ids.json"
    pipeline = TrackingPipeline.all_kinds()
    IdReservation(path).begin(pipeline)
    assert pipeline.id_counters() == {
        "individual": 1,
        "point_patterns": 1,
        "extended": 1,
        "formation": 1,
    }
    assert _saved(path) == {k: 1 + ID_BLOCK for k in pipeline.id_counters()}
    assert id_file(tmp_path, "west") == tmp_path / "ids.west.json"


def test_every_id_given_is_below_the_reservation_on_disk(tmp_path: Path, scans) -> None:
    path = tmp_path / "ids.json"
    now = [0.0]
    ids = IdReservation(path, block=5, clock=lambda: now[0])
    pipeline = TrackingPipeline()
    ids.begin(pipeline)
    writes = 0
    for scan in scans:
        now[0] += 100.0  # slow enough for blocks of 5 (BLOCK_SECONDS of ids at the rate)
        pipeline.process(scan)
        before = _saved(path)
        ids.check(pipeline)
        after = _saved(path)
        writes += after != before
        # what a crash now would leave: every id given so far is below it
        assert all(_number(i) < after["individual"] for i in _ids(pipeline))
        assert pipeline.id_counters()["individual"] < after["individual"]
    assert pipeline.id_counters()["individual"] > 20  # the scans gave many ids...
    assert 1 < writes < len(scans) + 1  # ... and blocks of 5 took several writes


def test_after_a_crash_the_next_run_gives_no_id_twice(tmp_path: Path, scans) -> None:
    path = tmp_path / "ids.json"
    now = [0.0]
    first = TrackingPipeline()
    ids = IdReservation(path, block=50, clock=lambda: now[0])
    ids.begin(first)
    for scan in scans:
        now[0] += 100.0  # slowly: blocks of 50
        first.process(scan)
        ids.check(first)
    given = first.id_counters()["individual"]
    # no end(): the process was killed (its lock goes with it); the next one starts without
    # a state file
    ids._unlock()
    second = TrackingPipeline()
    IdReservation(path, block=50).begin(second)
    start = second.id_counters()["individual"]
    assert given <= start <= given + 50
    for scan in scans:
        second.process(scan)
    assert min(_number(i) for i in _ids(second)) >= start
    assert not _ids(first) & _ids(second)


def test_after_a_clean_stop_the_ids_go_on_from_the_next(tmp_path: Path, scans) -> None:
    path = tmp_path / "ids.json"
    first = TrackingPipeline.all_kinds()
    ids = IdReservation(path)
    ids.begin(first)
    for scan in scans:
        first.process(scan)
        ids.check(first)
    ids.end(first)
    assert _saved(path) == first.id_counters()
    second = TrackingPipeline.all_kinds()
    IdReservation(path).begin(second)
    assert second.id_counters() == first.id_counters()
    assert _saved(path) == {k: n + ID_BLOCK for k, n in first.id_counters().items()}


def test_a_counter_ahead_of_the_file_stays_and_other_kinds_are_kept(tmp_path: Path) -> None:
    path = tmp_path / "ids.json"
    path.write_text(json.dumps({"version": 1, "reserved": {"individual": 7, "bending": 40}}))
    pipeline = TrackingPipeline()
    pipeline.skip_ids({"individual": 90})  # e.g. restored from a state file
    IdReservation(path, block=10).begin(pipeline)
    assert pipeline.id_counters() == {"individual": 90}
    assert _saved(path) == {"individual": 100, "bending": 40}


@pytest.mark.parametrize(
    "content",
    [
        b"{not json",
        b"\xff\xfe",
        b'{"version": 2, "reserved": {}}',
        b'{"version": 1, "reserved": []}',
        b'{"version": 1, "reserved": {"individual": 0}}',
        b'{"version": 1, "reserved": {"individual": true}}',
        b'{"version": 1, "reserved": {"individual": 1.5}}',
        b'{"version": 1, "reserved": {"individual": 1e300}}',
        b'{"version": 1, "reserved": {"individual": 99999999999999999999}}',
        b"[" * 100_000,
        b'{"version": 1, "reserved": {}, "x": "' + b"a" * 70_000 + b'"}',
    ],
)
def test_a_bad_file_is_logged_and_replaced(
    tmp_path: Path, content: bytes, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "ids.json"
    path.write_bytes(content)
    pipeline = TrackingPipeline()
    with caplog.at_level(logging.WARNING, logger="service.ids"):
        IdReservation(path, block=10).begin(pipeline)
    assert "is not usable" in caplog.text and str(path) in caplog.text
    assert pipeline.id_counters() == {"individual": 1}
    assert _saved(path) == {"individual": 11}


def test_a_lock_that_cannot_be_taken_keeps_no_reservation(
    tmp_path: Path, scans, caplog: pytest.LogCaptureFixture
) -> None:
    (tmp_path / "file").write_text("")
    path = tmp_path / "file" / "ids.json"  # its folder is a file
    pipeline = TrackingPipeline()
    ids = IdReservation(path, block=2)
    with caplog.at_level(logging.WARNING, logger="service.ids"):
        ids.begin(pipeline)
        for scan in scans[:4]:
            pipeline.process(scan)
            ids.check(pipeline)
        ids.end(pipeline)
    assert caplog.text.count("no track id reservation is kept") == 1
    assert not ids.active and ids.reserved == {}


def test_a_second_service_on_the_same_folder_keeps_none(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "ids.json"
    first, second, third = (IdReservation(path, block=10) for _ in range(3))
    first.begin(TrackingPipeline())
    with caplog.at_level(logging.WARNING, logger="service.ids"):
        pipeline = TrackingPipeline()
        second.begin(pipeline)
    assert "another service holds the track id reservation" in caplog.text
    assert first.active and not second.active
    pipeline.skip_ids({"individual": 500})
    second.check(pipeline)
    second.end(pipeline)  # writes nothing: the file is the first one's
    assert _saved(path) == {"individual": 11}
    first.end(TrackingPipeline())  # releases the lock
    third.begin(TrackingPipeline())
    assert third.active
    third.end(TrackingPipeline())


def test_a_failed_write_is_tried_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A disk full for a while: warned once, tried again every RETRY_SECONDS, and the
    reservation covers the counters again once a write works."""
    import service.id_reserve as module

    now = [0.0]
    path = tmp_path / "ids.json"
    ids = IdReservation(path, block=5, clock=lambda: now[0])
    pipeline = TrackingPipeline()
    ids.begin(pipeline)
    full = [True]
    real = module.atomic_write

    def write(target: Path, data: bytes) -> None:
        if full[0]:
            raise OSError(28, "No space left on device")
        real(target, data)

    monkeypatch.setattr(module, "atomic_write", write)
    with caplog.at_level(logging.WARNING, logger="service.ids"):
        pipeline.skip_ids({"individual": 8})  # ids given past the reservation (6)
        ids.check(pipeline)
        assert not ids.active and _saved(path) == {"individual": 6}
        now[0] = module.RETRY_SECONDS / 2
        ids.check(pipeline)  # too soon: not tried
        full[0] = False
        ids.check(pipeline)
        assert not ids.active
        now[0] = module.RETRY_SECONDS + 1
        ids.check(pipeline)
    assert ids.active and _saved(path)["individual"] > 8
    assert caplog.text.count("cannot write the track id reservation") == 1


def test_a_file_that_cannot_be_read_is_left_alone(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "ids.json"
    path.mkdir()  # reading it fails (not a missing file)
    pipeline = TrackingPipeline()
    ids = IdReservation(path)
    with caplog.at_level(logging.WARNING, logger="service.ids"):
        ids.begin(pipeline)
    assert "cannot read the track id reservation" in caplog.text
    assert not ids.active and path.is_dir()
    ids.end(pipeline)
    assert path.is_dir()


def test_ids_numbered_fast_reserve_a_larger_block(tmp_path: Path) -> None:
    """Clutter starting hundreds of tentative tracks a second: a block holds the ids of
    BLOCK_SECONDS at that rate, so the file is not written every few batches."""
    from service.id_reserve import BLOCK_SECONDS

    now = [0.0]
    path = tmp_path / "ids.json"
    ids = IdReservation(path, block=100, clock=lambda: now[0])
    pipeline = TrackingPipeline()
    ids.begin(pipeline)
    assert _saved(path) == {"individual": 101}
    now[0] = 1.0
    pipeline.skip_ids({"individual": 101})  # 100 ids in 1 s
    ids.check(pipeline)
    assert _saved(path) == {"individual": 101 + int(BLOCK_SECONDS * 100)}


def test_a_counter_near_the_bound_writes_a_file_the_next_start_reads(tmp_path: Path) -> None:
    from service.id_reserve import MAX_COUNTER

    path = tmp_path / "ids.json"
    pipeline = TrackingPipeline()
    pipeline.skip_ids({"individual": MAX_COUNTER - 10})
    ids = IdReservation(path)
    ids.begin(pipeline)
    assert _saved(path) == {"individual": MAX_COUNTER}
    ids._unlock()  # killed
    again = TrackingPipeline()
    IdReservation(path).begin(again)
    assert again.id_counters() == {"individual": MAX_COUNTER}


def test_a_bad_block_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="block"):
        IdReservation(tmp_path / "ids.json", block=0)


class _CheckingSink(ListSink):
    """Checks, as each report goes out, that every id the engine shows (tentative tracks
    too) is below the reservation on disk."""

    def __init__(self, path: Path) -> None:
        super().__init__()
        self.path = path
        self.engine: Engine | None = None
        self.checked = 0
        self.uncovered: list[tuple[str, int]] = []  # (an exception here would be logged)

    def publish_tracks(self, data: bytes) -> None:
        super().publish_tracks(data)
        assert self.engine is not None
        reserved = _saved(self.path)
        for track in self.engine.tracks("all")["tracks"]:
            kind = {"T": "individual", "E": "extended"}[track["id"][0]]
            if _number(track["id"]) >= reserved[kind]:
                self.uncovered.append((track["id"], reserved[kind]))
            self.checked += 1


def test_the_engine_reserves_before_reporting_and_shrinks_at_stop(tmp_path: Path) -> None:
    path = tmp_path / "ids.json"
    payloads = [batch_payload(s) for s in simulate(reference_scenario(2))[:10]]
    sink = _CheckingSink(path)
    engine = Engine(sink=sink, id_reservation=IdReservation(path, block=1))
    sink.engine = engine
    engine.start()
    try:
        run_batches(engine, payloads, key=None)
        assert not sink.errors and sink.checked > 50 and sink.uncovered == []
        before = _saved(path)["extended"]
        track = engine.start_extended_track((9e4, 9e4), (0.0, 0.0), [[400.0, 0.0], [0.0, 100.0]])
        assert _number(track["id"]) < _saved(path)["extended"]  # covered before the answer
        assert _saved(path)["extended"] > before
        counters = engine.call_in_worker(lambda p: p.id_counters())
    finally:
        engine.stop()
    assert _saved(path) == counters  # a clean stop: the next start goes on from the next id
