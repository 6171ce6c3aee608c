"""The tracking step over peers and individual tracks, and its refusal of bad scans."""

import math
from dataclasses import replace

import numpy as np
import pytest

from trackers.config import TrackerConfig
from trackers.peers import PeerError, PeerProposal, ResolutionCell
from trackers.pipeline import TrackingPipeline, check_scan
from trackers.types import Scan, ScanRejected

#: Tracks that start at one detection, so that one scan makes a track to look at.
SINGLE_POINT = TrackerConfig().merged({"initiation": {"method": "single_point"}})


def scan_at(t, points, R=None, **kw):
    z = np.asarray(points, dtype=float).reshape(-1, 2)
    if R is None:
        R = np.tile(25.0 * np.eye(2), (len(z), 1, 1))
    return Scan("r1", float(t), z, R, **kw)


class ScriptedPeer:
    """A peer whose proposal for each scan comes from ``plan(scan, view)``; its state is the
    number of scans it has committed, and it records the views it was shown."""

    def __init__(self, kind, plan):
        self.kind = kind
        self.plan = plan
        self.committed = 0
        self.views = []
        self.config = None

    def propose(self, scan, view):
        self.views.append(view)
        return self.plan(scan, view)

    def commit(self, proposal):
        self.committed += 1

    def snapshot(self):
        return ()

    def reconfigure(self, config):
        self.config = config


def nothing(scan, view):
    return PeerProposal(claimed=np.zeros(scan.size, dtype=bool))


class DiscClaimer(ScriptedPeer):
    """A peer that explains every detection within ``radius`` of ``center`` as its own and
    masks individual targets there (detection probability ``pd_inside``)."""

    def __init__(self, center, radius, pd_inside):
        super().__init__("extended", self._plan)
        self.center = np.asarray(center, dtype=float)
        self.radius = radius
        self.pd_inside = pd_inside

    def _plan(self, scan, view):
        inside = np.linalg.norm(scan.z - self.center, axis=1) <= self.radius
        cell = ResolutionCell(self.center, self.radius**2 * np.eye(2), self.pd_inside)
        return PeerProposal(claimed=inside, cells=(cell,))


def state(p):
    return [(t.id, t.position, t.score, t.status) for t in p.snapshot()]


@pytest.mark.parametrize(
    ("scan", "reason", "text"),
    [
        (scan_at(float("nan"), [0, 0]), "invalid_scan", "time"),
        (scan_at(1.7e18, [0, 0]), "invalid_scan", "time: beyond ±1e+12 s"),
        (scan_at(5.0, [[0, 0], [np.nan, 1]]), "invalid_scan", "detections[1]"),
        (
            scan_at(5.0, [0, 0], R=np.array([[[1.0, 2.0], [2.0, 1.0]]])),
            "invalid_scan",
            "positive definite",
        ),
        (scan_at(5.0, [0, 0], R=np.array([[[1.0, 0.5], [0.4, 1.0]]])), "invalid_scan", "symmetric"),
        (scan_at(5.0, [0, 0], R=np.array([[[np.inf, 0], [0, 1.0]]])), "invalid_scan", "finite"),
        (scan_at(5.0, [[0, 0], [2e9, 0]]), "invalid_scan", "detections[1]: position beyond"),
        (scan_at(5.0, [0, 0], R=np.array([[[1e300, 0], [0, 1e300]]])), "invalid_scan", "entry"),
        (scan_at(5.0, [0, 0], R=np.array([[[1.0, 1e200], [1e200, 1.0]]])), "invalid_scan", "entry"),
        (scan_at(5.0, [0, 0], pd=0.0), "invalid_scan", "pd"),
        (scan_at(5.0, [0, 0], clutter_density=-1.0), "invalid_scan", "clutter_density"),
        (scan_at(0.5, [0, 0]), "out_of_sequence", "older"),
        (scan_at(5.0, [0, 0], sensor_position=[0.0, np.inf]), "invalid_scan", "sensor_position"),
        (
            scan_at(5.0, [0, 0], sensor_position=[0.0, 0.0], sensor_velocity=[np.nan, 1.0]),
            "invalid_scan",
            "sensor_velocity: not finite",
        ),
    ],
)
def test_bad_scans_are_rejected_and_change_nothing(scan, reason, text):
    p = TrackingPipeline(SINGLE_POINT)
    p.process(scan_at(0.0, [[0, 0], [100, 100]]))
    p.process(scan_at(1.0, [[1, 0], [101, 100]]))
    before = state(p)
    with pytest.raises(ScanRejected) as err:
        p.process(scan)
    assert err.value.reason == reason
    assert text in err.value.detail
    assert state(p) == before
    assert p.last_time == 1.0
    p.process(scan_at(2.0, [[2, 0], [102, 100]]))  # and it goes on
    assert p.last_time == 2.0


def test_range_rates_and_amplitudes_are_one_per_detection():
    z, R = np.zeros((2, 2)), np.tile(np.eye(2), (2, 1, 1))
    for name in ("range_rate", "amplitude"):
        with pytest.raises(ScanRejected, match=f"2 detections but 3 {name}s"):
            Scan("s", 0.0, z, R, **{name: np.ones(3)})
    scan = Scan("s", 0.0, z, R, range_rate=[1.0, np.nan], sensor_position=np.zeros(2))
    assert scan.range_rate.shape == (2,) and np.isnan(scan.range_rate[1])
    for name in ("sensor_position", "sensor_velocity"):
        with pytest.raises(ScanRejected, match=f"{name}: must be"):
            Scan("s", 0.0, z, R, **{name: np.ones(3)})


def test_equal_times_are_in_sequence():
    check_scan(scan_at(1.0, [0, 0]), 1.0)


def test_claimed_detections_start_no_individual_track():
    peer = DiscClaimer(center=[0, 0], radius=50.0, pd_inside=0.1)
    p = TrackingPipeline(SINGLE_POINT, peers=[peer])
    res = p.process(scan_at(0.0, [[0, 0], [10, 10], [-20, 5], [500, 500]]))
    assert [t.position for t in res.tracks] == [(500.0, 500.0)]


def test_resolution_cell_changes_individual_detection_probability_and_score():
    cfg = SINGLE_POINT.merged({"track_management": {"pd": 0.9}})
    # A track at (0, 0) is started before the peer exists; then the peer masks it.
    plain = TrackingPipeline(cfg)
    hybrid = TrackingPipeline(cfg, peers=[DiscClaimer(center=[0, 0], radius=50.0, pd_inside=0.2)])
    for p in (plain, hybrid):
        p.point.step(scan_at(0.0, [0, 0]))
    s0 = plain.snapshot()[0].score
    plain.process(scan_at(1.0, np.zeros((0, 2))))
    hybrid.process(scan_at(1.0, np.zeros((0, 2))))
    assert plain.snapshot()[0].score == pytest.approx(s0 + math.log(1 - 0.9))
    assert hybrid.snapshot()[0].score == pytest.approx(s0 + math.log(1 - 0.2))


def test_peer_sees_individual_tracks_predicted_to_the_scan_time_read_only():
    peer = ScriptedPeer("formation", nothing)
    p = TrackingPipeline(SINGLE_POINT, peers=[peer])
    p.point.step(scan_at(0.0, [0, 0]))
    p.point.step(scan_at(1.0, [10, 0]))  # a track moving at about 10 m/s along x
    x1 = p.snapshot()[0].position[0]
    vx = p.snapshot()[0].velocity[0]
    p.process(scan_at(3.0, np.zeros((0, 2))))
    view = peer.views[-1]
    assert view.time == 3.0 and len(view) == 1
    assert view.x[0, 0] == pytest.approx(x1 + 2.0 * vx)
    assert view.x.shape == (1, 5) and view.P.shape == (1, 5, 5)
    with pytest.raises(ValueError):
        view.x[0, 0] = 0.0
    with pytest.raises(ValueError):
        view.P[0, 0, 0] = 0.0


def test_a_failing_second_peer_changes_no_tracker():
    first = ScriptedPeer("extended", nothing)

    def fail(scan, view):
        raise RuntimeError("template lost")

    p = TrackingPipeline(SINGLE_POINT, peers=[first, ScriptedPeer("formation", fail)])
    p.point.step(scan_at(0.0, [[0, 0], [100, 100]]))
    before = state(p)
    with pytest.raises(PeerError) as err:
        p.process(scan_at(1.0, [[1, 0], [101, 100], [500, 500]]))
    assert err.value.kind == "formation"
    assert "template lost" in str(err.value)
    assert first.committed == 0
    assert state(p) == before
    assert p.last_time is None
    # The point tracker has not moved on either: a scan at the same time still goes through.
    p.peers[1].plan = nothing
    p.process(scan_at(1.0, [[1, 0], [101, 100], [500, 500]]))
    assert first.committed == 1
    assert len(p.snapshot()) == 3


@pytest.mark.parametrize(
    ("proposal", "text"),
    [
        (lambda s, v: PeerProposal(claimed=np.zeros(s.size + 1, dtype=bool)), "claimed"),
        (lambda s, v: PeerProposal(claimed=np.zeros(s.size)), "boolean mask"),
        (lambda s, v: {"claimed": np.zeros(s.size, dtype=bool)}, "not a PeerProposal"),
        (lambda s, v: PeerProposal(np.zeros(s.size, dtype=bool), pd={"T999": 0.5}), "T999"),
        (lambda s, v: PeerProposal(np.zeros(s.size, dtype=bool), pd={v.ids[0]: 1.5}), "(0, 1]"),
        (lambda s, v: PeerProposal(np.zeros(s.size, dtype=bool), take=("T999",)), "take"),
        (
            lambda s, v: PeerProposal(np.zeros(s.size, dtype=bool), hand_back=(v.state(0),)),
            "already a live",
        ),
    ],
)
def test_an_ill_formed_proposal_is_an_error_naming_the_peer_and_changes_nothing(proposal, text):
    p = TrackingPipeline(SINGLE_POINT, peers=[ScriptedPeer("extended", proposal)])
    p.point.step(scan_at(0.0, [[0, 0], [100, 100]]))
    before = state(p)
    with pytest.raises(PeerError) as err:
        p.process(scan_at(1.0, [[1, 0], [101, 100]]))
    assert "peer 'extended'" in str(err.value) and text in str(err.value)
    assert state(p) == before


def test_a_peer_sets_the_detection_probability_of_a_named_track():
    cfg = SINGLE_POINT.merged({"track_management": {"pd": 0.9}})

    def lower_t1(scan, view):
        return PeerProposal(claimed=np.zeros(scan.size, dtype=bool), pd={"T1": 0.3})

    p = TrackingPipeline(cfg, peers=[ScriptedPeer("extended", lower_t1)])
    p.point.step(scan_at(0.0, [[0, 0], [1000, 0]]))
    s0 = {t.id: t.score for t in p.snapshot()}
    p.process(scan_at(1.0, np.zeros((0, 2))))
    s1 = {t.id: t.score for t in p.snapshot()}
    assert s1["T1"] == pytest.approx(s0["T1"] + math.log(1 - 0.3))
    assert s1["T2"] == pytest.approx(s0["T2"] + math.log(1 - 0.9))


def test_where_requests_meet_the_lowest_detection_probability_holds():
    cfg = SINGLE_POINT.merged({"track_management": {"pd": 0.9}})
    a = DiscClaimer(center=[0, 0], radius=50.0, pd_inside=0.5)

    def named(scan, view):
        return PeerProposal(claimed=np.zeros(scan.size, dtype=bool), pd={"T1": 0.7})

    p = TrackingPipeline(cfg, peers=[a, ScriptedPeer("formation", named)])
    p.point.step(scan_at(0.0, [0, 0]))
    s0 = p.snapshot()[0].score
    p.process(scan_at(1.0, np.zeros((0, 2))))
    assert p.snapshot()[0].score == pytest.approx(s0 + math.log(1 - 0.5))


class Holder(ScriptedPeer):
    """Takes over track ``tid`` when it first sees it, claims the detections within 50 m of
    it while it holds it (as a formation claims its members'), and hands it back, with its
    hits counting those detections, at the first scan at or after ``back_at``."""

    def __init__(self, tid, back_at):
        super().__init__("formation", self._plan)
        self.tid, self.back_at = tid, back_at
        self.held = None

    def _plan(self, scan, view):
        if self.held == "done":
            return nothing(scan, view)
        if self.held is None:
            if self.tid not in view.ids:
                return nothing(scan, view)
            held, take = view.state(view.index()[self.tid]), (self.tid,)
        else:
            held, take = self.held, ()
        near = np.linalg.norm(scan.z - held.x[:2], axis=1) <= 50.0
        if near.any():
            held = replace(held, hits=held.hits + 1, updated=scan.time)
        held = replace(held, time=scan.time)
        if scan.time >= self.back_at:
            return PeerProposal(claimed=near, take=take, hand_back=(held,), state="done")
        return PeerProposal(claimed=near, take=take, state=held)

    def commit(self, proposal):
        super().commit(proposal)
        self.held = proposal.state


def test_a_peer_takes_over_a_track_and_hands_it_back_under_its_id():
    peer = Holder("T1", back_at=3.0)
    p = TrackingPipeline(SINGLE_POINT, peers=[peer])
    p.point.step(scan_at(0.0, [[0, 0], [1000, 0]]))
    hits0 = {t.id: t.hits for t in p.point.snapshot()}["T1"]
    p.process(scan_at(1.0, [[0, 0], [1000, 0]]))
    assert [t.id for t in p.point.snapshot()] == ["T2"]  # T1 is the peer's now
    assert peer.held.id == "T1"
    p.process(scan_at(2.0, [[1, 0], [1000, 0]]))
    assert [t.id for t in p.point.snapshot()] == ["T2"]  # its detection started nothing
    p.process(scan_at(3.0, [[2, 0], [1000, 0]]))
    assert peer.held == "done"
    back = {t.id: t for t in p.point.snapshot()}
    assert sorted(back) == ["T1", "T2"]
    assert back["T1"].hits == hits0 + 3
    assert back["T1"].updated == 3.0
    assert back["T1"].position == pytest.approx((0.0, 0.0))
    # The individual tracker goes on with it, and never hands out its id again.
    p.process(scan_at(4.0, [[2, 0], [1000, 0], [5000, 5000]]))
    snap = p.point.snapshot()
    assert sorted(t.id for t in snap) == ["T1", "T2", "T3"]
    assert {t.id: t.hits for t in snap}["T1"] == hits0 + 4


def test_snapshots_cannot_change_the_tracker():
    p = TrackingPipeline(SINGLE_POINT)
    res = p.process(scan_at(0.0, [0, 0]))
    snap = res.tracks[0]
    with pytest.raises(ValueError):
        snap.covariance[0, 0] = 1e9
    assert p.snapshot()[0].covariance[0, 0] == pytest.approx(25.0)
    with pytest.raises(ValueError):
        p.point.tracks.x_comb[0, 0] = 1e9


def test_reconfigure_reaches_every_peer():
    peer = ScriptedPeer("extended", nothing)
    p = TrackingPipeline(SINGLE_POINT, peers=[peer])
    new = SINGLE_POINT.merged({"track_management": {"pd": 0.8}})
    p.reconfigure(new)
    assert peer.config == new
    assert p.config == new


def test_two_peers_of_one_kind_are_refused():
    with pytest.raises(ValueError, match="one kind"):
        TrackingPipeline(
            SINGLE_POINT, peers=[ScriptedPeer("x", nothing), ScriptedPeer("x", nothing)]
        )


# -- hand-over between the trackers of neighbouring sectors ---------------------------------


def _crossing(pipeline, times, x0=-4000.0, speed=200.0, y=1000.0):
    for t in times:
        pipeline.process(scan_at(t, [[x0 + speed * t, y]], R=np.tile(400.0 * np.eye(2), (1, 1, 1))))


def test_new_ids_carry_the_instance_prefix():
    p = TrackingPipeline.all_kinds(SINGLE_POINT, id_prefix="west:")
    p.process(scan_at(0.0, [[0.0, 0.0]]))
    assert [s.id for s in p.snapshot()] == ["west:T1"]
    assert {peer.id_prefix for peer in p.peers} == {"west:"}


def test_a_handed_track_is_predicted_to_the_scan_and_updated_under_its_id():
    west = TrackingPipeline.all_kinds(id_prefix="west:")
    _crossing(west, [2.0 * k for k in range(8)])  # to x = -1200 at t = 14
    (track,) = [s for s in west.snapshot() if s.confirmed]
    states = west.point_states([track.id, "west:T999"])  # an unknown id is skipped
    assert [st.id for st in states] == [track.id] and states[0].time == 14.0

    east = TrackingPipeline.all_kinds(id_prefix="east:")
    east.process(scan_at(10.0, [[50000.0, 0.0]]))  # the east has seen nothing of it
    east.hand_in(states)
    east.process(scan_at(18.0, [[-4000.0 + 200.0 * 18.0, 1000.0]]))
    got = {s.id: s for s in east.snapshot()}
    assert track.id in got
    moved = got[track.id]
    assert moved.confirmed and moved.created == track.created
    assert moved.hits == track.hits + 1  # predicted 4 s ahead and updated with the scan
    assert abs(moved.position[0] - (-400.0)) < 60.0
    assert abs(moved.velocity[0] - 200.0) < 20.0

    west.hand_over([track.id])
    west.process(scan_at(18.0, []))
    result_ids = [s.id for s in west.snapshot()]
    assert track.id not in result_ids


def test_a_handed_track_renames_the_local_track_of_the_same_target():
    west = TrackingPipeline.all_kinds(id_prefix="west:")
    east = TrackingPipeline.all_kinds(id_prefix="east:")
    _crossing(west, [2.0 * k for k in range(10)])
    _crossing(east, [2.0 * k for k in range(10)])  # both follow it near the boundary
    (local,) = [s for s in east.snapshot() if s.confirmed]
    assert local.id == "east:T1"
    states = west.point_states([s.id for s in west.snapshot() if s.confirmed])
    east.hand_in(states)
    east.hand_in(states)  # offered twice: taken once
    step = east.process(scan_at(20.0, [[-4000.0 + 200.0 * 20.0, 1000.0]]))
    ids = [s.id for s in east.snapshot()]
    assert ids == ["west:T1"], ids
    assert "east:T1" in step.deleted  # gone under its old id
    # a far track is not merged: it is added beside the local ones
    far = replace(states[0], id="west:T77", x=np.array([30000.0, 0.0, 0.0, 0.0, 0.0]))
    east.hand_in([far])
    east.process(scan_at(22.0, [[-4000.0 + 200.0 * 22.0, 1000.0]]))
    assert sorted(s.id for s in east.snapshot()) == ["west:T1", "west:T77"]


def test_a_rejected_scan_keeps_the_hand_over_for_the_next():
    west = TrackingPipeline.all_kinds(id_prefix="west:")
    _crossing(west, [2.0 * k for k in range(6)])
    states = west.point_states([s.id for s in west.snapshot() if s.confirmed])
    east = TrackingPipeline.all_kinds(id_prefix="east:")
    east.process(scan_at(10.0, []))
    east.hand_in(states)
    with pytest.raises(ScanRejected):
        east.process(scan_at(5.0, []))  # out of sequence
    east.process(scan_at(12.0, []))
    assert [s.id for s in east.snapshot()] == [states[0].id]


def test_a_reset_drops_the_tracks_and_the_time_and_ids_go_on() -> None:
    """``reset``: no track of any kind, scans of any time taken again, and new ids after the
    last one given (a dropped id never comes back)."""
    from clients.scenarios.multitarget import reference_scenario, simulate

    scans = [s.to_scan() for s in simulate(reference_scenario(1))]
    p = TrackingPipeline.all_kinds()
    for scan in scans[:10]:
        p.process(scan)
    before = {t.id for t in p.snapshot()}
    assert before and p.last_time == scans[9].time
    p.reset()
    assert p.snapshot() == () and p.last_time is None
    for scan in scans[:10]:
        p.process(scan)
    after = {t.id for t in p.snapshot()}
    assert after and not after & before
    last = max(int(i[1:]) for i in before if i.startswith("T"))
    assert min(int(i[1:]) for i in after if i.startswith("T")) > last


def test_skip_ids_moves_each_counter_past_the_ids_given_before() -> None:
    """``skip_ids`` (the service's id reservation after a restart): each named tracker gives
    no id below its number, a counter is never moved back, unknown kinds are ignored."""
    from clients.scenarios.multitarget import reference_scenario, simulate

    p = TrackingPipeline.all_kinds()
    assert p.id_counters() == {"individual": 1, "point_patterns": 1, "extended": 1, "formation": 1}
    p.skip_ids({"individual": 500, "extended": 30, "formation": 7, "radar": 9})
    p.skip_ids({"individual": 2, "point_patterns": 3})  # lower: stays at 500
    assert p.id_counters() == {
        "individual": 500,
        "point_patterns": 3,
        "extended": 30,
        "formation": 7,
    }
    for scan in [s.to_scan() for s in simulate(reference_scenario(1))][:5]:
        p.process(scan)
    numbers = sorted(int(t.id[1:]) for t in p.snapshot() if t.id.startswith("T"))
    assert numbers[0] == 500
    assert p.id_counters()["individual"] == numbers[-1] + 1
    extended = next(peer for peer in p.peers if peer.kind == "extended")
    track = extended.start(p.last_time, np.array([9e4, 9e4]), np.zeros(2), np.eye(2) * 400.0)
    assert track.id == "E30" and p.id_counters()["extended"] == 31


def test_a_sensor_position_beyond_the_position_bound_is_refused() -> None:
    """Finite but absurd (1e200 m): its detections' range from it overflowed in the coverage
    learner, whose saved state then failed to restore."""
    z = np.array([[0.0, 0.0]])
    scan = Scan("s", 0.0, z, np.eye(2)[None] * 100.0, sensor_position=np.array([1e200, 0.0]))
    with pytest.raises(ScanRejected, match="sensor_position: beyond"):
        check_scan(scan, None)
    pipe = TrackingPipeline(TrackerConfig())
    with pytest.raises(ScanRejected):
        pipe.process(scan)
    pipe.process(replace(scan, sensor_position=np.array([1e9, 0.0])))  # at the bound: taken
