"""The formation peer (paper 003) in the pipeline: formation, member updates, hand-backs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from clients.scenarios.airspace import (
    Manoeuvre,
    PolarRadar,
    ScriptedScenario,
    ScriptedTarget,
    simulate_scripted,
)
from clients.scenarios.formation import (
    environment_1,
    environment_2,
    run_figures,
    simulate_formations,
)
from trackers.config import TrackerConfig
from trackers.formation.tracker import (
    FormationTracker,
    _joining,
    _match_one,
    _moving_together,
    _new_formation,
    _shared_modes,
    _update,
    member_motion,
)
from trackers.peers import PointTrackView
from trackers.pipeline import TrackingPipeline
from trackers.types import Scan

ON = TrackerConfig().merged({"formation": {"enabled": True}})


def _formation_peer(p: TrackingPipeline) -> FormationTracker:
    peer = next(p for p in p.peers if p.kind == "formation")
    assert isinstance(peer, FormationTracker)
    return peer


def _view(xy: list[tuple[float, float]], v: tuple[float, float], t: float = 0.0) -> PointTrackView:
    n = len(xy)
    x = np.array([[px, py, v[0], v[1], 0.0] for px, py in xy])
    return PointTrackView(
        time=t,
        ids=tuple(f"T{i + 1}" for i in range(n)),
        x=x,
        P=np.tile(np.diag([100.0, 100.0, 4.0, 4.0, 1e-4]), (n, 1, 1)),
        score=np.full(n, 20.0),
        hits=np.full(n, 10),
        confirmed=np.ones(n, dtype=bool),
        created=np.zeros(n),
        updated=np.full(n, t),
    )


def test_tracks_moving_together_become_a_formation_after_its_scans() -> None:
    cfg = ON
    groups: dict = {}
    spread = [(0.0, 0.0), (300.0, 0.0), (600.0, 50.0)]
    for k in range(cfg.formation.confirm_scans):
        t = float(k)
        groups, ripe = _moving_together(_view(spread, (250.0, 0.0), t), cfg, groups, t, set())
        if k < cfg.formation.confirm_scans - 1:
            assert ripe == [] and len(groups) == 1
    assert ripe == [[0, 1, 2]] and groups == {}
    # closer than the resolution distance and no faster than an extended object may be: one
    # unresolved object, never a formation; as close but at 250 m/s: no convoy, resolved
    close = [(0.0, 0.0), (100.0, 0.0), (200.0, 0.0)]
    assert _moving_together(_view(close, (40.0, 0.0)), cfg, {}, 0.0, set()) == ({}, [])
    assert len(_moving_together(_view(close, (250.0, 0.0)), cfg, {}, 0.0, set())[0]) == 1
    off = cfg.merged({"extended": {"enabled": False}})
    assert len(_moving_together(_view(close, (40.0, 0.0)), off, {}, 0.0, set())[0]) == 1
    # too slow, too few, or too far apart
    assert _moving_together(_view(spread, (10.0, 0.0)), cfg, {}, 0.0, set()) == ({}, [])
    assert _moving_together(_view(spread[:2], (250.0, 0.0)), cfg, {}, 0.0, set()) == ({}, [])
    apart = [(0.0, 0.0), (1500.0, 0.0), (3000.0, 0.0)]
    assert _moving_together(_view(apart, (250.0, 0.0)), cfg, {}, 0.0, set()) == ({}, [])


def test_paper_003_environment_1_forms_both_formations_and_holds_every_target() -> None:
    p = TrackingPipeline.all_kinds(ON)
    figures = run_figures(environment_1(seed=0, scans=40), p)
    assert figures.formations_at_end == 2
    assert figures.rate >= 0.99 and figures.rms_position < 40.0
    # the bounds on the velocity error: a formation's common velocity is known better than
    # each member's alone (four members: about half the RMS)
    assert 0.4 < figures.formation_velocity_bound / figures.velocity_bound < 0.6
    tracks = p.snapshot()
    formations = [t for t in tracks if t.kind == "formation"]
    for f in formations:
        assert f.members is not None and len(f.members) >= 3
        members = [t for t in tracks if t.id in f.members]
        assert all(m.kind == "individual" and m.formation_id == f.id for m in members)
        centre = np.mean([m.position for m in members], axis=0)
        assert np.allclose(f.position, centre)
    # the point tracker no longer holds the members
    held = set(p.point.predicted(p.last_time).ids)
    assert not held & {m for f in formations for m in (f.members or ())}


def test_paper_003_environment_2_with_radars_reporting_together_holds_its_targets() -> None:
    """The paper's radars report together (its Z(k)): three batches of one instant. A second
    radar's detection of the instant told nothing of velocity but confirmed two-point tracks
    of a neighbour's or a false alarm's pairing, and of the rival starts that took one
    detection only one kept it while the others took a miss and were deleted, the right
    velocity among them: 0.93 of the target-scans held at (λ1, λ2) = (3, 6), seed 0. Now
    0.99."""
    figures = run_figures(
        environment_2(3, 6, seed=0, scans=60, synchronized=True),
        TrackingPipeline.all_kinds(ON),
    )
    assert figures.rate >= 0.97
    assert figures.false_per_batch <= 0.05


def test_members_fly_the_formations_own_constant_velocity_mode() -> None:
    cfg = TrackerConfig().merged(
        {"formation": {"q_cv": 0.01, "cv_sojourn_time": 500.0, "cv_turn_rate_std": 0.03}}
    )
    m = member_motion(cfg)
    assert (m.q_cv, m.cv_turn_rate_std) == (0.01, 0.03)
    assert m.sojourn_times == (500.0, cfg.motion.sojourn_times[1])  # the turn mode's kept
    assert (m.models, m.q_ct, m.q_turn_rate) == (
        cfg.motion.models,
        cfg.motion.q_ct,
        cfg.motion.q_turn_rate,
    )
    ct_only = TrackerConfig().merged(
        {"motion": {"models": ["ct"], "sojourn_times": [10.0], "initial_mode_probabilities": [1]}}
    )
    assert member_motion(ct_only).sojourn_times == (10.0,)


def test_members_velocity_settles_below_the_individual_trackers() -> None:
    """Environment 1 flies straight: once formed, the members' velocity error (RMS from
    t = 50 s) is under 1.5 m/s, below the individual tracker's on the same detections."""

    def steady(figures, after=50.0):
        v = [e for t, e in figures.rms_velocity_by_time if t >= after]
        return float(np.sqrt(np.mean(np.square(v))))

    scenario = environment_1(seed=1, scans=80)
    formed = steady(run_figures(scenario, TrackingPipeline.all_kinds(ON)))
    alone = steady(run_figures(scenario, TrackingPipeline(TrackerConfig())))
    assert formed < 1.5 and formed < 0.5 * alone, (formed, alone)


def test_a_formations_members_share_one_mode_probability() -> None:
    """μ_f ∝ c̄ Π_i μ_i / c̄_i over the updated members of each formation; a formation
    without an update keeps its prediction."""
    c_bar = np.array([[0.9, 0.1]] * 3 + [[0.5, 0.5]] * 2)  # formation 0: rows 0-2; 1: 3-4
    mu = np.array([[0.6, 0.4], [0.7, 0.3]])  # the posteriors of rows 0 and 2
    out = _shared_modes(c_bar, mu, np.array([0, 2]), np.array([0, 3, 5]))
    assert len(out) == 1 and out[0][0] == slice(0, 3) and out[0][2].size == 0
    w = np.array([0.9, 0.1]) * (mu[0] / c_bar[0]) * (mu[1] / c_bar[2])
    np.testing.assert_allclose(out[0][1], w / w.sum())
    assert out[0][1][1] > 0.7  # two members' evidence for the turn mode outweighs the prior


def test_a_track_moving_with_a_formation_joins_it_after_its_scans() -> None:
    cfg = ON
    members = _view([(0.0, 0.0), (300.0, 0.0), (600.0, 0.0)], (250.0, 0.0))
    f = _new_formation("F1", [0, 1, 2], members, cfg)
    # T1 moves with it 400 m behind; T2 as fast but 40 m/s across; T3 71 m from a member,
    # inside the resolution distance but at 250 m/s no extended object: it joins too; T4 too
    # far
    others = _view([(-400.0, 0.0), (0.0, 500.0), (650.0, 50.0), (0.0, 3000.0)], (250.0, 0.0))
    x = others.x.copy()
    x[1, 3] = 40.0
    others = dataclasses.replace(others, x=x)
    counts: dict = {}
    for k in range(cfg.formation.confirm_scans):
        t = 1.0 * k
        counts, ripe = _joining(others, [f], cfg, counts, t, exclude=set())
        if k < cfg.formation.confirm_scans - 1:
            assert ripe == {} and set(counts) == {("F1", "T1"), ("F1", "T3")}
    assert ripe == {0: [0, 2]} and counts == {}
    # at 40 m/s, T3 so close to a member is one unresolved object with it
    slow = _view([(0.0, 0.0), (300.0, 0.0), (600.0, 0.0)], (40.0, 0.0))
    g = _new_formation("F2", [0, 1, 2], slow, cfg)
    near = _view([(650.0, 50.0)], (40.0, 0.0))
    assert _joining(near, [g], cfg, {}, 0.0, exclude=set()) == ({}, {})
    # a track taken this scan by someone else is not counted
    assert _joining(others, [f], cfg, {}, 0.0, exclude={"T1", "T3"}) == ({}, {})


def test_formations_are_off_by_default() -> None:
    p = TrackingPipeline.all_kinds()
    for sim in simulate_formations(environment_1(seed=0, scans=20)):
        assert not [t for t in p.process(sim.to_scan()).tracks if t.kind == "formation"]


def test_a_member_that_turns_away_is_handed_back_under_its_id() -> None:
    speed = 250.0
    targets = tuple(
        ScriptedTarget(
            "member",
            (-8000.0 + 300.0 * i, 10000.0 + 40.0 * i, speed, 0.0),
            (Manoeuvre(25.0, 20.0, math.radians(3.0)),) if i == 3 else (),
        )
        for i in range(4)
    )
    radars = tuple(
        PolarRadar(
            f"radar-{i + 1}",
            position=pos,
            range_std=40.0,
            bearing_std=2e-3,
            period=1.0,
            time_offset=i / 3.0,
            clutter_mean=0.0,
        )
        for i, pos in enumerate(((-20e3, 0.0), (0.0, -20e3), (20e3, 0.0)))
    )
    scenario = ScriptedScenario(targets, radars, duration=80.0, seed=3)
    p = TrackingPipeline.all_kinds(ON)
    peer = _formation_peer(p)
    member_of_leaver: str | None = None
    for sim in simulate_scripted(scenario):
        result = p.process(sim.to_scan())
        if sim.time < 24.0 and peer.formations:
            f = peer.formations[0]
            x, _ = f.combined()
            d = np.hypot(*(x[:, :2] - sim.truth_states[3, :2]).T)
            member_of_leaver = f.members[int(np.argmin(d))]
    assert member_of_leaver is not None, "no formation formed before the turn"
    f = peer.formations[0]
    assert member_of_leaver not in f.members and len(f.members) >= 2
    mine = [t for t in result.confirmed() if t.id == member_of_leaver]
    assert mine and mine[0].formation_id is None and mine[0].kind == "individual"
    assert np.hypot(*(np.array(mine[0].position) - sim.truth_states[3, :2])) < 300.0


@pytest.mark.parametrize("displaced", [True, False])
def test_a_member_whose_detection_left_its_gate_is_found_and_handed_back(displaced: bool):
    """Three members flying straight at 250 m/s; the third last detected 4 s ago. Its
    detection lies 150 m across its track, out of its gate (the formation flies straight) but
    within the reach of a turn since then: the formation's second look, as a manoeuvring lone
    track, finds it, updates the member with it and marks it departed (handed back). A member
    merely missed, with nothing there, stays."""
    t = 10.0
    view = _view([(0.0, 0.0), (300.0, 0.0), (600.0, 0.0)], (250.0, 0.0), t=t)
    view = dataclasses.replace(view, updated=np.array([t, t, t - 4.0]))
    f = _new_formation("F1", [0, 1, 2], view, ON)
    z = [[0.0, 0.0], [300.0, 0.0]] + ([[600.0, 150.0]] if displaced else [])
    n = len(z)
    scan = Scan(
        sensor_id="r",
        time=t,
        z=np.array(z),
        R=np.tile(np.eye(2) * 400.0, (n, 1, 1)),
        detection_ids=tuple(f"d{i}" for i in range(n)),
    )
    (out,), claimed = _update([f], scan, ON, 0.9, 1e-6)
    assert claimed.all()
    assert out.departed.tolist() == [False, False, displaced]
    x, _ = out.combined()
    if displaced:
        assert out.updated[2] == t and out.detection_ids[2] == ("d2",)
        assert 100.0 < x[2, 1] <= 150.0  # moved to its detection
        assert x[2, 3] > 20.0  # and turned towards it
    else:
        assert out.updated[2] == t - 4.0


def test_a_member_turning_alone_does_not_turn_its_formation() -> None:
    """Three members' modes (constant velocity, turn): two mildly for flying straight, one
    strongly for a turn. The one is left out of the shared product and keeps its own μ."""
    c_bar = np.array([[0.9, 0.1]] * 3)
    mu = np.array([[0.93, 0.07], [0.92, 0.08], [0.05, 0.95]])
    ((sl, mu_f, own),) = _shared_modes(c_bar, mu, np.array([0, 1, 2]), np.array([0, 3]))
    assert sl == slice(0, 3) and own.tolist() == [2]
    w = np.array([0.9, 0.1]) * (mu[0] / c_bar[0]) * (mu[1] / c_bar[1])
    np.testing.assert_allclose(mu_f, w / w.sum())
    # all three turning: one body, every member's evidence counts
    turning = np.array([[0.1, 0.9], [0.15, 0.85], [0.05, 0.95]])
    ((_, mu_f, own),) = _shared_modes(c_bar, turning, np.array([0, 1, 2]), np.array([0, 3]))
    assert own.size == 0 and mu_f[1] > 0.999


def test_a_formation_asked_for_by_ids_is_formed_at_the_next_scan() -> None:
    cfg = ON.merged({"formation": {"min_speed": 1e4}})  # none forms by itself
    p = TrackingPipeline.all_kinds(cfg)
    peer = _formation_peer(p)
    sims = simulate_formations(environment_1(seed=1, scans=15))
    for sim in sims[:30]:
        p.process(sim.to_scan())
    view = p.point.predicted(p.last_time)
    confirmed = [tid for tid, c in zip(view.ids, view.confirmed, strict=True) if c]
    p_of = {tid: view.x[i, :2] for i, tid in enumerate(view.ids)}
    far = [t for t in confirmed if np.hypot(*(p_of[t] - p_of[confirmed[0]])) > 5000.0]
    confirmed = [t for t in confirmed if t not in far]  # one formation's members
    assert len(confirmed) >= 3 and far
    with pytest.raises(ValueError, match="at least 2"):
        peer.request(confirmed[:1], view)
    with pytest.raises(ValueError, match="twice"):
        peer.request([confirmed[0], confirmed[0]], view)
    with pytest.raises(ValueError, match="no live individual track 'T999'"):
        peer.request([confirmed[0], "T999"], view)
    # A newcomer's formation of a jet and a tentative track on a ship 4.5 km away.
    small = _view([(0.0, 0.0), (300.0, 0.0), (4500.0, 0.0)], (200.0, 0.0), p.last_time)
    small = dataclasses.replace(small, confirmed=np.array([True, False, True]))
    with pytest.raises(ValueError, match="track 'T2' is tentative, not confirmed"):
        peer.request(["T1", "T2"], small)
    with pytest.raises(ValueError, match="'T1' and 'T3' are 4500 m apart and no chain"):
        peer.request(["T1", "T3"], small)
    with pytest.raises(ValueError, match=r"no chain of members closer than formation\.max_spac"):
        peer.request([confirmed[0], far[0]], view)
    snap = peer.request(confirmed[:2], view)
    assert snap.kind == "formation" and snap.members == tuple(confirmed[:2])
    with pytest.raises(ValueError, match="already in formation"):
        peer.request([confirmed[1], confirmed[2]], view)
    assert peer.formations == ()
    p.process(sims[30].to_scan())
    assert [f.members for f in peer.formations] == [tuple(confirmed[:2])]
    assert not set(confirmed[:2]) & set(p.point.predicted(p.last_time).ids)


def test_switching_formations_off_hands_every_member_back() -> None:
    p = TrackingPipeline.all_kinds(ON)
    sims = simulate_formations(environment_1(seed=0, scans=30))
    for sim in sims[:-3]:
        p.process(sim.to_scan())
    peer = _formation_peer(p)
    members = {m for f in peer.formations for m in f.members}
    assert members
    p.reconfigure(TrackerConfig())
    result = p.process(sims[-3].to_scan())
    assert peer.formations == ()
    assert set(result.deleted) >= {"F1", "F2"} or not [
        t for t in result.tracks if t.kind == "formation"
    ]
    live = set(p.point.predicted(p.last_time).ids)
    assert members <= live


def test_members_handed_back_by_switching_formations_off_go_on_being_updated() -> None:
    """The members are handed back at the scan's time, not where the formation's last update
    left them (a newcomer's three jets at 200 m/s, T = 1 s: handed back 200 m behind, never
    updated again, doubled by new tracks and deleted)."""
    p = TrackingPipeline.all_kinds(ON)
    rng = np.random.default_rng(1)
    slots = np.array([[0.0, 0.0], [400.0, 0.0], [200.0, 350.0]])
    v = np.array([200.0, 0.0])
    R = np.tile(np.eye(2) * 20.0**2, (3, 1, 1))
    members: set[str] = set()
    for k in range(60):
        if k == 40:
            members = {m for f in _formation_peer(p).formations for m in f.members}
            assert len(members) == 3
            p.reconfigure(TrackerConfig())
        truth = slots + v * k
        result = p.process(Scan("r", float(k), truth + rng.normal(0.0, 20.0, (3, 2)), R))
        if k >= 40:
            confirmed = [t for t in result.confirmed() if t.kind == "individual"]
            assert {t.id for t in confirmed} == members  # none lost, none doubled
            for t in confirmed:
                d = np.hypot(*(truth - np.asarray(t.position)).T)
                assert d.min() < 80.0, (k, t.id, d.min())
                assert k - t.updated <= 1.0


@pytest.mark.parametrize("turn", [0.1, 0.15, 0.2])
def test_a_formation_turned_since_its_prediction_matches_every_member(turn):
    """Four members in line (±300 m, ±900 m) whose detections have turned about the centre
    since the prediction: the outer ones lie beyond the miss cost of every predicted member
    (135-180 m at 0.15-0.2 rad), yet within reach of the turned templates, which are tried
    and match all four."""
    zhat = np.array([[-900.0, 0.0], [-300.0, 0.0], [300.0, 0.0], [900.0, 0.0]])
    c, s = np.cos(turn), np.sin(turn)
    Z = zhat @ np.array([[c, -s], [s, c]]).T
    cov = np.tile(800.0 * np.eye(2), (4, 1, 1))
    vel = np.tile([200.0, 0.0], (4, 1))
    assign = _match_one(zhat, cov, vel, Z, cov, 9.21)
    assert assign.tolist() == [0, 1, 2, 3]
