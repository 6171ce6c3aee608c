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
    ids = IdReservation(path, block=5)
    pipeline = TrackingPipeline()
    ids.begin(pipeline)
    writes = 0
    for scan in scans:
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
    first = TrackingPipeline()
    ids = IdReservation(path, block=50)
    ids.begin(first)
    for scan in scans:
        first.process(scan)
        ids.check(first)
    given = first.id_counters()["individual"]
    # no end(): the process was killed; the next one starts without a state file
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


def test_a_folder_that_cannot_be_written_is_logged_once(
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
    assert caplog.text.count("cannot write the track id reservation") == 1
    assert ids.reserved == {}


def test_a_bad_block_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="block"):
        IdReservation(tmp_path / "ids.json", block=0)


def test_the_engine_reserves_before_reporting_and_shrinks_at_stop(tmp_path: Path) -> None:
    path = tmp_path / "ids.json"
    payloads = [batch_payload(s) for s in simulate(reference_scenario(2))[:10]]
    sink = ListSink()
    engine = Engine(sink=sink, id_reservation=IdReservation(path, block=3))
    engine.start()
    try:
        reserved = []
        for p in payloads:
            run_batches(engine, [p], key=None)
            reserved.append(_saved(path)["individual"])
            shown = {t["id"] for t in engine.tracks("all")["tracks"]}
            assert all(_number(i) < reserved[-1] for i in shown)
        counters = engine.call_in_worker(lambda p: p.id_counters())
    finally:
        engine.stop()
    assert reserved == sorted(reserved) and reserved[-1] > reserved[0]
    assert _saved(path) == counters  # a clean stop: the next start goes on from the next id
