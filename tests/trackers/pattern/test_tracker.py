"""The point-pattern tracker as a peer of the individual tracker: paper 000's bending target
through the whole pipeline with the default configuration plus the two patterns, tracks
started by hand, births in clutter, reconfiguration, and the peer's no-change guarantees."""

from __future__ import annotations

import math

import numpy as np
import pytest

from clients.scenarios.bending import BendingRun, bending_scenario
from trackers.config import TrackerConfig
from trackers.pattern.tracker import PatternTracker
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan


def _config(run: BendingRun, **section: object) -> TrackerConfig:
    patterns = {"five": run.patterns[0].tolist(), "four": run.patterns[1].tolist()}
    return TrackerConfig().merged({"point_patterns": {"patterns": patterns, **section}})


def _scan(run: BendingRun, k: int) -> Scan:
    return run.to_scan(k)


def _peer(p: TrackingPipeline) -> PatternTracker:
    peer = next(q for q in p.peers if q.kind == "point_patterns")
    assert isinstance(peer, PatternTracker)
    return peer


@pytest.mark.parametrize("filter_", ["lmm", "imm"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_papers_bending_target_is_held_by_one_track(seed: int, filter_: str) -> None:
    """Paper 000 section 5 (a 5-point pattern, then a 4-point one at k = 16; a turn at
    −3°/s for k = 11-20; rotation at 5°/s from k = 18; clutter about as dense as the target's
    points): one track, started within three scans, never lost, its attitude within a few
    degrees, the right shape within 3 scans of the switch, and no individual track confirmed
    from its detections or the clutter around it."""
    run = bending_scenario(seed)
    p = TrackingPipeline.all_kinds(_config(run, filter=filter_))
    ids: set[str] = set()
    pos, att = [], []
    taken = wrong = 0
    for k in range(len(run.scans)):
        r = p.process(_scan(run, k))
        sc = run.scans[k]
        tracks = [t for t in r.confirmed() if t.attitude is not None]
        assert not [t for t in r.confirmed() if t.kind == "individual"]
        if sc.k < 3:
            continue
        assert len(tracks) == 1, (sc.k, tracks)
        t = tracks[0]
        ids.add(t.id)
        assert t.kind == "extended" and t.extent is not None
        x = sc.state
        pos.append(math.hypot(t.position[0] - x[0], t.position[1] - x[2]))
        att.append(math.remainder(t.attitude - x[4], 2 * math.pi))
        assert abs(sum(t.shape_probabilities.values()) - 1) < 1e-9
        want = "five" if sc.k <= 15 else "four"
        if sc.k >= 19 or 6 <= sc.k <= 15:
            assert t.shape_probabilities[want] > 0.9, (sc.k, t.shape_probabilities)
        mine = {f"k{sc.k}d{i}" for i in np.flatnonzero(sc.point_of_detection >= 0)}
        taken += len(t.detection_ids)
        wrong += len(set(t.detection_ids) - mine)
    assert len(ids) == 1
    assert taken > 2.5 * 27 and wrong <= 0.08 * taken  # clutter is about half of each scan
    assert math.sqrt(np.mean(np.square(pos[4:]))) < 1.0
    assert math.degrees(math.sqrt(np.mean(np.square(att[4:])))) < 3.0


def test_a_track_started_by_hand_takes_the_patterns_detections() -> None:
    run = bending_scenario(4)
    p = TrackingPipeline.all_kinds(_config(run))
    peer = _peer(p)
    with pytest.raises(ValueError, match="pattern"):
        peer.start(0.0, "seven", [0, 0], [0, 0], 0.0)
    x = run.initial_state
    track = peer.start(0.0, "five", [x[0], x[2]], [x[1], x[3]], x[4], position_std=2.0)
    assert track.id == "B1" and pattern_names(track) == ("five", "four")
    r = p.process(_scan(run, 0))
    [t] = [t for t in r.confirmed() if t.attitude is not None]
    assert t.id == "B1" and len(t.detection_ids) >= 3
    with pytest.raises(ValueError, match="time"):
        peer.start(0.5, "five", [0, 0], [0, 0], 0.0)


def pattern_names(track: object) -> tuple[str, ...]:
    return track.shapes  # type: ignore[attr-defined, no-any-return]


def test_clutter_alone_starts_no_pattern_track() -> None:
    """Dense clutter (the paper's 0.005 per m²) over 200 m x 200 m for 30 scans, with the
    two patterns configured: no track."""
    run = bending_scenario(0)
    p = TrackingPipeline.all_kinds(_config(run))
    rng = np.random.default_rng(3)
    for k in range(30):
        n = rng.poisson(0.005 * 200 * 200)
        z = rng.uniform(-100, 100, size=(n, 2))
        r = p.process(
            Scan("radar", float(k), z, np.tile(run.R, (n, 1, 1)), pd=0.9, clutter_density=0.005)
        )
        assert not [t for t in r.tracks if t.attitude is not None], k


def test_no_patterns_no_tracks_and_no_cost() -> None:
    p = TrackingPipeline.all_kinds()
    peer = _peer(p)
    assert peer.modes is None
    run = bending_scenario(0)
    for k in range(5):
        p.process(_scan(run, k))
    assert peer.tracks == ()


def test_reconfiguring_carries_shapes_by_name_and_removing_all_ends_the_tracks() -> None:
    run = bending_scenario(1)
    cfg = _config(run)
    p = TrackingPipeline.all_kinds(cfg)
    for k in range(6):
        p.process(_scan(run, k))
    peer = _peer(p)
    [before] = peer.tracks
    extra = {"tri": [[0.0, 0.0], [30.0, 0.0], [0.0, 30.0]]}
    p.reconfigure(cfg.merged({"point_patterns": {"patterns": extra}}))
    [after] = peer.tracks
    assert after.id == before.id and after.shapes == ("five", "four", "tri")
    mu = dict(zip(after.shapes, after.estimate.layer_probabilities[2], strict=True))
    assert mu["five"] > 0.9 and mu["tri"] < 0.05
    p.process(_scan(run, 6))
    assert [t.id for t in peer.tracks] == [before.id]
    p.reconfigure(TrackerConfig())
    r = p.process(_scan(run, 7))
    assert before.id in r.deleted and peer.tracks == ()


def test_propose_changes_nothing_until_commit() -> None:
    run = bending_scenario(2)
    p = TrackingPipeline.all_kinds(_config(run))
    for k in range(4):
        p.process(_scan(run, k))
    peer = _peer(p)
    view = p.point.predicted(run.scans[4].time)
    state = peer._state
    a = peer.propose(_scan(run, 4), view)
    b = peer.propose(_scan(run, 4), view)
    assert peer._state is state
    assert np.array_equal(a.claimed, b.claimed)
    assert [t.position for t in a.tracks] == [t.position for t in b.tracks]
    peer.commit(a)
    assert peer._state is a.state


def test_a_pattern_track_has_a_resolution_cell_that_masks_point_tracks_in_it() -> None:
    """Paper 002's hybridization for pattern tracks: each has a resolution cell (its pattern's
    ellipse grown by half the resolution distance) with the extended section's in-cell
    detection probability; a point track inside gets it, one outside keeps the sensor's."""
    from trackers.peers import PointTrackView, combine_directives

    run = bending_scenario(0)
    patterns = {"first": run.patterns[0].tolist(), "second": run.patterns[1].tolist()}
    config = TrackerConfig().merged({"point_patterns": {"patterns": patterns}})
    p = TrackingPipeline.all_kinds(config)
    for i in range(12):
        p.process(run.to_scan(i))
    peer = next(q for q in p.peers if isinstance(q, PatternTracker))
    scan = run.to_scan(12)
    prop = peer.propose(scan, p.point.predicted(scan.time))
    (cell,) = prop.cells
    (snap,) = prop.tracks
    assert snap.extent is not None and cell.pd == config.extended.in_cell_pd
    centre = np.array(snap.position)
    # the cell reaches half a resolution distance beyond the pattern along its major axis
    theta = snap.extent.orientation
    reach = snap.extent.semi_axes[0] + 0.45 * config.extended.resolution_distance
    edge = centre + reach * np.array([math.cos(theta), math.sin(theta)])
    assert cell.contains(np.array([centre, edge])).all()
    x = np.zeros((2, 5))
    x[0, :2], x[1, :2] = centre, centre + np.array([500.0, 0.0])
    points = PointTrackView(
        time=scan.time,
        ids=("T1", "T2"),
        x=x,
        P=np.tile(np.eye(5), (2, 1, 1)),
        score=np.full(2, 20.0),
        hits=np.full(2, 5),
        confirmed=np.ones(2, dtype=bool),
        created=np.zeros(2),
        updated=np.full(2, scan.time),
    )
    directives = combine_directives((peer.kind,), (prop,), points)
    assert directives.pd.get("T1") == pytest.approx(config.extended.in_cell_pd)
    assert "T2" not in directives.pd
