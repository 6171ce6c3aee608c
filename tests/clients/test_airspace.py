import math

import numpy as np
import pytest

from clients.scenarios.airspace import (
    AT_REST_SPEED,
    Manoeuvre,
    PolarRadar,
    ScriptedScenario,
    ScriptedTarget,
    apron_scenario,
    formation_scenario,
    mixed_speed_scenario,
    path_ranges,
    runway_scenario,
    simulate_scripted,
)


def test_polar_noise_and_its_covariance_agree():
    """Range noise along the line of sight, bearing noise across it, and the reported R
    matches the spread of the detections."""
    radar = PolarRadar(
        "r", (0.0, 0.0), range_std=50.0, bearing_std=2e-3, pd=1.0, period=1.0, clutter_mean=0.0
    )
    target = ScriptedTarget("parked", (0.0, 30e3, 0.0, 0.0))
    scans = simulate_scripted(ScriptedScenario((target,), (radar,), duration=1999.0, seed=1))
    z = np.array([s.z[0] for s in scans])
    R = scans[0].R[0]
    assert np.std(z[:, 1]) == pytest.approx(50.0, rel=0.1)  # range: y here
    assert np.std(z[:, 0]) == pytest.approx(60.0, rel=0.1)  # 30 km x 2 mrad
    np.testing.assert_allclose(np.diag(R), [60.0**2, 50.0**2], rtol=0.02)


def test_scripted_turn_changes_heading_by_rate_times_duration():
    omega = math.radians(3.0)
    target = ScriptedTarget("airliner", (0.0, 0.0, 250.0, 0.0), (Manoeuvre(10.0, 30.0, omega),))
    radar = PolarRadar("r", (0.0, -50e3), pd=1.0, period=5.0, clutter_mean=0.0)
    scans = simulate_scripted(ScriptedScenario((target,), (radar,), duration=60.0))
    vx, vy = scans[-1].truth_states[0, 2:]
    assert math.atan2(vy, vx) == pytest.approx(omega * 30.0, abs=1e-9)
    assert math.hypot(vx, vy) == pytest.approx(250.0)


def test_a_scripted_acceleration_changes_the_speed_along_a_straight_path():
    """10 m/s, then 2.5 m/s² for 28 s: 80 m/s, 10 × 28 + 2.5 × 28² / 2 = 1260 m further on,
    the heading kept; a target braking harder than its speed allows stops."""
    radar = PolarRadar("r", (0.0, -50e3), pd=1.0, period=1.0, clutter_mean=0.0)
    fast = ScriptedTarget("take-off", (0.0, 0.0, 6.0, 8.0), (Manoeuvre(0.0, 28.0, 0.0, 2.5),))
    stop = ScriptedTarget("landing", (0.0, 0.0, 10.0, 0.0), (Manoeuvre(0.0, 20.0, 0.0, -2.0),))
    scans = simulate_scripted(ScriptedScenario((fast, stop), (radar,), duration=28.0))
    x, y, vx, vy = scans[-1].truth_states[0]
    assert math.hypot(vx, vy) == pytest.approx(80.0)
    assert math.hypot(x, y) == pytest.approx(1260.0, rel=1e-9)
    assert math.atan2(vy, vx) == pytest.approx(math.atan2(8.0, 6.0))
    x, _, vx, vy = scans[-1].truth_states[1]
    assert (vx, vy) == (0.0, 0.0)
    assert x == pytest.approx(25.0, abs=0.1)  # stopped after 5 s and 25 m


def test_runway_scenario_brakes_and_speeds_up():
    sc = runway_scenario(seed=0)
    scans = simulate_scripted(sc)
    speeds = np.array([np.hypot(*s.truth_states[:, 2:].T) for s in scans])  # (scans, 8)
    landing = [i for i, c in sc.classes.items() if c == "landing"]
    take_off = [i for i, c in sc.classes.items() if c == "take-off"]
    assert len(landing) == len(take_off) == 4
    np.testing.assert_allclose(speeds[0, landing], 80.0)
    np.testing.assert_allclose(speeds[-1, landing], 10.0)
    np.testing.assert_allclose(speeds[0, take_off], 10.0)
    np.testing.assert_allclose(speeds[-1, take_off], 80.0)


def test_mixed_speed_scenario_has_every_class_and_speed():
    sc = mixed_speed_scenario(period=4.0, seed=0)
    scans = simulate_scripted(sc)
    speeds = np.hypot(*scans[0].truth_states[:, 2:].T)
    classes = np.array([sc.classes[i] for i in range(len(sc.targets))])
    assert set(classes) == {"parked", "ground", "helicopter", "airliner", "jet"}
    assert np.all(speeds[classes == "parked"] == 0)
    assert speeds.max() == pytest.approx(680.0)
    ranges = np.hypot(*np.concatenate([s.truth_states[:, :2] for s in scans]).T)
    assert ranges.min() > 4e3 and ranges.max() < 62e3  # 5-60 km, give or take process noise
    assert 60 < np.mean([np.sum(s.target_of_detection < 0) for s in scans]) < 140


@pytest.mark.parametrize("seed", range(5))
def test_mixed_speed_paths_stay_5_to_60_km_from_the_radar(seed):
    sc = mixed_speed_scenario(period=4.0, seed=seed)
    for target in sc.targets:
        r = path_ranges(target, sc.duration)
        assert r.min() >= 5e3 and r.max() <= 60e3, target


def test_path_ranges_follow_the_script():
    target = ScriptedTarget("jet", (10e3, 0.0, 0.0, 500.0), (Manoeuvre(10.0, 10.0, 0.05),))
    r = path_ranges(target, 30.0)
    assert r.shape == (31,)
    assert r[0] == pytest.approx(10e3)
    assert r[10] == pytest.approx(math.hypot(10e3, 5e3))  # straight for 10 s at 500 m/s


def test_formation_scenario_three_radars_unsynchronized():
    scans = simulate_scripted(formation_scenario(seed=0))
    first = [(s.sensor_id, s.time) for s in scans[:4]]
    assert [sid for sid, _ in first] == ["radar-1", "radar-2", "radar-3", "radar-1"]
    assert 0 < first[1][1] - first[0][1] < 1.0
    speeds = np.hypot(*scans[0].truth_states[:, 2:].T)
    np.testing.assert_allclose(sorted(set(np.round(speeds))), [316.0, 361.0])


def test_apron_scenario_sets_off_from_rest_across_the_line_of_sight():
    sc = apron_scenario(seed=0)
    scans = simulate_scripted(sc)
    speeds = np.array([np.hypot(*s.truth_states[:, 2:].T) for s in scans])  # (scans, 8)
    rolls = [i for i, c in sc.classes.items() if c == "take-off roll"]
    vehicles = [i for i, c in sc.classes.items() if c == "vehicle"]
    assert len(rolls) == len(vehicles) == 4
    np.testing.assert_allclose(speeds[:8], AT_REST_SPEED)  # at rest for the first 28 s
    np.testing.assert_allclose(speeds[-1, rolls], 70.0 + AT_REST_SPEED)
    np.testing.assert_allclose(speeds[-1, vehicles], 15.0 + AT_REST_SPEED)
    for i in range(8):
        p = scans[0].truth_states[i, :2]
        assert 1e3 <= np.hypot(*p) <= 3e3
        v = scans[-1].truth_states[i, 2:]
        cos = abs(p @ v) / (np.hypot(*p) * np.hypot(*v))
        assert cos < np.sin(0.31)  # within 17° of across the line of sight
