import numpy as np
import pytest

from trackers.association.manoeuvre import (
    ALONG_TRACK_FRACTION,
    at_rest,
    manoeuvre_covariance,
    manoeuvre_search,
    reaches_beyond,
)
from trackers.config import TrackerConfig
from trackers.individual import IndividualTracker
from trackers.types import Scan


def test_covariance_worked_example_along_x():
    # v = (100, 0), τ = 2 s, a = min(50, 0.1 · 100) = 10 m/s²: A = 100/3 diag(κ², 1).
    Q = manoeuvre_covariance(np.array([[100.0, 0.0]]), np.array([2.0]), 50.0, 0.1)[0]
    across = 100.0 / 3.0
    along = across * ALONG_TRACK_FRACTION**2
    expected = np.zeros((5, 5))
    expected[0, 0], expected[0, 2], expected[2, 2] = along * 4.0, along * 4.0, along * 4.0
    expected[1, 1], expected[1, 3], expected[3, 3] = across * 4.0, across * 4.0, across * 4.0
    expected[2, 0], expected[3, 1] = expected[0, 2], expected[1, 3]
    np.testing.assert_allclose(Q, expected, rtol=1e-12, atol=1e-12)


def test_covariance_turns_with_the_velocity_and_is_capped():
    v = np.array([[300.0, 400.0], [0.0, 0.0]])  # 500 m/s: a = min(50, 0.1 · 500) = 50
    Q = manoeuvre_covariance(v, np.array([4.0, 4.0]), 50.0, 0.1)
    u, n = np.array([0.6, 0.8]), np.array([-0.8, 0.6])
    A = 2500.0 / 3.0 * (np.outer(n, n) + ALONG_TRACK_FRACTION**2 * np.outer(u, u))
    np.testing.assert_allclose(Q[0, 0:2, 0:2], A * 4.0**4 / 4.0, rtol=1e-12)
    np.testing.assert_allclose(Q[0, 2:4, 2:4], A * 16.0, rtol=1e-12)
    assert (Q[0, 4] == 0).all() and (Q[0, :, 4] == 0).all()
    assert (Q[1] == 0).all()  # a parked target cannot turn: no search at all


def test_covariance_of_an_agile_target_across_the_track():
    # A 40 m/s drone pulling 12 m/s² turns at 0.3 rad/s: a = 0.3 · 40 = 12 m/s² across the
    # track instead of 0.1 · 40 = 4, within one radian over τ (τ = 20 s: 0.05 -> ω_max).
    v, tau = np.array([[40.0, 0.0], [40.0, 0.0], [250.0, 0.0]]), np.array([2.0, 20.0, 2.0])
    plain = manoeuvre_covariance(v, tau, 50.0, 0.1)
    agile = manoeuvre_covariance(v, tau, 50.0, 0.1, agile=12.0)
    across = np.array([12.0, 4.0, 25.0]) ** 2 / 3.0 * tau**4 / 4.0
    np.testing.assert_allclose(agile[:, 1, 1], across, rtol=1e-12)
    np.testing.assert_allclose(agile[1:], plain[1:], rtol=1e-12)  # long τ, fast: as before
    assert agile[0, 1, 1] == pytest.approx(9.0 * plain[0, 1, 1])


def _one_track(speed):
    """One CV/CT track at the origin flying along x, predicted 4 s since its last update."""
    x = np.zeros((1, 2, 5))
    x[0, :, 2] = speed
    P = np.tile(np.diag([400.0, 400.0, 25.0, 25.0, 1e-4]), (1, 2, 1, 1))
    return x, P, np.array([[0.9, 0.1]]), x[:, 0], P[:, 0]


def _search(speed, z, clutter_density, tau=4.0):
    x, P, c_bar, xc, Pc = _one_track(speed)
    return manoeuvre_search(
        x, P, c_bar, xc, Pc, np.array([tau]), np.asarray(z, float),
        np.tile(400.0 * np.eye(2), (len(z), 1, 1)), np.array([0.9]), clutter_density,
        a_max=50.0, omega_max=0.1, straight_sojourn=30.0, gamma=18.4,
    )  # fmt: skip


def test_search_takes_a_turning_target_across_the_track_in_sparse_clutter():
    # 250 m/s turning at 4°/s: 140 m across after 4 s, far outside the 20 m gate.
    found = _search(250.0, [[0.0, 140.0], [0.0, -900.0]], 1e-9)
    assert found is not None
    assert found.detection.tolist() == [0]
    assert found.x[0, :, 1] == pytest.approx(140.0, abs=25.0)
    assert (found.x[0, :, 3] > 30.0).all()  # the velocity turns towards it


def test_search_takes_nothing_along_the_track_in_dense_clutter_or_when_slow():
    assert _search(250.0, [[400.0, 0.0]], 1e-9) is None  # 400 m along: no turn gets there
    assert _search(250.0, [[0.0, 140.0]], 1e-4) is None  # clutter likelier than a manoeuvre
    assert _search(5.0, [[0.0, 140.0]], 1e-9) is None  # 5 m/s cannot turn 140 m in 4 s


#: The false-alarm density of the turning-target runs: sparse enough that the search's gain
#: for the detection after the missed scan is clearly positive. At 1e-9 it was +0.07 with
#: 30/10 s sojourn times and below 0 with 60/20 s (a turn's onset half as likely a priori),
#: a knife's edge these tests are not about.
CLUTTER = 1e-10


def test_search_keeps_the_speed_of_a_turn_and_refuses_a_false_alarm_km_across():
    """A 236 m/s aircraft coasting 20 s (two misses at a 10 s revisit), the straight-line
    prediction at the origin. A 90° turn at 0.0785 rad/s puts it 1715 m short and 3005 m
    across: taken (the update's speed stays within the along-track allowance). A false alarm
    6 km across is as likely under the manoeuvre's Gaussian (2.2 sigma across) but asks the
    speed to double: refused, even in clutter this sparse (a newcomer's ATC radar, where such
    a track went on at 1,000-2,000 m/s)."""
    turn = _search(236.0, [[-1715.0, 3005.0]], 1e-12, tau=20.0)
    assert turn is not None and turn.detection.tolist() == [0]
    speed = np.hypot(*np.einsum("km,kmi->ki", turn.mu, turn.x[:, :, 2:4])[0])
    assert 236.0 < speed < 236.0 + 165.0
    assert _search(236.0, [[0.0, 6000.0]], 1e-12, tau=20.0) is None


def test_the_speed_test_allows_for_the_detections_own_noise():
    """A holding aircraft at 124 m/s, 150 km from a radar of 1.5 mrad (225 m across the
    beam, here along its track), found again 10 s after its last update: the update's speed
    of 187 m/s is the detection's noise over 10 s (45 m/s a sigma), and is kept; the same
    change from a detection of 20 m noise is no turn's."""
    from trackers.association.manoeuvre import _speed_kept

    x = np.zeros((1, 2, 5))
    x[0, :, 2] = 187.0
    mu = np.array([[0.9, 0.1]])
    xc = np.zeros((1, 5))
    xc[0, 2] = 124.0
    Pc = np.diag([400.0, 400.0, 25.0, 25.0, 1e-4])[None]
    tau = np.array([10.0])
    wide, narrow = np.diag([225.0**2, 100.0**2])[None], (400.0 * np.eye(2))[None]
    assert _speed_kept(x, mu, xc, Pc, wide, tau, 50.0, 0.1, 700.0).tolist() == [True]
    assert _speed_kept(x, mu, xc, Pc, narrow, tau, 50.0, 0.1, 700.0).tolist() == [False]


def _turning_target_ids(a_max, range_rates=False, velocity_errors=None):
    """A 250 m/s target seen every 4 s turns at 0.12 rad/s (3 g) from scan 11; scan 12 is
    missed. The ids of the confirmed tracks from scan 8 on. With ``range_rates``, each
    detection has its range-rate from a sensor 20 km south (1 m/s noise); the velocity errors
    of the confirmed tracks go into ``velocity_errors`` by scan."""
    sensor = np.array([0.0, -20e3])
    tracker = IndividualTracker(
        TrackerConfig().merged(
            {
                "gating": {"manoeuvre_acceleration": a_max},
                "track_management": {"clutter_density": CLUTTER},
            }
        )
    )
    rng = np.random.default_rng(0)
    p, heading, omega, sigma = np.zeros(2), 0.0, 0.12, 20.0
    ids = []
    for k in range(25):
        if k > 0:
            turning = k > 10
            if turning:
                new_heading = heading + omega * 4.0
                p = p + 250.0 / omega * np.array(
                    [np.sin(new_heading) - np.sin(heading), np.cos(heading) - np.cos(new_heading)]
                )
                heading = new_heading
            else:
                p = p + 1000.0 * np.array([np.cos(heading), np.sin(heading)])
        z = np.zeros((0, 2)) if k == 12 else (p + rng.normal(0, sigma, 2))[None]
        v = 250.0 * np.array([np.cos(heading), np.sin(heading)])
        extra = {}
        if range_rates:
            rdot = (p - sensor) @ v / np.hypot(*(p - sensor)) + rng.normal(0.0, 1.0, len(z))
            extra = {"sensor_position": sensor, "range_rate": rdot}
        result = tracker.step(
            Scan("r", 4.0 * k, z, np.tile(sigma**2 * np.eye(2), (len(z), 1, 1)), **extra)
        )
        if k >= 8:
            ids.append(tuple(t.id for t in result.confirmed()))
        if velocity_errors is not None:
            velocity_errors[k] = [
                float(np.hypot(*(np.array(t.velocity) - v))) for t in result.confirmed()
            ]
    return ids


def test_a_track_follows_its_target_into_a_turn_through_a_missed_detection():
    assert set(_turning_target_ids(50.0)) == {("T1",)}
    without = _turning_target_ids(0.0)
    assert ("T1",) in without and () in without  # lost without the search


def test_the_range_rate_of_a_detection_found_by_the_search_updates_the_track():
    """Scan 13, after the missed scan 12 in the turn, is the search's: with range-rates the
    track's velocity there is nearer the truth."""
    plain: dict = {}
    doppler: dict = {}
    assert set(_turning_target_ids(50.0, velocity_errors=plain)) == {("T1",)}
    assert set(_turning_target_ids(50.0, True, velocity_errors=doppler)) == {("T1",)}
    assert doppler[13][0] < 0.7 * plain[13][0], (doppler[13], plain[13])


def test_reaches_beyond_compares_the_manoeuvre_with_the_track_uncertainty() -> None:
    """(a²/3)(τ⁴/4) against REACH_FRACTION² λ_max: a 250 m/s aircraft (a = 25 m/s² with
    ω_max 0.1) lost for 8 s has an across-track std of 460 m, beyond half its 100 m; a parked car
    has none (a = 0), and the aircraft a second after its last detection 7 m."""
    x = np.zeros((3, 5))
    x[0, 2] = x[2, 2] = 250.0
    P = np.tile(np.diag([100.0**2, 100.0**2, 25.0, 25.0, 1e-4]), (3, 1, 1))
    tau = np.array([8.0, 8.0, 1.0])
    out = reaches_beyond(x, P, tau, a_max=50.0, omega_max=0.1)
    np.testing.assert_array_equal(out, [True, False, False])


def test_covariance_with_a_change_of_speed_along_the_track():
    """``a_u = max(κ a_n, a_speed)`` along the velocity: v = (100, 0), τ = 2 s, a_n = 10 m/s²
    across; a_speed 3 m/s² beats κ a_n = 2 along, 1 does not; at rest, a_u in every
    direction."""
    v, tau = np.array([[100.0, 0.0]]), np.array([2.0])
    Q = manoeuvre_covariance(v, tau, 50.0, 0.1, a_speed=3.0)[0]
    assert Q[0, 0] == pytest.approx(9.0 / 3.0 * 2.0**4 / 4.0)  # along x: a_u² / 3 · τ⁴ / 4
    assert Q[2, 2] == pytest.approx(9.0 / 3.0 * 2.0**2)
    assert Q[1, 1] == pytest.approx(100.0 / 3.0 * 2.0**4 / 4.0)  # across: a_n unchanged
    np.testing.assert_allclose(
        manoeuvre_covariance(v, tau, 50.0, 0.1, a_speed=1.0),
        manoeuvre_covariance(v, tau, 50.0, 0.1),
    )
    slow = np.array([[0.5, 0.0]])  # a_n = 0.05 across
    Q = manoeuvre_covariance(slow, tau, 50.0, 0.1, a_speed=3.0, rest=np.array([True]))[0]
    np.testing.assert_allclose(Q[0:2, 0:2], 3.0 * 4.0 * np.eye(2), rtol=1e-12)
    Q = manoeuvre_covariance(slow, tau, 50.0, 0.1, a_speed=3.0, rest=np.array([False]))[0]
    assert Q[1, 1] < 0.01 * Q[0, 0]


def test_at_rest_is_a_speed_within_two_standard_deviations_of_zero():
    v = np.array([[1.0, 1.0], [3.0, 0.0], [0.0, 0.0]])
    P_v = np.tile(np.diag([1.0, 0.25]), (3, 1, 1))  # λ_max 1: |v| ≤ 2
    np.testing.assert_array_equal(at_rest(v, P_v), [True, False, True])


def test_reaches_beyond_with_a_change_of_speed():
    """A parked car (a_n = 0) lost for 8 s: a start at 3 m/s² reaches 55 m (std), beyond half
    its 10 m."""
    x = np.zeros((1, 5))
    P = np.diag([100.0, 100.0, 1.0, 1.0, 1e-4])[None]
    tau = np.array([8.0])
    assert not reaches_beyond(x, P, tau, a_max=50.0, omega_max=0.1)[0]
    assert reaches_beyond(x, P, tau, a_max=50.0, omega_max=0.1, a_speed=3.0)[0]


def _search_from_rest(z, clutter_density, a_speed=3.0):
    """A track at rest at the origin (2 m position std, 1 m/s velocity std), 4 s since its
    last update, searched for a start at ``a_speed`` where fewer than 0.1 false alarms are
    expected (detections of 2 m std)."""
    x = np.zeros((1, 2, 5))
    P = np.tile(np.diag([4.0, 4.0, 1.0, 1.0, 1e-4]), (1, 2, 1, 1))
    return manoeuvre_search(
        x, P, np.array([[0.9, 0.1]]), x[:, 0], P[:, 0], np.array([4.0]), np.asarray(z, float),
        np.tile(4.0 * np.eye(2), (len(z), 1, 1)), np.array([0.9]), clutter_density,
        a_max=50.0, omega_max=0.1, straight_sojourn=30.0, gamma=18.4, a_speed=a_speed,
        quiet=0.1,
    )  # fmt: skip


def test_search_finds_a_target_setting_off_from_rest_where_few_false_alarms_are():
    """20 m off after 4 s (2.5 m/s² from rest), outside the 12 m gate of the track at rest:
    found at 1e-6 false alarms per m² (the start's gate, S ≈ 200 m², expects 0.01); not at
    1e-5 (0.12: searched for a turn alone, which a track at rest cannot make), nor without
    a change of speed; the updated speed is a start's, about 10 m/s."""
    found = _search_from_rest([[20.0, 0.0]], 1e-6)
    assert found is not None and found.detection.tolist() == [0]
    speed = np.hypot(*np.einsum("km,kmi->ki", found.mu, found.x[:, :, 2:4])[0])
    assert 5.0 < speed < 15.0
    assert _search_from_rest([[20.0, 0.0]], 1e-5) is None
    assert _search_from_rest([[20.0, 0.0]], 1e-6, a_speed=0.0) is None
    # Per detection: a quiet one is found beside a crowded one.
    found = _search_from_rest([[0.0, -20.0], [20.0, 0.0]], np.array([1e-5, 1e-6]))
    assert found is not None and found.detection.tolist() == [1]


def _two_tracks_search(z, clutter_density, a_speed, quiet=0.1):
    """Track 0, far off and 1 s since its update, whose manoeuvre stays inside its gate (not
    searched), and track 1, a 20 m/s track along x (2 m position std, 1 m/s velocity std)
    4 s after its last update; detections of 2 m std."""
    P0 = np.diag([1e4, 1e4, 1.0, 1.0, 1e-4])
    P1 = np.diag([4.0, 4.0, 1.0, 1.0, 1e-4])
    x = np.zeros((2, 2, 5))
    x[0, :, :2] = 5e3
    x[1, :, 2] = 20.0
    P = np.stack([np.tile(P0, (2, 1, 1)), np.tile(P1, (2, 1, 1))])
    return manoeuvre_search(
        x, P, np.array([[0.9, 0.1]] * 2), x[:, 0], P[:, 0], np.array([1.0, 4.0]),
        np.asarray(z, float), np.tile(4.0 * np.eye(2), (len(z), 1, 1)), np.array([0.9, 0.9]),
        clutter_density, a_max=50.0, omega_max=0.1, straight_sojourn=30.0, gamma=18.4,
        a_speed=a_speed, quiet=quiet,
    )  # fmt: skip


def test_where_the_search_is_crowded_a_pair_is_one_of_a_turn_exactly_as_before():
    """15 m across the prediction (a 2 m/s² turn) at 2e-5 false alarms per m², where the
    change of speed's gate is crowded: the same match, state and gain as without a change of
    speed. 24 m ahead (3 m/s² faster, no turn gets there): found where quiet (2e-6), not
    where crowded, found there too when no bound is set."""
    turn = [[0.0, 15.0]]
    old, new = _two_tracks_search(turn, 2e-5, 0.0), _two_tracks_search(turn, 2e-5, 3.0)
    assert old is not None and new is not None
    assert new.track.tolist() == old.track.tolist() == [1]
    for field in ("x", "P", "mu", "hit"):
        np.testing.assert_allclose(getattr(new, field), getattr(old, field), rtol=1e-12)
    ahead = [[24.0, 0.0]]
    found = _two_tracks_search(ahead, 2e-6, 3.0)
    assert found is not None and found.track.tolist() == [1]
    assert _two_tracks_search(ahead, 2e-5, 3.0) is None
    assert _two_tracks_search(ahead, 2e-5, 3.0, quiet=np.inf) is not None


def test_the_change_of_speed_is_at_most_the_manoeuvre_acceleration():
    v, tau = np.array([[10.0, 0.0]]), np.array([2.0])
    capped = manoeuvre_covariance(v, tau, 5.0, 0.1, a_speed=1e4)
    np.testing.assert_allclose(capped, manoeuvre_covariance(v, tau, 5.0, 0.1, a_speed=5.0))


def _tracker_sees_a_start_from_rest(clutter_density, a_speed=3.0):
    """A confirmed track of a target at rest 1 km out (2 m detection std, T = 4 s), whose
    target is then seen 35 m off, beyond its gate: the track's position after that scan."""
    config = TrackerConfig().merged({"gating": {"manoeuvre_speed_change": a_speed}})
    tracker = IndividualTracker(config)
    R = np.tile(4.0 * np.eye(2), (1, 1, 1))
    rng = np.random.default_rng(3)
    for k in range(10):
        z = np.array([[1000.0, 0.0]]) + rng.normal(0.0, 2.0, (1, 2))
        tracker.step(Scan("r", 4.0 * k, z, R, clutter_density=clutter_density))
    result = tracker.step(
        Scan("r", 40.0, np.array([[1000.0, 35.0]]), R, clutter_density=clutter_density)
    )
    (track,) = [t for t in result.tracks if t.id == "T1"]
    return track.status, np.asarray(track.position)


def test_the_tracker_looks_for_a_start_from_rest_only_where_the_search_is_quiet():
    """At 1e-7 false alarms per m² the track follows its target off (the search for a start
    expects about 0.001 false alarms); at 2e-5 (0.1 and more) it stays, missed, and so it
    does without the change of speed."""
    status, position = _tracker_sees_a_start_from_rest(1e-7)
    assert status == "confirmed" and position[1] > 25.0
    status, position = _tracker_sees_a_start_from_rest(2e-5)
    assert status == "confirmed" and abs(position[1]) < 5.0
    status, position = _tracker_sees_a_start_from_rest(1e-7, a_speed=0.0)
    assert status == "confirmed" and abs(position[1]) < 5.0


def test_a_crowded_pair_of_a_track_whose_turn_stays_in_its_gate_is_not_searched():
    """A 2 m/s track (its turn, 0.2 m/s², stays inside its gate) 4 s after its last update,
    a detection 5 m off at 2e-5 false alarms per m²: the change of speed's gate is crowded,
    and a turn alone was never searched for such a track: nothing, with or without it."""
    x = np.zeros((1, 2, 5))
    x[0, :, 2] = 2.0
    P = np.tile(np.diag([4.0, 4.0, 1.0, 1.0, 1e-4]), (1, 2, 1, 1))

    def search(a_speed):
        return manoeuvre_search(
            x, P, np.array([[0.9, 0.1]]), x[:, 0], P[:, 0], np.array([4.0]),
            np.array([[0.0, 5.0]]), 4.0 * np.eye(2)[None], np.array([0.9]), 2e-5,
            a_max=50.0, omega_max=0.1, straight_sojourn=30.0, gamma=18.4, a_speed=a_speed,
            quiet=0.1,
        )  # fmt: skip

    assert search(0.0) is None
    assert search(3.0) is None
