"""The extended tracker's state saved and restored: a restart goes on exactly as before, and a
bad section is refused without a change."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from clients.scenarios.extended import convoy_scenario
from trackers.config import TrackerConfig
from trackers.extended.tracker import ExtendedTracker
from trackers.peers import PointTrackView
from trackers.pipeline import TrackingPipeline
from trackers.state import StateError, StateSection, decode_state, encode_state
from trackers.types import Scan


@pytest.fixture(scope="module")
def convoy_scans() -> list[Scan]:
    return [ts.scan.to_scan() for ts in convoy_scenario(0).scans[:90]]


def _tracks(result) -> list[tuple]:
    return sorted((t.id, t.kind, t.status, t.position, t.velocity, t.score) for t in result.tracks)


def test_a_restart_goes_on_with_the_same_extended_tracks(convoy_scans: list[Scan]) -> None:
    """The convoy scenario saved after 60 scans (an extended track on the convoy, clusters
    waiting to be born, tracks being absorbed), restored through the bytes of a file into a
    new pipeline: the next 30 scans give every track of every kind exactly as without the
    restart."""
    a = TrackingPipeline.all_kinds(TrackerConfig())
    for scan in convoy_scans[:60]:
        a.process(scan)
    saved = a.export_state()
    assert "extended" in saved.peers and saved.peers["extended"].values["n_tracks"] >= 1
    state, _ = decode_state(encode_state(saved))
    b = TrackingPipeline.all_kinds(TrackerConfig())
    b.import_state(state)
    kinds = set()
    for scan in convoy_scans[60:]:
        ra, rb = a.process(scan), b.process(scan)
        assert _tracks(ra) == _tracks(rb)
        kinds |= {t.kind for t in ra.confirmed()}
    assert kinds == {"individual", "extended"}


def test_a_track_started_by_hand_keeps_its_fields() -> None:
    """Every field of a track comes back, the infinite origin of one started by hand too."""
    ext = ExtendedTracker(TrackerConfig())
    track = ext.start(5.0, np.array([100.0, -50.0]), np.array([3.0, 1.0]), np.diag([400.0, 25.0]))
    assert math.isinf(track.origin)
    other = ExtendedTracker(TrackerConfig())
    other.import_state(ext.export_state())
    (back,) = other.tracks
    for name in ("id", "time", "score", "peak", "hits", "confirmed", "created", "updated"):
        assert getattr(back, name) == getattr(track, name)
    assert back.gamma == track.gamma and math.isinf(back.origin)
    for name in ("x", "P", "X"):
        np.testing.assert_array_equal(getattr(back.estimate, name), getattr(track.estimate, name))
    assert back.estimate.alpha == track.estimate.alpha
    # the id counter goes on: the next track started by hand is E2
    assert other.start(6.0, np.zeros(2), np.zeros(2), np.eye(2) * 100.0).id == "E2"


def _edited(section: StateSection, **arrays: np.ndarray) -> StateSection:
    return StateSection(section.values, {**section.arrays, **arrays})


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda s: _edited(s, **{"tracks.X": -s.arrays["tracks.X"]}), "positive definite"),
        (
            lambda s: StateSection({**s.values, "next_id": 1}, s.arrays),
            "would give again the id E1",
        ),
        (
            lambda s: StateSection(
                {**s.values, "time": 5.0},
                {**s.arrays, "tracks.updated": s.arrays["tracks.updated"] + 1e3},
            ),
            "created <= updated <= the track's time",
        ),
        (lambda s: _edited(s, **{"tracks.alpha": s.arrays["tracks.alpha"][:0]}), "tracks.alpha"),
        (lambda s: StateSection({**s.values, "n_tracks": -1}, s.arrays), "n_tracks"),
    ],
)
def test_a_bad_section_is_refused_and_changes_nothing(edit, message: str) -> None:
    ext = ExtendedTracker(TrackerConfig())
    ext.start(5.0, np.array([100.0, -50.0]), np.array([3.0, 1.0]), np.diag([400.0, 25.0]))
    section = ext.export_state()
    target = ExtendedTracker(TrackerConfig())
    target.start(1.0, np.zeros(2), np.zeros(2), np.eye(2) * 100.0)
    before = target.tracks
    with pytest.raises(StateError, match=message):
        target.import_state(edit(section))
    assert target.tracks is before


def test_a_file_without_an_extended_section_leaves_the_tracker_empty(
    convoy_scans: list[Scan],
) -> None:
    """A state saved before extended tracks were saved has no section for them: the tracker
    starts empty, the individual tracks come back."""
    a = TrackingPipeline.all_kinds(TrackerConfig())
    for scan in convoy_scans[:30]:
        a.process(scan)
    saved = a.export_state()
    older = replace(saved, peers={k: v for k, v in saved.peers.items() if k != "extended"})
    b = TrackingPipeline.all_kinds(TrackerConfig())
    b.import_state(older)
    assert not [t for t in b.snapshot() if t.kind == "extended"]
    assert {t.id for t in b.snapshot()} == {t.id for t in a.snapshot() if t.kind != "extended"}


def test_a_track_started_by_hand_ahead_of_the_last_scan_is_restored() -> None:
    """The service lets a track be started a little after the last batch's time (within the
    time-jump allowance): such a state is valid and comes back."""
    p = TrackingPipeline.all_kinds(TrackerConfig())
    p.process(Scan(sensor_id="s", time=1.0, z=np.zeros((0, 2)), R=np.zeros((0, 2, 2))))
    ext = next(q for q in p.peers if q.kind == "extended")
    assert isinstance(ext, ExtendedTracker)
    ext.start(3.0, np.array([0.0, 0.0]), np.zeros(2), np.eye(2) * 100.0)
    q = TrackingPipeline.all_kinds(TrackerConfig())
    q.import_state(decode_state(encode_state(p.export_state()))[0])
    assert [t.id for t in q.snapshot() if t.kind == "extended"] == ["E1"]


def test_the_sensors_position_noise_is_kept_and_older_files_have_none() -> None:
    """The resolution distance in force follows the coarsest recent sensor: its noise comes
    back after a restart; a file written before it was kept reads as no sensor yet."""
    ext = ExtendedTracker(TrackerConfig())
    for t, sensor, sigma in ((0.0, "radar", 15.0), (0.5, "camera", 0.3)):
        z = np.array([[10.0 * t, 0.0]])
        ext.commit(ext.propose(Scan(sensor, t, z, np.eye(2)[None] * sigma**2), _empty_view(t)))
    section = ext.export_state()
    back = ExtendedTracker(TrackerConfig())
    back.import_state(section)
    kept = [(s, round(v, 6)) for s, v, _ in back._state.noise]
    assert kept == [("radar", 15.0), ("camera", 0.3)]
    arrays = {k: v for k, v in section.arrays.items() if "noise" not in k}
    old = StateSection(section.values, arrays)
    older = ExtendedTracker(TrackerConfig())
    older.import_state(old)
    assert older._state.noise == ()
    with pytest.raises(StateError, match=r"noise\.sigma: must be positive"):
        older.import_state(_edited(section, **{"noise.sigma": -section.arrays["noise.sigma"]}))


def _empty_view(t: float) -> PointTrackView:
    return PointTrackView(
        time=t,
        ids=(),
        x=np.zeros((0, 5)),
        P=np.zeros((0, 5, 5)),
        score=np.zeros(0),
        hits=np.zeros(0, dtype=np.int64),
        confirmed=np.zeros(0, dtype=bool),
        created=np.zeros(0),
        updated=np.zeros(0),
    )
