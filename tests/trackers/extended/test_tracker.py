"""The extended-object peer (trackers/extended/tracker.py) on hand-made scans and on the
harbour scenario of clients/scenarios/extended.py (the convoy's targets are not met yet: see
benchmarks/extended.py)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from clients.scenarios.extended import convoy_scenario, harbour_scenario, run_figures
from trackers.config import TrackerConfig
from trackers.extended.tracker import (
    ExtendedTracker,
    _standing_out,
    extent_ellipse,
    position_noise,
    remembered_noise,
    resolution_in_force,
)
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan

R = np.eye(2) * 100.0  # 10 m per axis


def _cluster_scan(k, rng, centre, n=8, half=(150.0, 15.0), clutter=100, T=5.0):
    """A block of ``n`` detections uniform in a rectangle (plus 10 m noise) and uniform clutter."""
    pts = centre + rng.uniform(-1, 1, (n, 2)) * half + rng.normal(0, 10.0, (n, 2))
    z = np.vstack([pts, rng.uniform(-5000, 5000, (clutter, 2))])
    return Scan(
        "s",
        T * k,
        z,
        np.tile(R, (len(z), 1, 1)),
        tuple(f"d{k}-{i}" for i in range(len(z))),
        pd=0.9,
        clutter_density=1e-6,
    )


def test_a_moving_cluster_becomes_one_confirmed_extended_track():
    rng = np.random.default_rng(7)
    p = TrackingPipeline.all_kinds()
    for k in range(12):
        centre = np.array([1000.0 + 50.0 * k, 500.0])
        r = p.process(_cluster_scan(k, rng, centre))
    ext = [t for t in r.confirmed() if t.kind == "extended"]
    assert len(ext) == 1
    e = ext[0]
    assert np.hypot(*(np.array(e.position) - centre)) < 30.0
    assert np.hypot(*(np.array(e.velocity) - [10.0, 0.0])) < 3.0
    major, minor = e.extent.semi_axes
    # uniform 300 m x 30 m block: about 173 x 17 m; a false alarm within the resolution
    # distance (200 m) of the block joins its subset now and then and widens the minor axis
    assert 120 < major < 230 and minor < 50
    assert abs(np.sin(e.extent.orientation)) < 0.1
    assert len(e.detection_ids) >= 6
    # its detections start no individual track
    individual = [t for t in r.confirmed() if t.kind == "individual"]
    assert all(np.hypot(*(np.array(t.position) - centre)) > 300 for t in individual)


@pytest.mark.parametrize(("birth_time", "by"), [(10.0, 14.0), (4.0, 6.0)])
def test_an_object_starts_its_track_after_birth_time(birth_time, by):
    """A 200 m x 40 m object with 5-15 returns a scan at T = 2 s in sparse clutter: its
    extended track is confirmed no sooner than ``birth_time`` after it was first seen, and by
    ``by``; until then its returns confirm individual tracks (absorbed when it starts), none
    with 4 s."""
    cfg = TrackerConfig().merged({"extended": {"birth_time": birth_time}})
    p = TrackingPipeline.all_kinds(cfg)
    rng = np.random.default_rng(3)
    first, most = None, 0
    for k in range(10):
        t = 2.0 * k
        centre = np.array([-500.0 + 8.0 * t, 0.0])
        n = int(rng.integers(5, 16))
        z = centre + rng.uniform(-1, 1, (n, 2)) * (100.0, 20.0) + rng.normal(0, 5.0, (n, 2))
        z = np.vstack([z, rng.uniform(-2000, 2000, (rng.poisson(4), 2))])
        R5 = np.tile(25.0 * np.eye(2), (len(z), 1, 1))
        r = p.process(Scan("s", t, z, R5, pd=0.9, clutter_density=4 / 4000.0**2))
        if first is None and any(x.kind == "extended" for x in r.confirmed()):
            first = t
        on = [x for x in r.confirmed() if x.kind == "individual"]
        most = max(most, sum(np.hypot(*(np.array(x.position) - centre)) < 300 for x in on))
    assert first is not None and birth_time <= first <= by
    assert (most == 0) if birth_time < 10 else (most > 3)


def test_nothing_is_born_from_uniform_clutter_or_when_disabled():
    rng = np.random.default_rng(8)
    p = TrackingPipeline.all_kinds()
    off = TrackingPipeline.all_kinds(TrackerConfig().merged({"extended": {"enabled": False}}))
    for k in range(10):
        scan = _cluster_scan(k, rng, np.array([0.0, 0.0]), n=0, clutter=400)
        assert not [t for t in p.process(scan).tracks if t.kind == "extended"]
    for k in range(10):
        scan = _cluster_scan(k, rng, np.array([0.0, 0.0]))
        assert not [t for t in off.process(scan).tracks if t.kind == "extended"]


def test_a_track_started_by_hand_is_confirmed_and_takes_its_detections():
    rng = np.random.default_rng(9)
    p = TrackingPipeline.all_kinds()
    peer = next(q for q in p.peers if q.kind == "extended")
    assert isinstance(peer, ExtendedTracker)
    p.process(_cluster_scan(0, rng, np.array([0.0, 0.0]), n=0, clutter=10))
    track = peer.start(0.0, [0.0, 0.0], [10.0, 0.0], np.diag([150.0**2, 15.0**2]))
    assert track.confirmed and track.id.startswith("E")
    r = p.process(_cluster_scan(1, rng, np.array([50.0, 0.0])))
    ext = [t for t in r.confirmed() if t.kind == "extended"]
    assert [t.id for t in ext] == [track.id]
    assert len(ext[0].detection_ids) >= 6
    with pytest.raises(ValueError, match="time"):
        peer.start(-1.0, [0, 0], [0, 0], np.eye(2))
    with pytest.raises(ValueError):
        peer.start(10.0, [0, 0], [0, 0], -np.eye(2))
    # A newcomer's 5000 m/s start (coasted off to 18 km) and five starts of one object.
    with pytest.raises(ValueError, match=r"faster than extended\.max_speed"):
        peer.start(5.0, [5000.0, 0.0], [5000.0, 0.0], np.eye(2) * 100.0)
    with pytest.raises(ValueError, match=f"inside the extent of extended track '{track.id}'"):
        peer.start(5.0, [120.0, 5.0], [10.0, 0.0], np.diag([150.0**2, 15.0**2]))
    assert [t.id for t in peer.tracks] == [track.id]
    other = peer.start(5.0, [1000.0, 0.0], [10.0, 0.0], np.diag([150.0**2, 15.0**2]))
    assert [t.id for t in peer.tracks] == [track.id, other.id]


def test_a_small_object_does_not_take_a_buoy_its_resolution_subset_chains_it_to():
    """A 30 m boat started by hand passes 60-120 m from a static buoy: the buoy's detection
    shares a resolution subset (200 m) with the boat's, but lies far outside the boat's
    gate; the boat's track takes its own detection only and keeps its speed."""
    rng = np.random.default_rng(3)
    p = TrackingPipeline.all_kinds()
    peer = next(q for q in p.peers if q.kind == "extended")
    p.process(Scan("s", 0.0, np.zeros((0, 2)), np.zeros((0, 2, 2)), (), 0.9, 1e-7))
    track = peer.start(
        0.0, [0.0, 0.0], [5.0, 0.0], np.diag([15.0**2, 4.0**2]), expected_detections=1.5
    )
    buoy = np.array([150.0, 60.0])
    speeds = []
    for k in range(1, 30):
        t = 2.0 * k
        boat = np.array([5.0 * t, 0.0]) + rng.normal(0, 10.0, 2)
        z = np.vstack([boat, buoy + rng.normal(0, 10.0, 2)])
        scan = Scan("s", t, z, np.tile(R, (2, 1, 1)), (f"boat{k}", f"buoy{k}"), 0.9, 1e-7)
        ext = [x for x in p.process(scan).tracks if x.kind == "extended"]
        assert [x.id for x in ext] == [track.id]
        assert ext[0].detection_ids == (f"boat{k}",)
        speeds.append(ext[0].velocity[0])
    assert np.hypot(*(np.array(ext[0].position) - [5.0 * t, 0.0])) < 25.0
    assert abs(np.mean(speeds) - 5.0) < 1.0


def test_extent_ellipse_axes_and_orientation():
    theta = 0.4
    V = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    X = V @ np.diag([40.0**2, 10.0**2]) @ V.T
    e = extent_ellipse(X)
    assert e.semi_axes == pytest.approx((40.0, 10.0))
    assert e.orientation == pytest.approx(theta)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_harbour_boat_and_backwash_are_one_extended_track_each_and_false_tracks_fall(seed):
    run = harbour_scenario(seed)
    hybrid = run_figures(run, TrackingPipeline.all_kinds(), designate=True)
    alone = run_figures(run, TrackingPipeline())
    assert hybrid["backwash"] == 1
    assert hybrid["false"] <= 0.2 * alone["false"]  # at least 80 % fewer false confirmed tracks
    # the boat, designated at its first detection as in paper 002: one extended track
    # from then to the end, never more than 100 m from it
    assert hybrid["boat_breaks"] == 0 and hybrid["boat_held"] == 1.0


def test_convoy_is_one_track_through_both_junctions_and_splits_into_two():
    """Convoy scenario, seed 0 (benchmarks/extended.py prints all its figures): one
    extended track holds the convoy from its confirmation to the split, through both
    junctions; both groups have an extended track within 150 m a few scans after the split;
    its detections start next to no false individual track. (Not yet the issue's targets:
    centroid RMSE 36 m here against 15 m, where a filter on the convoy's own detections alone
    reaches 28 m (benchmarks.extended.centroid_floor); the split seen 3.4 scans after it
    against 3; and the overtaking vehicle's track breaks.)"""
    figures = run_figures(convoy_scenario(0), TrackingPipeline.all_kinds())
    assert figures["held"] == 1
    assert figures["rmse"] < 50.0
    assert figures["split"] <= 5.0
    assert figures["near_false"] < 0.05


def test_a_vehicle_coming_up_to_a_group_keeps_its_track_as_it_passes():
    """A block of detections moving east at 10 m/s becomes a confirmed extended track; a
    vehicle 1.5 km behind at 18 m/s, 60 m to the side, overtakes it. Its individual track is
    neither absorbed nor started anew: one id from before it reaches the group to after."""
    rng = np.random.default_rng(11)
    p = TrackingPipeline.all_kinds()
    ids = []
    for k in range(40):
        centre = np.array([1000.0 + 50.0 * k, 500.0])
        car = np.array([-500.0 + 90.0 * k, 560.0])
        scan = _cluster_scan(k, rng, centre, clutter=20)
        if rng.random() < 0.9:  # the car's detection
            z = np.vstack([scan.z, car + rng.normal(0, 10.0, 2)])
            scan = Scan(
                "s",
                scan.time,
                z,
                np.tile(R, (len(z), 1, 1)),
                (*scan.detection_ids, f"car{k}"),
                pd=0.9,
                clutter_density=1e-6,
            )
        conf = p.process(scan).confirmed()
        if k >= 8:
            near = [
                t.id for t in conf if t.kind == "individual" and np.hypot(*(t.position - car)) < 50
            ]
            ids.append(near[0] if near else None)
    assert [t for t in conf if t.kind == "extended"]
    assert None not in ids and len(set(ids)) == 1


@pytest.mark.parametrize("seed", range(3))
def test_a_vehicle_leaving_its_column_alone_gets_its_own_track(seed):
    """Six vehicles 60 m apart at 10 m/s, one extended track; at t = 100 s the lead speeds up
    to 17 m/s and drives away alone. Its detection, a subset of its own once 200 m ahead,
    keeps moving away from the track's centroid, so after three scans it is left to the
    individual tracker: the lead has a confirmed individual track when 450 m ahead (before,
    the extent stretched to hold it 1.4 km ahead, and it had none), and the extended track
    stays on the other five."""
    rng = np.random.default_rng(seed)
    p = TrackingPipeline.all_kinds()
    lead_track = None
    for k in range(34):
        t = 5.0 * k
        pos = np.array([[10.0 * t - 60.0 * i, 0.0] for i in range(6)])
        if t > 100.0:
            pos[0, 0] = 1000.0 + 17.0 * (t - 100.0)
        z = pos[rng.random(6) < 0.9]
        z = np.vstack([z + rng.normal(0, 10.0, z.shape), rng.uniform(-2e3, 3e3, (3, 2))])
        conf = p.process(
            Scan("s", t, z, np.tile(R, (len(z), 1, 1)), pd=0.9, clutter_density=1e-7)
        ).confirmed()
        gap = pos[0, 0] - pos[1, 0]
        near = [
            tr for tr in conf if tr.kind == "individual" and np.hypot(*(tr.position - pos[0])) < 50
        ]
        if near and lead_track is None:
            lead_track = gap
    assert lead_track is not None and lead_track <= 450.0
    rest = pos[1:].mean(axis=0)
    ext = [t for t in conf if t.kind == "extended"]
    assert len(ext) == 1 and np.hypot(*(ext[0].position - rest)) < 100.0


def _view_of(xy, v, confirmed):
    from trackers.peers import PointTrackView

    n = len(xy)
    x = np.zeros((n, 5))
    x[:, :2], x[:, 2:4] = xy, v
    return PointTrackView(
        time=0.0,
        ids=tuple(f"T{i}" for i in range(n)),
        x=x,
        P=np.tile(np.diag([100.0, 100.0, 1.0, 1.0, 1e-4]), (n, 1, 1)),
        score=np.zeros(n),
        hits=np.full(n, 5),
        confirmed=np.asarray(confirmed),
        created=np.zeros(n),
        updated=np.zeros(n),
    )


def test_members_velocity_is_the_mean_of_the_tracks_moving_together_in_the_cluster():
    """Three confirmed tracks on a ship's resolved scatterers (noisy velocities about
    (-2.5, -6.5) m/s) and a boat crossing it at 8 m/s east: the boat is left out, the mean is
    the three's, its std the scatter of their velocities over √3."""
    from trackers.extended.tracker import _members_velocity, _PointGates

    xy = np.array([[0, 0], [0, 45], [0, 90], [0, 60]], dtype=float)
    v = np.array([[-1.5, -5.0], [-3.5, -7.0], [-2.5, -7.5], [8.0, 0.0]])
    view = _view_of(xy, v, [True] * 4)
    z = xy + 2.0
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    mean, std = _members_velocity(np.arange(4), _PointGates(view, scan), TrackerConfig().extended)
    np.testing.assert_allclose(mean, [-2.5, -6.5])
    scatter = ((1.0 + 2.25) + (1.0 + 0.25) + (0.0 + 1.0)) / (2 * 2)  # Σ‖vᵢ − v̄‖² / (2 (n − 1))
    assert std == pytest.approx(math.sqrt(scatter / 3))
    # one track, or none, in the cluster: no velocity from the tracks
    one = _members_velocity(np.array([0]), _PointGates(view, scan), TrackerConfig().extended)
    assert one is None
    # as _group_clusters takes them: tracks created since the run began that do not resolve
    # their detection, and tracks not moving with the run, show nothing of its velocity
    young = np.array([[-5.0, 0.0], [-5.0, 15.0], [-5.0, 30.0]])
    xy2 = np.vstack([xy[:3], young])
    v2 = np.vstack([v[:3], np.tile([15.0, 0.0], (3, 1))])
    view2 = _view_of(xy2, v2, [True] * 6)
    view2 = replace(view2, created=np.array([0.0, 0.0, 0.0, 50.0, 50.0, 50.0]))
    z2 = np.vstack([xy2[:3], [[-4.0, 8.0], [-4.0, 22.0]]])
    scan2 = Scan("s", 60.0, z2, np.tile(R, (len(z2), 1, 1)))
    pg2 = _PointGates(view2, scan2)
    cfg = TrackerConfig().extended
    mean2, _ = _members_velocity(np.arange(5), pg2, cfg, 40.0, np.array([-2.5, -6.5]), 3.0)
    np.testing.assert_allclose(mean2, [-2.5, -6.5])
    assert _members_velocity(np.arange(5), pg2, cfg, 40.0, np.array([15.0, 0.0]), 1.0) is None


def test_birth_velocity_weighs_the_centroid_slope_and_the_tracks_by_inverse_variance():
    from trackers.extended.tracker import _birth_velocity

    slope = np.array([-4.6, -20.0])
    v, s = _birth_velocity(slope, 12.0, (np.array([-2.5, -6.5]), 1.0))
    # weights 1/144 and 1/1: v = (slope + 144 v_m) / 145
    np.testing.assert_allclose(v, (slope + 144.0 * np.array([-2.5, -6.5])) / 145.0)
    assert s == pytest.approx(math.sqrt(144.0 / 145.0))
    v, s = _birth_velocity(slope, 12.0, None)
    assert v is slope and s == 12.0
    v, s = _birth_velocity(np.zeros(2), math.inf, (np.array([1.0, 2.0]), 0.5))
    np.testing.assert_allclose(v, [1.0, 2.0])
    assert s == 0.5


def test_a_birth_cluster_keeps_tracks_moving_together_and_leaves_the_others_theirs():
    """Cluster A: detections of three confirmed tracks at 10 m/s east and one at 10 m/s north
    (left to its track), and one no track explains. Cluster B: two tracks moving apart, which
    are no group (both left out), and one free detection."""
    from trackers.extended.tracker import _group_clusters, _PointGates

    xy = np.array([[0, 0], [60, 0], [120, 0], [180, 0], [5000, 0], [5060, 0]], dtype=float)
    v = np.array([[10, 0], [10.5, 0], [9.5, 0], [0, 10], [10, 0], [-10, 0]], dtype=float)
    view = _view_of(xy, v, [True] * 6)
    z = np.vstack([xy + 3.0, [[240.0, 0.0], [5120.0, 0.0]]])
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    pg = _PointGates(view, scan)
    a, b = _group_clusters(
        [np.array([0, 1, 2, 3, 6]), np.array([4, 5, 7])], pg, TrackerConfig().extended
    )
    assert a.tolist() == [0, 1, 2, 6] and b.tolist() == [7]
    # a tentative track explains nothing: its detection stays with the cluster
    view = _view_of(xy, v, [True, True, True, False, True, True])
    (a,) = _group_clusters(
        [np.array([0, 1, 2, 3, 6])], _PointGates(view, scan), TrackerConfig().extended
    )
    assert a.tolist() == [0, 1, 2, 3, 6]


def test_tracks_moving_together_against_their_clusters_run_are_not_its_group():
    """A newcomer's motorway: two confirmed cars of the other carriageway (30 m/s west) pass
    a cluster whose run moves 30 m/s east (run velocity std 5 m/s). They move together, but
    not with the run: their detections are theirs. Moving with it (east), they are the group's.
    """
    from trackers.extended.tracker import _group_clusters, _PointGates

    xy = np.array([[0, 0], [60, 0]], dtype=float)
    z = np.vstack([xy + 3.0, [[120.0, 0.0], [180.0, 0.0], [240.0, 0.0]]])
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    cluster = [np.arange(5)]
    run = (np.array([[30.0, 0.0]]), np.array([5.0]))
    west = _PointGates(_view_of(xy, np.array([[-30.0, 0], [-29.0, 0]]), [True, True]), scan)
    east = _PointGates(_view_of(xy, np.array([[29.0, 0], [30.0, 0]]), [True, True]), scan)
    cfg = TrackerConfig().extended
    assert _group_clusters(cluster, west, cfg)[0].tolist() == [0, 1, 2, 3, 4]  # (no run)
    assert _group_clusters(cluster, west, cfg, None, run)[0].tolist() == [2, 3, 4]
    assert _group_clusters(cluster, east, cfg, None, run)[0].tolist() == [0, 1, 2, 3, 4]


def test_gate_sets_tell_targets_explained_one_to_one_from_an_objects_returns():
    """Sets of confirmed tracks joined by the detections in their gates (10 m of noise,
    99 % gates of about 45 m): a lone track with its detection, two tracks side by side with
    two detections are explained one to one; one track amid
    three returns is not, nor three tracks and three detections strung together (more than
    two: an object's returns)."""
    from trackers.extended.tracker import _PointGates

    xy = np.array(
        [[0, 0], [1000, 0], [1000, 4], [2000, 0], [3000, 0], [4000, 0], [4000, 8], [4000, 16]],
        dtype=float,
    )
    view = _view_of(xy, np.tile([10.0, 0.0], (len(xy), 1)), [True] * len(xy))
    z = np.array(
        [[2, 1], [1001, 0], [999, 5], [2990, 0], [3000, 6], [3010, -3], [4001, 3], [3999, 10]],
        dtype=float,
    )
    z = np.vstack([z, [[4002, 15.0]]])
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    pg = _PointGates(view, scan)
    want = [True, True, True, False, False, False, False, False, False]
    # (the births' mask of explained detections, found before and without the sets' arrays)
    assert _PointGates(view, scan).explained_detections.tolist() == want
    explained = np.zeros(len(z), dtype=bool)
    explained[pg.det[pg.explained]] = True
    assert explained.tolist() == want
    assert pg.explained_detections.tolist() == want  # (and from them, once they are made)
    # (a track with no detection in its gate is not: a coasting member may be absorbed)
    assert pg.explained_tracks.tolist() == [True, True, True, False, False, False, False, False]


@pytest.mark.parametrize("seed", range(6))
def test_explained_detections_are_those_of_the_explained_gate_pairs(seed):
    """Crowded random scenes (tracks and detections a gate or two apart, so that many gate
    pairs share a track or a detection): the births' mask of explained detections is the
    detections of the pairs :attr:`_PointGates.explained` marks."""
    from trackers.extended.tracker import _PointGates

    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 400, (40, 2))
    view = _view_of(xy, np.zeros((40, 2)), rng.uniform(size=40) < 0.8)
    z = np.vstack([xy[:30] + rng.normal(0, 10, (30, 2)), rng.uniform(0, 400, (30, 2))])
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    pg = _PointGates(view, scan)
    fast = _PointGates(view, scan).explained_detections
    want = np.zeros(len(z), dtype=bool)
    want[pg.det[pg.explained]] = True
    assert fast.tolist() == want.tolist()
    assert 0 < want.sum() < len(z)
    assert (np.bincount(pg.det) > 1).any()  # sets of more than one pair were in it


def test_a_birth_leaves_targets_being_acquired_their_detections():
    """Tentative tracks of 3 detections (not confirmed yet) explain detections of a ripe
    cluster one to one: a car alone with its track, two cars side by side, and a car with two
    rival tracks of one start (newcomer motorway replay: seeds 1 and 9 held 0.679 -> 0.709 and
    0.739 -> 0.789 once rivals counted). A track of 2 detections, or one amid three returns,
    leaves the cluster its detections."""
    from trackers.extended.tracker import _not_acquiring

    xy = np.array(
        [[0, 0], [1000, 0], [1000, 4], [2000, 0], [2000, 3], [3000, 0], [4000, 0]], dtype=float
    )
    view = _view_of(xy, np.tile([10.0, 0.0], (len(xy), 1)), [False] * len(xy))
    hits = np.array([3, 3, 3, 3, 4, 2, 3])
    view = replace(view, hits=hits)
    z = np.array(
        [[2, 1], [1001, 0], [999, 5], [2001, 1], [3001, 0], [3995, 0], [4000, 6], [4005, -3]],
        dtype=float,
    )
    scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
    (kept,) = _not_acquiring([np.arange(len(z))], view, scan)
    assert kept.tolist() == [4, 5, 6, 7]


def test_a_platoon_of_resolved_cars_stays_individual_tracks():
    """A newcomer's motorway radar: five cars 50 m apart in one lane at 30 m/s, 1.5 km from
    the radar (5 m in range, 2 mrad in bearing), T = 1 s, P_D 0.9. Each car's confirmed
    track explains its detection one to one, so no extended track forms (before: one
    started at 18 s, took the five tracks and held none of the cars by 33 s)."""
    rng = np.random.default_rng(0)
    p = TrackingPipeline.all_kinds()
    radar = np.array([0.0, -1500.0])
    extended = 0
    for k in range(60):
        cars = np.array([[-600.0 + 30.0 * k - 50.0 * i, -10.0] for i in range(5)])
        seen = cars[rng.random(5) < 0.9]
        d = seen - radar
        rho, theta = np.hypot(*d.T), np.arctan2(d[:, 1], d[:, 0])
        u = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        w = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
        R_k = 25.0 * u[:, :, None] * u[:, None, :] + (0.002 * rho)[:, None, None] ** 2 * (
            w[:, :, None] * w[:, None, :]
        )
        noise = np.einsum("nij,nj->ni", np.linalg.cholesky(R_k), rng.normal(size=(len(seen), 2)))
        confirmed = p.process(Scan("radar", float(k), seen + noise, R_k)).confirmed()
        extended = max(extended, sum(t.kind == "extended" for t in confirmed))
    pos = np.array([t.position for t in confirmed if t.kind == "individual"]).reshape(-1, 2)
    assert extended == 0
    assert all(np.hypot(*(pos - car).T).min() < 15.0 for car in cars)


def test_a_birth_candidate_moves_along_the_least_squares_line_of_its_centroids():
    from trackers.extended.tracker import _Candidate

    run = _Candidate.first((0.0, 0.0), 0.0)
    for t, c in ((5.0, (80.0, 0.0)), (10.0, (40.0, 10.0)), (15.0, (150.0, -10.0))):
        run = run.seen_again(c, t, "r")
    # x through (0, 0), (5, 80), (10, 40), (15, 150): 6 + 8.2 t; y: 3 − 0.4 t
    assert run.velocity == pytest.approx([8.2, -0.4])
    assert run.predicted(20.0) == pytest.approx((6.0 + 8.2 * 20.0, 3.0 - 0.4 * 20.0))
    # σ_v = σ_c / √Σ(τ − τ̄)² = 100 / √125
    assert run.velocity_std(100.0) == pytest.approx(100.0 / math.sqrt(125.0))
    assert _Candidate.first((1.0, 2.0), 3.0).velocity == pytest.approx([0.0, 0.0])


def test_the_resolution_in_force_follows_the_coarsest_recent_sensor():
    cfg = TrackerConfig().extended
    camera = position_noise(np.tile(np.eye(2) * 0.3**2, (5, 1, 1)))
    assert camera == pytest.approx(0.3)
    fine = resolution_in_force(cfg, camera)
    assert fine.resolution_distance == pytest.approx(12.0)
    assert fine.group_speed_spread == pytest.approx(3.0 * 12.0 / 200.0)
    radar = position_noise(np.array([np.diag([5.0**2, 5.0**2]), np.diag([50.0**2, 1.0])]))
    assert resolution_in_force(cfg, radar) is cfg  # 40 sigma above 200 m: as configured
    assert position_noise(np.zeros((0, 2, 2))) is None
    assert resolution_in_force(cfg, None) is cfg
    off = replace(cfg, resolution_noise_factor=0.0)
    assert resolution_in_force(off, camera) is off
    # a radar and a camera on one scene: the radar's noise decides while it reports
    noise = remembered_noise((), "radar", 15.0, 0.0)
    noise = remembered_noise(noise, "camera", camera, 0.5)
    assert max(e[1] for e in noise) == 15.0
    noise = remembered_noise(noise, "camera", None, 30.0)  # an empty batch keeps its entry
    assert [e[0] for e in noise] == ["radar", "camera"]
    noise = remembered_noise(noise, "camera", camera, 61.0)  # the radar is silent 61 s
    assert noise == (("camera", camera, 61.0),)


def _junction(seed: int, false_alarms: int, scans: int = 60):
    """A newcomer's road junction: a radar 350 m south of a 400 m square (1 s, 3 m in range,
    5 mrad), 6 cars on two crossing roads at 8-14 m/s (P_D 0.85) and 6 pedestrians walking
    at 1-1.5 m/s (P_D 0.6), leaving on one side and coming back on the other; false alarms
    uniform over the square; no density stated."""
    rng = np.random.default_rng(seed)
    radar = np.array([0.0, -350.0])
    x = np.zeros((12, 4))
    for k in range(6):
        v = rng.uniform(8.0, 14.0) * rng.choice([-1.0, 1.0])
        along = rng.uniform(-200.0, 200.0)
        x[k] = [along, 4.0 * np.sign(v), v, 0.0] if k % 2 else [-4.0 * np.sign(v), along, 0.0, v]
    x[6:, :2] = rng.uniform(-180.0, 180.0, (6, 2))
    x[6:, 2:] = rng.normal(0.0, 1.0, (6, 2))
    pd = np.array([0.85] * 6 + [0.6] * 6)

    def cov(z):
        d = z - radar
        r, b = np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])
        c, s = np.cos(b), np.sin(b)
        J = np.stack([np.stack([c, -r * s], -1), np.stack([s, r * c], -1)], 1)
        return J @ np.diag([9.0, 25e-6]) @ J.transpose(0, 2, 1)

    for k in range(scans):
        if k:
            x[:6, :2] += x[:6, 2:]
            x[:6, :2] = (x[:6, :2] + 200.0) % 400.0 - 200.0
            x[6:, 2:] += rng.normal(0.0, 0.2, (6, 2))
            x[6:, 2:] *= np.minimum(1.0, 1.5 / np.hypot(*x[6:, 2:].T))[:, None]
            x[6:, :2] += x[6:, 2:]
            x[6:, 2:] *= np.where(np.abs(x[6:, :2]) > 195.0, -1.0, 1.0)
        seen = x[rng.random(12) < pd, :2]
        R = cov(seen)
        noisy = seen + np.array([rng.multivariate_normal([0.0, 0.0], r) for r in R]).reshape(-1, 2)
        z = np.vstack([noisy, rng.uniform(-200.0, 200.0, (false_alarms, 2))])
        yield Scan("radar", float(k), z, cov(z), sensor_position=radar), x[:, :2].copy()


def test_a_radar_alone_in_even_clutter_over_a_small_scene_makes_no_group_of_it():
    """20 false alarms a scan over the junction's 400 m square, no density stated: at the
    3 m radar's resolution in force, 40 sigma, 120 m, its false alarms and targets chain over
    the whole square; one extended track took it all and held the targets 0.01 of the time
    (4 seeds; 0.67 without extended tracking). That cluster is no denser than the scene's
    learned density: no extended track now, the targets held as without one."""
    p = TrackingPipeline.all_kinds(TrackerConfig())
    extended = held = counted = 0
    for k, (scan, truth) in enumerate(_junction(1, 20)):
        confirmed = p.process(scan).confirmed()
        extended += sum(t.kind == "extended" for t in confirmed)
        if k >= 30:
            pos = np.array([t.position for t in confirmed if t.kind == "individual"])
            pos = pos.reshape(-1, 2)
            held += sum(pos.size > 0 and np.hypot(*(pos - x).T).min() < 15.0 for x in truth)
            counted += len(truth)
    assert extended == 0
    assert held / counted > 0.5


def test_only_clusters_standing_out_from_the_clutter_make_runs():
    rows = [np.arange(3), np.arange(3, 7)]
    # a line of 3 (scatter 200/3 m² along it) and a 200 m x 200 m square of 4 corners (scatter
    # 1e4 m² on both axes); sigma 2 m grows each side by 8 m
    z = np.array(
        [[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [1000, 0], [1200, 0], [1000, 200], [1200, 200]],
        dtype=float,
    )
    scan = Scan("r", 0.0, z, np.tile(np.eye(2) * 4.0, (7, 1, 1)))
    line = (np.sqrt(12.0 * 200.0 / 3.0) + 8.0) * 8.0  # 28.3 m x 8 m
    square = (np.sqrt(12.0 * 1e4) + 8.0) ** 2  # 354 m x 354 m
    # at 1e-4 per m² false alarms would put 0.023 and 12.5 detections in them
    assert 3 * 1e-4 * line <= 3 and 3 * 1e-4 * square > 4
    kept = _standing_out(rows, scan, 1e-4, 2.0)
    assert [r.tolist() for r in kept] == [[0, 1, 2]]
    assert _standing_out(rows, scan, None, 2.0) == rows  # no density known: every cluster
    assert len(_standing_out(rows, scan, 1e-6, 2.0)) == 2
    # whatever its heading: the line turned by 45° is kept at the density that just keeps it
    c = math.sqrt(0.5)
    turned = Scan(
        "r", 0.0, z[:3] @ np.array([[c, c], [-c, c]]), np.tile(np.eye(2) * 4.0, (3, 1, 1))
    )
    edge = 3.0 / (3.0 * line) * 0.999
    assert len(_standing_out([np.arange(3)], turned, edge, 2.0)) == 1
    assert len(_standing_out([np.arange(3)], scan, edge, 2.0)) == 1
    # the density about each cluster, where denser than the one given: the line is no group
    # in clutter as dense as itself around it
    here = lambda p: np.where(p[:, 0] < 500.0, 0.5, 1e-6)  # noqa: E731
    assert _standing_out(rows, scan, 1e-6, 2.0, around=here) == [rows[1]]


def _sea_clutter_run(scans: int = 60) -> tuple[int, int]:
    """A radar every 2.5 s (10 m noise) with 400 false alarms a scan within 3 km and 30
    over 40 km x 40 km, no density stated and no target: the extended tracks confirmed, and
    the confirmed tracks of any kind, in the last scan."""
    rng = np.random.default_rng(4)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    for k in range(scans):
        r, a = 3e3 * np.sqrt(rng.uniform(size=400)), rng.uniform(-np.pi, np.pi, 400)
        z = np.vstack(
            [np.column_stack([r * np.cos(a), r * np.sin(a)]), rng.uniform(-2e4, 2e4, (30, 2))]
        )
        res = pipe.process(Scan("r", 2.5 * k, z, np.tile(np.eye(2) * 100.0, (len(z), 1, 1))))
    confirmed = res.confirmed()
    return sum(t.kind == "extended" for t in confirmed), len(confirmed)


def test_sea_clutter_near_a_radar_starts_no_group_tracks():
    """The clutter 3 km about the radar is 60 times denser than its whole scene: weighed
    against the scene, clusters of it started extended tracks that fed on it (7 confirmed
    at the end of this run); against the clutter map's density about them, none."""
    extended, confirmed = _sea_clutter_run()
    assert extended == 0 and confirmed == 0


def _walkers(seed: int, T: float = 0.1, duration: float = 25.0):
    """Eight pedestrians at 1-2 m/s in a 30 m square, turning at random, seen by a camera
    (0.3 m noise, Pd 0.95, 10 Hz) with two false alarms a frame and no stated density."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(5.0, 25.0, (8, 2))
    heading = rng.uniform(0.0, 2 * math.pi, 8)
    speed = rng.uniform(1.0, 2.0, 8)
    for k in range(int(duration / T)):
        turn = rng.random(8) < 0.02
        heading[turn] += rng.choice([-1.0, 1.0], turn.sum()) * math.pi / 2
        out = (p < 2.0) | (p > 28.0)
        heading[out.any(axis=1)] = np.arctan2(*(15.0 - p[out.any(axis=1)]).T[::-1])
        p = p + T * speed[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
        seen = p[rng.random(8) < 0.95]
        z = np.vstack([seen + rng.normal(0.0, 0.3, seen.shape), rng.uniform(0, 30, (2, 2))])
        yield Scan("cam", k * T, z, np.tile(np.eye(2) * 0.09, (len(z), 1, 1)), pd=0.95), p


@pytest.mark.parametrize("factor", [20.0, 0.0])
def test_pedestrians_metres_apart_seen_by_a_camera_stay_individual_tracks(factor):
    """A newcomer's camera scene: with the resolution in force set by the 0.3 m noise (12 m)
    the walkers keep their tracks; and with the radar's 200 m (factor 0) too, since their
    confirmed tracks explain their detections one to one (before that rule, one extended
    track took them all: none of the 8 held, seeds 4-6)."""
    cfg = TrackerConfig().merged({"extended": {"resolution_noise_factor": factor}})
    p = TrackingPipeline.all_kinds(cfg)
    extended = 0
    for scan, now in _walkers(4):
        confirmed = p.process(scan).confirmed()
        extended = max(extended, sum(t.kind == "extended" for t in confirmed))
        truth = now
    pos = np.array([t.position for t in confirmed if t.kind == "individual"]).reshape(-1, 2)
    held = [pos.size and np.hypot(*(pos - x).T).min() < 1.0 for x in truth]
    assert extended == 0 and all(held)


def test_a_ships_own_point_tracks_do_not_starve_its_new_extended_track():
    """A newcomer's ship (150 m x 20 m, 5-11 returns a scan, 10 m noise, T = 1 s): its returns
    confirm point tracks before its extended track starts at 10 s, and those kept the returns
    in their gates from the new track, which was dropped at the next scan with 5 returns
    (seed 16: started again at 22 s, point tracks on the ship until about 60 s). A track its
    own returns started holds nothing back from it. (Confirmed at 13 s: the clutter map,
    which counts the returns no track holds yet as a scene's false alarms, reads 3e-5 per m²
    for this scene without clutter, and the track's updates weigh its returns against that
    since 2026-11-27; at the configured 1e-6, 12 s.)"""
    rng = np.random.default_rng(16)
    p = TrackingPipeline.all_kinds()
    first = None
    for k in range(40):
        n = int(rng.integers(5, 12))
        z = np.array(
            [
                (rng.uniform(-75, 75), rng.uniform(-10, 10), rng.normal(0, 10), rng.normal(0, 10))
                for _ in range(n)
            ]
        )
        z = np.array([3000.0 + 5.0 * k, -2000.0]) + z[:, :2] + z[:, 2:]
        confirmed = p.process(Scan("r3", float(k), z, np.tile(np.eye(2) * 100.0, (n, 1, 1))))
        kinds = [t.kind for t in confirmed.confirmed()]
        if first is None and "extended" in kinds:
            first = k
        if k >= 14:
            assert kinds == ["extended"], (k, kinds)
    assert first is not None and first <= 13


@pytest.mark.parametrize("seed", [0, 2])
def test_two_groups_crossing_keep_their_own_extended_tracks(seed):
    """A newcomer's motorway: twelve cars a carriageway (3 lanes, 4 cars each, staggered 20 m:
    too close for one track a car), 30 m/s each way, seen 1.5 km away (5 m, 2 mrad). Each
    block is an extended track; when they pass each other, each keeps the detections likelier
    under its own gate (before, the first took what it reached of both: seed 0 ended with the
    eastbound block's track 270 m behind it at 18 m/s; these two seeds of six come through
    whole now, four still lose the westbound track's speed in the crossing)."""
    rng = np.random.default_rng(seed)
    radar = np.array([0.0, -1500.0])

    def cars(k: float) -> list[tuple[float, float]]:
        return [
            (-1200 + 30 * k - 60 * i - 20 * lane, -13.7 + 3.7 * lane)
            for lane in range(3)
            for i in range(4)
        ] + [
            (1200 - 30 * k + 60 * i + 20 * lane, 6.3 + 3.7 * lane)
            for lane in range(3)
            for i in range(4)
        ]

    p = TrackingPipeline.all_kinds()
    for k in range(60):
        z, R_k = [], []
        for x, y in cars(k):
            if rng.random() < 0.9:
                dx, dy = x - radar[0], y - radar[1]
                rho = math.hypot(dx, dy) + rng.normal(0, 5.0)
                theta = math.atan2(dy, dx) + rng.normal(0, 0.002)
                z.append(radar + rho * np.array([math.cos(theta), math.sin(theta)]))
        for q in z:
            d = q - radar
            rho, theta = math.hypot(*d), math.atan2(d[1], d[0])
            rot = np.array(
                [[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]]
            )
            R_k.append(rot @ np.diag([25.0, (0.002 * rho) ** 2]) @ rot.T)
        scan = Scan("radar", float(k), np.array(z), np.array(R_k))
        extended = [t for t in p.process(scan).tracks if t.kind == "extended"]
    east, west = np.mean(cars(59)[:12], axis=0), np.mean(cars(59)[12:], axis=0)
    assert len(extended) == 2
    a, b = sorted(extended, key=lambda t: t.velocity[0])
    assert b.velocity[0] > 20.0 and np.hypot(*(np.array(b.position) - east)) < 60.0
    assert a.velocity[0] < -20.0 and np.hypot(*(np.array(a.position) - west)) < 60.0


def _ship_scans(seconds: float = 40.0):
    """A 160 m ship at 5 m/s with five scatterers 40 m apart: radar "a" (every 2 s) sees all
    five, 10 m noise; radar "b" (every 2 s, 1 s after "a") only its middle one."""
    rng = np.random.default_rng(4)
    offsets = np.array([[-80.0, 0.0], [-40.0, 0.0], [0.0, 0.0], [40.0, 0.0], [80.0, 0.0]])
    for k in range(int(seconds)):
        t = float(k)
        centre = np.array([5.0 * t, 0.0])
        sensor, points = ("a", centre + offsets) if k % 2 == 0 else ("b", centre[None, :])
        z = points + rng.normal(0.0, 10.0, points.shape)
        yield Scan(sensor, t, z, np.tile(R, (len(z), 1, 1)))


def test_another_sensors_scan_that_misses_a_birth_run_does_not_break_it():
    """A run of clusters is broken by a scan of the sensor that saw it last and does not see
    it again, not by another sensor's, which may resolve the object's returns otherwise (a
    newcomer's coastal radars: a ship's extended track 36-45 % of the time, its scatterers 2-3
    individual tracks meanwhile; 84-89 % now). Before, every scan of "b" broke the run and
    four individual tracks held the ship for a minute. (17 s: "b", which sees nothing but
    the ship's middle return, learns a dense scene from it, against which that return is
    worth little to the track since its updates weigh detections at the scene's density;
    15 s before.)"""
    from trackers.extended.tracker import _Candidate

    run = _Candidate.first((0.0, 0.0), 0.0, "a")
    assert not run.broken_by("b") and run.broken_by("a")
    assert _Candidate.first((0.0, 0.0), 0.0).broken_by("b")  # sensor not known: as before
    p = TrackingPipeline.all_kinds()
    born = None
    for scan in _ship_scans():
        result = p.process(scan)
        ext = [t for t in result.confirmed() if t.kind == "extended"]
        if ext and born is None:
            born = scan.time
    assert born is not None and born <= 17.0, born
    assert [t.kind for t in result.confirmed()] == ["extended"]  # the one track of the ship


def _started_by_hand(expected: float, seed: int):
    """A pipeline (extended tracks coast up to 1000 s) with one extended track started by
    hand at the origin, standing still, expecting ``expected`` detections a scan."""
    cfg = TrackerConfig().merged({"extended": {"max_coast_time": 1000.0}})
    p = TrackingPipeline.all_kinds(cfg)
    peer = next(q for q in p.peers if q.kind == "extended")
    rng = np.random.default_rng(seed)
    p.process(_cluster_scan(0, rng, np.array([0.0, 0.0]), n=0, clutter=10))
    track = peer.start(
        0.0, [0.0, 0.0], [0.0, 0.0], np.eye(2) * 50.0**2, expected_detections=expected
    )
    return p, peer, track, rng


def test_misses_do_not_lower_an_extended_tracks_expected_count():
    """ΔL(∅) = −γ: learned from the misses too, γ fell by a fifth with each, so the misses of
    a track expecting fewer than 3 detections cost less than delete_drop_from_peak in all, and
    a confirmed track with none coasted on until max_coast_time."""
    p, peer, track, _ = _started_by_hand(2.0, seed=2)
    gone = None
    for k in range(1, 40):
        far = np.array([[-5e3, -5e3], [5e3, 5e3]])  # the radar looks at the track: a miss
        p.process(Scan("radar", 5.0 * k, far, np.tile(R, (2, 1, 1))))
        live = [t for t in peer.tracks if t.id == track.id]
        if live:
            assert live[0].gamma == pytest.approx(2.0)
        elif gone is None:
            gone = k
    # 15 / 2: deleted at the 8th miss
    assert gone == 8


def test_the_expected_count_is_the_poisson_mean_behind_the_scans_with_detections():
    """γ is learned from the scans that gave detections, whose mean is the zero-truncated
    Poisson mean γ / (1 − e^−γ): an object giving 1 detection a scan on average gives
    1.58 in the scans that give any."""
    from trackers.extended.tracker import expected_count, truncated_mean

    assert truncated_mean(1.0) == pytest.approx(1.0 / (1.0 - math.exp(-1.0)))
    assert truncated_mean(0.0) == 1.0 and truncated_mean(30.0) == pytest.approx(30.0)
    for gamma in (0.05, 0.3, 1.0, 2.5, 8.0, 40.0):
        assert expected_count(truncated_mean(gamma)) == pytest.approx(gamma, rel=1e-9)
    assert expected_count(1.0) == 0.0 and expected_count(0.5) == 0.0
    # a track fed 1 or 2 detections a scan (mean 1.5): γ settles where its truncated mean is
    rng = np.random.default_rng(1)
    gamma, means = 3.0, []
    for n in rng.integers(1, 3, 400):  # as the track's update does, with its gain 0.2
        seen = truncated_mean(gamma)
        gamma = expected_count(seen + 0.2 * (n - seen))
        means.append(gamma)
    assert np.mean(means[100:]) == pytest.approx(expected_count(1.5), abs=0.1)  # 0.87


def test_a_state_file_without_run_sensors_reads_as_before():
    from trackers.state import StateSection

    p = TrackingPipeline.all_kinds()
    for scan in _ship_scans(6.0):
        p.process(scan)
    peer = next(q for q in p.peers if q.kind == "extended")
    section = peer.checkpoint().export()
    assert section.values["n_candidates"] >= 1
    old = StateSection(
        section.values,
        {k: v for k, v in section.arrays.items() if not k.startswith("candidates.sensors")},
    )
    fresh = next(q for q in TrackingPipeline.all_kinds().peers if q.kind == "extended")
    fresh.restore_state(fresh.check_state(old))
    assert fresh._state.candidates and all(c.sensor == "" for c in fresh._state.candidates)
    # and a file of this version keeps them
    again = next(q for q in TrackingPipeline.all_kinds().peers if q.kind == "extended")
    again.restore_state(again.check_state(section))
    assert {c.sensor for c in again._state.candidates} == {c.sensor for c in peer._state.candidates}
    assert "" not in {c.sensor for c in again._state.candidates}


def _end_on_ship_scans(seed: int, seconds: float = 300.0, T: float = 2.5):
    """A 300 m ship heading at 7 m/s for a coastal radar 17 km away, 8 scatterers along its
    hull of which a random 3 to 6 are lit each scan (each then seen with P_D 0.9); range
    noise 15 m, bearing noise 3 mrad (51 m across), each detection's covariance stated; 40
    false alarms a scan over 20 km x 20 km. Yields the time, the hull's centre and the scan."""
    rng = np.random.default_rng(seed)
    heading = np.array([0.0, -1.0])
    along = np.linspace(-150.0, 150.0, 8)
    for k in range(int(seconds / T)):
        t = k * T
        centre = np.array([0.0, 17000.0]) + 7.0 * t * heading
        lit = rng.choice(8, rng.integers(3, 7), replace=False)
        lit = lit[rng.random(lit.size) < 0.9]
        clutter = rng.uniform([-10000.0, 0.0], [10000.0, 20000.0], (rng.poisson(40), 2))
        z = np.vstack([centre + along[lit, None] * heading, clutter])
        r = np.hypot(z[:, 0], z[:, 1])
        u = z / r[:, None]
        n = np.stack([-u[:, 1], u[:, 0]], axis=1)
        cross = (0.003 * r)[:, None, None] ** 2 * n[:, :, None] * n[:, None, :]
        cov = 15.0**2 * u[:, :, None] * u[:, None, :] + cross
        z = z + rng.normal(0.0, 15.0, (len(z), 1)) * u
        z = z + rng.normal(0.0, 1.0, (len(z), 1)) * (0.003 * r)[:, None] * n
        yield t, centre, Scan("coast", t, z, cov, pd=0.9)


def test_a_ship_whose_scatterers_the_radar_resolves_gets_one_extended_track():
    """A newcomer's coastal radar: a 300 m ship seen end-on, its scatterers 43 m apart in
    range with 15 m of range noise, is several targets to the point tracker first. Its
    extended track must start all the same and absorb them. Before, confirmed individual
    tracks explained some of its returns one to one in one scan of three or four, which ended
    every birth run before it spanned birth_time, and a track born at last took the slope of
    a centroid jumping along the hull (14 m/s off), so the individual tracks kept the
    returns and starved it: in these three seeds the ship had one extended track in 0.53, 0
    and 0 of its scans after the first minute, and 3-4 individual tracks (4 seeds of 8 were
    fine). Now a run seen in birth_scans scans may miss one, and a new track takes the
    velocity its confirmed individual tracks show, weighed with the slope's: one extended
    track in all their scans, and 0, 0 and 0.68 individual tracks a scan."""
    for seed in (0, 4, 7):
        p = TrackingPipeline.all_kinds()
        one = individual = n = 0
        for t, centre, scan in _end_on_ship_scans(seed):
            conf = p.process(scan).confirmed()
            if t < 60.0:
                continue
            near = [tr for tr in conf if np.hypot(*(np.asarray(tr.position) - centre)) < 200.0]
            n += 1
            one += sum(tr.kind == "extended" for tr in near) == 1
            individual += sum(tr.kind == "individual" for tr in near)
        assert one / n >= 0.95, (seed, one / n)
        assert individual / n <= 1.0, (seed, individual / n)


def test_a_birth_run_seen_birth_scans_times_may_miss_one_scan_of_its_sensor():
    from trackers.extended.tracker import RUN_MISSES, _Candidate

    run = _Candidate.first((0.0, 0.0), 0.0, "a")
    assert run.missed_by("a", 3) is None  # seen once: a miss ends it
    assert run.missed_by("b", 3) is run  # another sensor's scan leaves it
    run = run.seen_again((10.0, 0.0), 2.0, "a")
    assert run.seen == 2 and run.missed_by("a", 3) is None  # seen twice: still ends it
    run = run.seen_again((20.0, 0.0), 4.0, "a")
    assert run.seen == 3
    missed = run.missed_by("a", 3)
    assert missed is not None and missed.missed == RUN_MISSES == 1 and missed.seen == 3
    again = missed.seen_again((40.0, 0.0), 8.0, "a")
    assert again.missed == 1 and again.seen == 4  # the miss counts for the whole run
    assert again.missed_by("a", 3) is None


def test_a_state_file_without_run_misses_reads_as_none_missed():
    from trackers.state import StateSection

    p = TrackingPipeline.all_kinds()
    for scan in _ship_scans(6.0):
        p.process(scan)
    peer = next(q for q in p.peers if q.kind == "extended")
    peer._state = replace(
        peer._state, candidates=tuple(c._replace(missed=1) for c in peer._state.candidates)
    )
    section = peer.checkpoint().export()
    assert section.values["n_candidates"] >= 1
    again = next(q for q in TrackingPipeline.all_kinds().peers if q.kind == "extended")
    again.restore_state(again.check_state(section))
    assert [c.missed for c in again._state.candidates] == [1] * section.values["n_candidates"]
    old = StateSection(
        section.values,
        {k: v for k, v in section.arrays.items() if k != "candidates.missed"},
    )
    fresh = next(q for q in TrackingPipeline.all_kinds().peers if q.kind == "extended")
    fresh.restore_state(fresh.check_state(old))
    assert fresh._state.candidates and all(c.missed == 0 for c in fresh._state.candidates)


def test_one_detection_a_scan_keeps_an_expected_count_of_one():
    """An object giving one detection every scan reads a zero-truncated mean of 1, a Poisson
    mean of 0: the learned γ is held at MIN_LEARNED_GAMMA (1), so its misses still cost 1
    each and the track goes after delete_drop_from_peak (15) of them, not after 50 at the
    floor of 0.3 (or at max_coast_time)."""
    from trackers.extended.tracker import MIN_LEARNED_GAMMA

    p, peer, track, rng = _started_by_hand(3.0, seed=3)
    far = np.array([[-5e3, -5e3], [5e3, 5e3]])  # the radar looks at the track
    for k in range(1, 30):
        z = np.vstack([rng.normal(0.0, 10.0, (1, 2)), far])
        p.process(Scan("radar", 5.0 * k, z, np.tile(R, (3, 1, 1))))
    (live,) = [t for t in peer.tracks if t.id == track.id]
    assert live.gamma == pytest.approx(MIN_LEARNED_GAMMA)
    misses = 0
    while any(t.id == track.id for t in peer.tracks):
        misses += 1
        p.process(Scan("radar", 5.0 * (29 + misses), far, np.tile(R, (2, 1, 1))))
        assert misses < 40
    assert 15 <= misses <= 17


@pytest.mark.parametrize("gate_probability", [0.9999, 0.95])
def test_point_gates_from_the_point_trackers_shared_pairs_are_its_own(gate_probability):
    """A scene of confirmed and tentative tracks amid detections: the gate pairs that
    :class:`_PointGates` takes from the point tracker's view (its own χ² gate, when as wide
    as the 99 % point gate; otherwise it finds its own) are those it finds itself, in the
    same order, and explain the same detections."""
    from trackers.extended.tracker import _PointGates
    from trackers.individual import IndividualTracker

    rng = np.random.default_rng(3)
    cfg = TrackerConfig().merged({"gating": {"gate_probability": gate_probability}})
    tracker = IndividualTracker(cfg)
    truth = rng.uniform(0, 3000, (30, 2))
    for k in range(6):  # targets at 5 m/s east, clutter
        seen = truth + np.array([5.0 * k, 0.0]) + rng.normal(0, 10, truth.shape)
        z = np.vstack([seen, rng.uniform(0, 3000, (20, 2))])
        tracker.step(Scan("s", float(k), z, np.tile(R, (len(z), 1, 1))))
    seen = truth + np.array([30.0, 0.0]) + rng.normal(0, 10, truth.shape)
    z = np.vstack([seen, rng.uniform(0, 3000, (40, 2))])
    scan = Scan("s", 6.0, z, np.tile(R, (len(z), 1, 1)))
    view = tracker.predicted(6.0)
    assert view.gated is not None and view.confirmed.sum() >= 10 and (~view.confirmed).sum() >= 1
    own = replace(view, gated=None)
    for min_hits in (None, 3):
        shared, alone = _PointGates(view, scan, min_hits), _PointGates(own, scan, min_hits)
        for a, b in ((shared.det, alone.det), (shared.trk, alone.trk)):
            assert a.tolist() == b.tolist()
        assert np.allclose(shared.m, alone.m, rtol=1e-12, atol=1e-12)
        assert shared.explained.tolist() == alone.explained.tolist()
        assert len(shared.det) >= 10


def test_gate_sets_of_a_few_shared_pairs_are_those_of_the_labelled_nodes(monkeypatch):
    """The sets of gate pairs that share a detection or a track: the plain loop for a few of
    them gives each pair's set sizes and each track's verdict as the node labels do."""
    import trackers.extended.tracker as tracker
    from trackers.extended.tracker import _PointGates

    rng = np.random.default_rng(11)
    shared = 0
    for trial in range(20):
        xy = rng.uniform(0, 600, (25, 2))
        view = _view_of(xy, np.zeros((25, 2)), rng.random(25) < 0.8)
        z = np.vstack([xy[:15] + rng.normal(0, 8, (15, 2)), rng.uniform(0, 600, (10, 2))])
        scan = Scan("s", 0.0, z, np.tile(R, (len(z), 1, 1)))
        few = _PointGates(view, scan)._sets
        monkeypatch.setattr(tracker, "UNION_FIND_EDGES", 0)
        labelled = _PointGates(view, scan)._sets
        monkeypatch.undo()
        for a, b in zip(few, labelled, strict=True):
            assert a.tolist() == b.tolist(), trial
        shared += bool((few[0] > 1).any() or (few[1] > 1).any())
    assert shared >= 10  # scenes with pairs sharing a node


def _plaza_after(heading: np.ndarray, seed: int = 3):
    """30 people on a grid over 50 m x 30 m walking at 1.3 m/s along ``heading`` (one per
    person), seen for 5 s at 10 Hz with 0.6 m of noise; then a scan with four detections
    scattered among them and five in a corner no person is near. Returns the scan, the point
    tracker's view of it and the rows of the scattered and the cornered detections."""
    rng = np.random.default_rng(seed)
    n = 30
    p = np.stack([np.tile(np.linspace(5, 55, 6), 5), np.repeat(np.linspace(5, 35, 5), 6)], 1)
    v = 1.3 * np.stack([np.cos(heading), np.sin(heading)], 1)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    R_cam = np.eye(2) * 0.36
    for k in range(50):
        p = p + 0.1 * v
        z = p + rng.normal(0, 0.6, p.shape)
        pipe.process(Scan("cam", 0.1 * k, z, np.tile(R_cam, (n, 1, 1))))
    p = p + 0.1 * v
    spread = np.array([[4.0, 36.0], [20.0, 18.0], [38.0, 24.0], [56.0, 3.0]])
    corner = np.array([80.0, 60.0]) + rng.normal(0, 1.0, (5, 2))
    z = np.vstack([p + rng.normal(0, 0.6, p.shape), spread, corner])
    scan = Scan("cam", 5.0, z, np.tile(R_cam, (len(z), 1, 1)))
    view = pipe.point.predicted(scan.time)
    assert int(np.count_nonzero(view.confirmed)) == n
    return scan, view, np.arange(n, n + 4), np.arange(n + 4, n + 9)


def test_a_cluster_among_more_individual_targets_than_its_detections_is_no_group():
    """A camera's plaza: 30 people walking every way, each with a confirmed track. A
    cluster of four detections that no track explains (false alarms, people side by side),
    chained at the resolution distance through the crowd across the plaza, lies among more
    individual targets than it holds: no group (one such cluster became an extended track
    53 m x 37 m that took every person's detections). Five detections in a corner no person
    is near stay a cluster. People walking all one way with the cluster's run are its
    own, not individuals about it: the scattered cluster is kept then."""
    from trackers.extended.tracker import _among_individuals, _PointGates

    rng = np.random.default_rng(3)
    scan, view, scattered, cornered = _plaza_after(rng.uniform(-math.pi, math.pi, 30))
    still = (np.zeros((2, 2)), np.zeros(2))  # the runs' velocities and their stds
    kept = _among_individuals(
        [scattered, cornered], scan, _PointGates(view, scan), 0.6, still, 0.42
    )
    assert kept[0].size == 0
    assert kept[1].tolist() == cornered.tolist()

    scan, view, scattered, _ = _plaza_after(np.full(30, 0.5))
    along = (np.tile(1.3 * np.array([math.cos(0.5), math.sin(0.5)]), (1, 1)), np.full(1, 0.5))
    kept = _among_individuals([scattered], scan, _PointGates(view, scan), 0.6, along, 0.42)
    assert kept[0].tolist() == scattered.tolist()


@pytest.mark.parametrize("learned", [None, 2e-3])
def test_a_group_takes_far_detections_only_where_clutter_is_as_rare_as_configured(learned):
    """A group of four walkers started by hand (camera noise 0.3 m: resolution distance
    12 m) with six unexplained detections strung 7-11 m from it. Where false alarms are as
    rare as configured (1e-6 per m²) each is likelier the group's than clutter, and it takes
    them; where the camera's clutter map learned 2e-3 per m² for its scene (2 false alarms a
    frame over 1,000 m²), scattered detections are what the scene gives anywhere, and the
    group takes none of them. (Its updates had weighed them at the configured density
    whatever the map said, and a camera's group track took a crowd's detections 10-28 m
    away and grew to 60 m x 40 m over it.)"""
    peer = ExtendedTracker()
    # as a birth starts it: its centroid uncertain by half the resolution distance
    peer.start(0.0, [0.0, 0.0], [1.0, 0.0], np.eye(2) * 1.5**2, position_std=6.0)
    own = np.array([[-0.8, -0.6], [0.7, -0.5], [-0.6, 0.8], [0.9, 0.7]])
    far = np.array([[7.0, 1.0], [-8.0, 2.0], [2.0, 9.0], [-3.0, -9.5], [10.5, -4.0], [9.0, 6.0]])
    z = np.vstack([own + np.array([0.1, 0.0]), far])
    scan = Scan(
        "cam",
        0.1,
        z,
        np.tile(np.eye(2) * 0.09, (len(z), 1, 1)),
        tuple(f"own{i}" for i in range(4)) + tuple(f"far{i}" for i in range(6)),
        pd=0.9,
        clutter_scene=learned,
    )
    empty = _view_of(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, dtype=bool))
    (group,) = peer.propose(scan, empty).tracks
    taken = set(group.detection_ids)
    if learned is None:
        assert taken == {f"own{i}" for i in range(4)} | {f"far{i}" for i in range(6)}
    else:  # (its one resolution subset is all or nothing: it coasts this scan)
        assert not taken & {f"far{i}" for i in range(6)}


def _queue_run(seed: int, spacing: float = 8.0) -> tuple[int, float]:
    """Five cars at 15 m/s on one road, 2 s apart, braking at 2 m/s² into a queue ``spacing``
    m apart (centre to centre) at a red light, standing 30 s, then going again; a 1 s radar,
    5 m noise, P_D 0.9, 3 false alarms a scan over 800 m x 800 m, no density stated. Returns
    the scans at which an extended track was confirmed and the share of car-scans held by a
    confirmed individual track within 15 m."""
    rng = np.random.default_rng(seed)
    pipe = TrackingPipeline.all_kinds(TrackerConfig())
    v0, dec, acc, stop = 15.0, 2.0, 1.5, 30.0
    grouped = held = looked = 0
    for t in range(121):
        cars = []
        for i in range(5):
            y_stop, t_stop, t_go = -10.0 - i * spacing, 30.0 + 2.0 * i, 30.0 + stop + 1.5 * i
            if t <= t_stop - v0 / dec:
                y = y_stop - v0 * v0 / (2 * dec) - v0 * (t_stop - v0 / dec - t)
            elif t <= t_stop:
                y = y_stop - 0.5 * dec * (t_stop - t) ** 2
            elif t <= t_go:
                y = y_stop
            else:
                tau = min(t - t_go, v0 / acc)
                y = y_stop + 0.5 * acc * tau * tau + v0 * max(0.0, t - t_go - v0 / acc)
            if -390.0 < y < 390.0:
                cars.append((1.75, y))
        x = np.array(cars).reshape(-1, 2)
        seen = x[rng.random(len(x)) < 0.9]
        z = np.vstack(
            [seen + rng.normal(0, 5.0, seen.shape), rng.uniform(-400, 400, (rng.poisson(3), 2))]
        )
        res = pipe.process(Scan("road", float(t), z, np.tile(25.0 * np.eye(2), (len(z), 1, 1))))
        confirmed = res.confirmed()
        grouped += any(c.kind == "extended" for c in confirmed)
        p = np.array([c.position for c in confirmed if c.kind == "individual"]).reshape(-1, 2)
        for car in x:
            looked += 1
            held += bool(p.size) and float(np.hypot(*(p - car).T).min()) < 15.0
    return grouped, held / looked


def test_a_queue_of_stopped_cars_is_no_group() -> None:
    """Cars queued at a red light move together at 0 m/s: a group born over the queue
    lowered their detection probability and held them (3 runs: an extended track confirmed
    at 38-61 of the 121 scans, car-scans held 0.61-0.68; extended tracking off, 0.85-0.91).
    At rest, moving together is no evidence of a group: none now, held 0.85-0.89."""
    for seed in range(3):
        grouped, held = _queue_run(seed)
        assert grouped == 0 and held >= 0.8
