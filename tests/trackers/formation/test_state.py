"""The formation tracker's state saved and restored: a restart keeps the formations and their
members, and a bad section is refused without a change."""

from __future__ import annotations

import numpy as np
import pytest

from clients.scenarios.formation import environment_2, simulate_formations
from trackers.config import TrackerConfig
from trackers.formation.tracker import FormationTracker
from trackers.pipeline import TrackingPipeline
from trackers.state import StateError, StateSection, decode_state, encode_state
from trackers.types import Scan

ON = TrackerConfig().merged({"formation": {"enabled": True}})


@pytest.fixture(scope="module")
def scans() -> list[Scan]:
    return [s.to_scan() for s in simulate_formations(environment_2(3, 6, seed=0, scans=45))]


def _tracks(result) -> list[tuple]:
    return sorted((t.id, t.kind, t.position, t.velocity, t.formation_id) for t in result.tracks)


@pytest.fixture(scope="module")
def saved(scans: list[Scan]) -> tuple[TrackingPipeline, StateSection]:
    p = TrackingPipeline.all_kinds(ON)
    for scan in scans[:90]:
        p.process(scan)
    return p, p.export_state()


def test_a_restart_goes_on_with_the_same_formations(
    scans: list[Scan], saved: tuple[TrackingPipeline, object]
) -> None:
    """Paper 003's two formations saved after 30 s (their members taken from the point
    tracker), restored through the bytes of a file: the next batches give every track,
    members with their formation ids, exactly as without the restart."""
    a, state = saved
    section = state.peers["formation"]  # type: ignore[attr-defined]
    assert section.values["n_formations"] == 2 and section.values["n_members"] == 8
    restored, _ = decode_state(encode_state(state))  # type: ignore[arg-type]
    b = TrackingPipeline.all_kinds(ON)
    b.import_state(restored)
    assert _tracks_of(b) == _tracks_of(a)
    for scan in scans[90:]:
        assert _tracks(a.process(scan)) == _tracks(b.process(scan))


def _tracks_of(p: TrackingPipeline) -> list[tuple]:
    return sorted((t.id, t.kind, t.position, t.formation_id) for t in p.snapshot())


def test_members_saved_under_other_motion_models_restart_their_modes(
    saved: tuple[TrackingPipeline, object],
) -> None:
    _, state = saved
    cv_only = ON.merged(
        {"motion": {"models": ["cv"], "sojourn_times": [30.0], "initial_mode_probabilities": [1]}}
    )
    peer = FormationTracker(cv_only)
    peer.import_state(state.peers["formation"])  # type: ignore[attr-defined]
    assert [f.mu.shape for f in peer.formations] == [(4, 1), (4, 1)]
    assert all(np.allclose(f.mu, 1.0) for f in peer.formations)


def _edit(section: StateSection, values=None, **arrays: np.ndarray) -> StateSection:
    return StateSection({**section.values, **(values or {})}, {**section.arrays, **arrays})


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda s: _edit(s, {"next_id": 2}), "would give again the id F2"),
        (lambda s: _edit(s, {"n_members": 7}), r"members.x: shape \(8, 2, 5\), expected \(7"),
        (
            lambda s: _edit(s, **{"members.mu": s.arrays["members.mu"] * 2.0}),
            "mode probabilities",
        ),
        (
            lambda s: _edit(s, **{"members.P": -s.arrays["members.P"]}),
            "symmetric positive definite",
        ),
        (lambda s: _edit(s, {"time": None}), "without the time"),
    ],
)
def test_a_bad_section_is_refused_and_changes_nothing(
    saved: tuple[TrackingPipeline, object], edit, message: str
) -> None:
    _, state = saved
    peer = FormationTracker(ON)
    before = peer.formations
    with pytest.raises(StateError, match=message):
        peer.import_state(edit(state.peers["formation"]))  # type: ignore[attr-defined]
    assert peer.formations is before
