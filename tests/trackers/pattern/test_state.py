"""The point-pattern tracker's state saved and restored: a restart goes on exactly as before
(LMM and full IMM), a track saved under another filter is adapted, and a bad section is
refused without a change."""

from __future__ import annotations

import numpy as np
import pytest

from clients.scenarios.bending import bending_scenario
from trackers.config import TrackerConfig
from trackers.pattern.tracker import PatternTracker
from trackers.pipeline import TrackingPipeline
from trackers.state import StateError, StateSection, decode_state, encode_state

RUN = bending_scenario(0)
PATTERNS = {"first": RUN.patterns[0].tolist(), "second": RUN.patterns[1].tolist()}


def _config(filter_: str) -> TrackerConfig:
    return TrackerConfig().merged({"point_patterns": {"patterns": PATTERNS, "filter": filter_}})


def _tracks(result) -> list[tuple]:
    return sorted(
        (t.id, t.kind, t.position, t.velocity, t.attitude, str(t.shape_probabilities))
        for t in result.tracks
    )


@pytest.mark.parametrize(("filter_", "at"), [("lmm", 12), ("imm", 12), ("lmm", 2)])
def test_a_restart_goes_on_with_the_same_pattern_tracks(filter_: str, at: int) -> None:
    """Saved after ``at`` scans of paper 000's scenario (a sighting waiting at 2, the track
    at 12), restored through the bytes of a file: every later track exactly as without the
    restart."""
    scans = [RUN.to_scan(i) for i in range(len(RUN.scans))]
    a = TrackingPipeline.all_kinds(_config(filter_))
    for scan in scans[:at]:
        a.process(scan)
    state, _ = decode_state(encode_state(a.export_state()))
    b = TrackingPipeline.all_kinds(_config(filter_))
    b.import_state(state)
    seen = set()
    for scan in scans[at:]:
        ra, rb = a.process(scan), b.process(scan)
        assert _tracks(ra) == _tracks(rb)
        seen |= {t.id for t in ra.confirmed() if t.attitude is not None}
    assert seen == {"B1"}


def _saved() -> StateSection:
    p = TrackingPipeline.all_kinds(_config("lmm"))
    for i in range(12):
        p.process(RUN.to_scan(i))
    return p.export_state().peers["point_patterns"]


def test_a_track_saved_under_another_filter_is_adapted() -> None:
    peer = PatternTracker(_config("imm"))
    peer.import_state(_saved())
    (track,) = peer.tracks
    assert track.estimate.algorithm == "imm" and track.estimate.filter_x.shape[0] == 12
    assert set(track.shapes) == {"first", "second"}


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda v, a: ({**v, "next_id": 1}, a), "would give again the id B1"),
        (
            lambda v, a: (v, {**a, "tracks.P": -a["tracks.P"]}),
            "symmetric positive definite",
        ),
        (lambda v, a: ({**v, "n_filters": 6}, a), "tracks.filter_x: shape"),
        (lambda v, a: ({**v, "patterns": "first"}, a), "list of pattern names"),
    ],
)
def test_a_bad_section_is_refused_and_changes_nothing(edit, message: str) -> None:
    section = _saved()
    values, arrays = edit(dict(section.values), dict(section.arrays))
    peer = PatternTracker(_config("lmm"))
    before = peer.tracks
    with pytest.raises(StateError, match=message):
        peer.import_state(StateSection(values, arrays))
    assert peer.tracks is before
    assert np.isfinite(section.arrays["tracks.x"]).all()


def test_a_track_started_by_hand_before_any_scan_comes_back() -> None:
    peer = PatternTracker(_config("lmm"))
    track = peer.start(5.0, "first", [0.0, 0.0], [10.0, 0.0], 0.3)
    other = PatternTracker(_config("lmm"))
    other.import_state(peer.export_state())
    assert [t.id for t in other.tracks] == [track.id]


def test_tracks_restored_with_no_pattern_configured_keep_their_points() -> None:
    """As a configuration change that removes every pattern keeps the tracks, so does a
    restart under it; their snapshots still hold the pattern's extent."""
    peer = PatternTracker(TrackerConfig())
    peer.import_state(_saved())
    (track,) = peer.tracks
    assert track.pattern_points.shape == (5, 2)
    (snap,) = peer.snapshot()
    assert snap.extent is not None and snap.attitude is not None


def test_a_sighting_of_a_pattern_not_saved_is_refused() -> None:
    p = TrackingPipeline.all_kinds(_config("lmm"))
    for i in range(2):
        p.process(RUN.to_scan(i))
    section = p.export_state().peers["point_patterns"]
    assert section.values["n_sightings"] == 1
    bad = StateSection({**section.values, "patterns": []}, section.arrays)
    with pytest.raises(StateError, match="sighting's shape"):
        PatternTracker(_config("lmm")).import_state(bad)
