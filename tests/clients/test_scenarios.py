"""Scenario simulator: reproducibility, detection statistics, truth statistics, batches."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from clients.scenarios.multitarget import (
    ScenarioConfig,
    SensorSpec,
    SimulatedScan,
    crossing_scenario,
    reference_scenario,
    scale_scenario,
    simulate,
)
from trackers.types import Scan


@pytest.fixture(scope="module")
def reference() -> list[SimulatedScan]:
    return simulate(reference_scenario(seed=7))


def truth_position(scan: SimulatedScan, target: np.ndarray) -> np.ndarray:
    """Positions of the targets ``target`` (ids) in ``scan``."""
    index = np.searchsorted(scan.truth_ids, target)
    assert np.array_equal(scan.truth_ids[index], target)
    return scan.truth_states[index, :2]


def test_reference_config() -> None:
    c = reference_scenario(3)
    assert (c.n_targets, c.n_scans, c.dt, c.seed) == (50, 100, 1.0, 3)
    assert c.area == ((-1000.0, 1000.0), (-1000.0, 1000.0))
    assert c.init_area == ((-600.0, 600.0), (-600.0, 600.0))
    assert (c.init_velocity_std, c.q) == (5.0, 0.05)
    (s,) = c.sensors
    assert (s.pd, s.sigma, s.clutter_mean) == (0.9, 5.0, 10.0)


def test_reproducible_with_seed() -> None:
    a = simulate(reference_scenario(seed=1))
    b = simulate(reference_scenario(seed=1))
    other = simulate(reference_scenario(seed=2))
    assert len(a) == len(b) == 100
    for x, y in zip(a, b, strict=True):
        assert x.time == y.time and x.detection_ids == y.detection_ids
        for name in ("truth_ids", "truth_states", "z", "R", "target_of_detection"):
            assert np.array_equal(getattr(x, name), getattr(y, name))
    assert not np.array_equal(a[0].truth_states, other[0].truth_states)


def test_scan_layout(reference: list[SimulatedScan]) -> None:
    times = [s.time for s in reference]
    assert times == [float(k) for k in range(100)]
    for i, s in enumerate(reference):
        n = s.z.shape[0]
        assert s.R.shape == (n, 2, 2) and s.target_of_detection.shape == (n,)
        assert s.detection_ids == tuple(f"s{i}-d{j}" for j in range(n))
        assert np.array_equal(s.truth_ids, np.arange(50))
        assert s.truth_states.shape == (50, 4)
        assert np.allclose(s.R, 25.0 * np.eye(2))
        assert s.clutter_density == pytest.approx(10.0 / 2000.0**2)
        assert s.pd == 0.9
    with pytest.raises(ValueError):
        reference[0].z[0, 0] = 1.0  # read-only


def test_detection_rate_matches_pd(reference: list[SimulatedScan]) -> None:
    hits = sum(int(np.count_nonzero(s.target_of_detection >= 0)) for s in reference)
    trials = sum(s.truth_ids.size for s in reference)
    # Binomial std sqrt(0.09 / 5000) ≈ 0.0042; allow 4 std.
    assert hits / trials == pytest.approx(0.9, abs=0.017)
    # No target is detected twice in a scan.
    for s in reference:
        owned = s.target_of_detection[s.target_of_detection >= 0]
        assert np.unique(owned).size == owned.size


def test_clutter_count_and_spread(reference: list[SimulatedScan]) -> None:
    counts = np.array([np.count_nonzero(s.target_of_detection < 0) for s in reference])
    # Poisson(10): the mean of 100 counts has std 0.32; the variance should be near 10 too.
    assert counts.mean() == pytest.approx(10.0, abs=1.3)
    assert counts.var(ddof=1) == pytest.approx(10.0, rel=0.45)
    clutter = np.vstack([s.z[s.target_of_detection < 0] for s in reference])
    assert np.all(np.abs(clutter) <= 1000.0)
    # Uniform on [-1000, 1000]: mean 0 (std 577/sqrt(1000) ≈ 18), std 577.
    assert np.allclose(clutter.mean(axis=0), 0.0, atol=80.0)
    assert np.allclose(clutter.std(axis=0), 2000 / math.sqrt(12), rtol=0.08)


def test_measurement_noise_matches_sigma(reference: list[SimulatedScan]) -> None:
    residuals = []
    for s in reference:
        own = s.target_of_detection >= 0
        residuals.append(s.z[own] - truth_position(s, s.target_of_detection[own]))
    r = np.vstack(residuals)
    assert r.shape[0] > 4000
    assert np.allclose(r.mean(axis=0), 0.0, atol=0.3)
    assert np.allclose(r.std(axis=0), 5.0, rtol=0.04)
    assert abs(np.corrcoef(r.T)[0, 1]) < 0.05


def test_detection_order_is_shuffled(reference: list[SimulatedScan]) -> None:
    owners = np.concatenate([s.target_of_detection for s in reference[:10]])
    targets_first = all(
        np.all(np.diff(np.flatnonzero(s.target_of_detection < 0)) == 1)
        and (s.target_of_detection[-1] < 0)
        for s in reference[:10]
    )
    assert not targets_first
    ordered = [s.target_of_detection[s.target_of_detection >= 0] for s in reference[:10]]
    assert not all(np.all(np.diff(o) > 0) for o in ordered)
    assert owners.size > 0


def test_truth_increments_match_q() -> None:
    config = ScenarioConfig(n_targets=200, n_scans=60, dt=2.0, q=0.05, seed=11)
    scans = simulate(config)
    T, q = 2.0, 0.05
    before = np.stack([s.truth_states for s in scans[:-1]])
    after = np.stack([s.truth_states for s in scans[1:]])
    dv = (after[..., 2:] - before[..., 2:]).ravel()
    dp = (after[..., :2] - before[..., :2] - T * before[..., 2:]).ravel()
    # 23 600 samples: the sample variance has relative std sqrt(2/n) ≈ 0.9 %.
    assert dv.var() == pytest.approx(q * T, rel=0.05)
    assert dp.var() == pytest.approx(q * T**3 / 3, rel=0.05)
    assert np.mean(dp * dv) == pytest.approx(q * T**2 / 2, rel=0.06)
    assert abs(dv.mean()) < 4 * math.sqrt(q * T / dv.size)


def test_initial_states_statistics() -> None:
    first = simulate(ScenarioConfig(n_targets=4000, n_scans=1, seed=5))[0].truth_states
    assert np.all(np.abs(first[:, :2]) <= 600.0)
    assert np.allclose(first[:, 2:].std(axis=0), 5.0, rtol=0.05)


def test_to_batch_round_trips_through_json(reference: list[SimulatedScan]) -> None:
    s = reference[3]
    batch = s.to_batch()
    assert json.loads(json.dumps(batch)) == batch
    assert set(batch) == {
        "sensor_id", "time", "detections", "pd", "clutter_density", "sensor_position",
    }  # fmt: skip
    assert type(batch["time"]) is float and type(batch["pd"]) is float
    assert batch["sensor_position"] == [0.0, 0.0]
    assert len(batch["detections"]) == s.z.shape[0]
    d = batch["detections"][0]
    assert (d["x"], d["y"]) == (float(s.z[0, 0]), float(s.z[0, 1]))
    assert d["cov"] == [[25.0, 0.0], [0.0, 25.0]] and d["id"] == s.detection_ids[0]
    assert all(type(v) is float for det in batch["detections"] for v in (det["x"], det["y"]))


def test_to_scan(reference: list[SimulatedScan]) -> None:
    s = reference[5]
    scan = s.to_scan()
    assert isinstance(scan, Scan)
    assert (scan.sensor_id, scan.time, scan.pd) == ("radar-1", 5.0, 0.9)
    assert scan.clutter_density == s.clutter_density
    assert np.array_equal(scan.z, s.z) and np.array_equal(scan.R, s.R)
    assert scan.detection_ids == s.detection_ids
    assert np.array_equal(scan.sensor_position, [0.0, 0.0])
    scan.z[0, 0] += 1.0  # the scan owns its arrays
    assert scan.z[0, 0] != s.z[0, 0]


def test_several_sensors_share_one_truth() -> None:
    sensors = (
        SensorSpec("a", pd=1.0, clutter_mean=0.0, position=(10.0, 20.0)),
        SensorSpec("b", pd=0.5, sigma=20.0, clutter_mean=3.0, time_offset=0.5),
        SensorSpec("c", time_offset=0.0),
    )
    scans = simulate(ScenarioConfig(n_targets=5, n_scans=4, sensors=sensors, seed=2))
    order = [(s.time, s.sensor_id) for s in scans]
    expected = [(k + o, sid) for k in range(4) for o, sid in ((0.0, "a"), (0.0, "c"), (0.5, "b"))]
    assert order == expected
    assert np.array_equal(scans[0].truth_states, scans[1].truth_states)  # same time
    assert not np.array_equal(scans[0].truth_states, scans[2].truth_states)
    assert scans[0].to_batch()["sensor_position"] == [10.0, 20.0]
    assert scans[0].z.shape[0] == 5 and np.all(scans[0].target_of_detection >= 0)
    assert np.allclose(scans[2].R, 400.0 * np.eye(2))
    ids = [d for s in scans for d in s.detection_ids]
    assert len(set(ids)) == len(ids)


def test_coordinated_turns_keep_speed_and_turn() -> None:
    config = ScenarioConfig(n_targets=100, n_scans=120, q=0.0, turn_rate_std=0.05, seed=4)
    scans = simulate(config)
    v = np.stack([s.truth_states[:, 2:] for s in scans])
    speed = np.linalg.norm(v, axis=-1)
    assert np.allclose(speed, speed[0], rtol=1e-9)
    heading = np.unwrap(np.arctan2(v[..., 1], v[..., 0]), axis=0)
    rates = np.diff(heading, axis=0)  # per second
    turning = np.abs(rates) > 1e-9
    assert 0.2 < turning.mean() < 0.8  # half the segments are straight
    # The rate changes at random times, about every 15 s.
    switches = np.count_nonzero(np.abs(np.diff(rates, axis=0)) > 1e-9)
    assert 0.3 * 100 * 118 / 15 < switches < 100 * 118 / 15
    # Positions follow the exact turn: |Δp| equals the chord 2 v sin(ωT/2)/ω.
    p = np.stack([s.truth_states[:, :2] for s in scans])
    chord = np.linalg.norm(np.diff(p, axis=0), axis=-1)
    w = rates
    expected = np.where(np.abs(w) > 1e-12, 2 * speed[1:] * np.sin(w / 2) / np.where(w == 0, 1, w),
                        speed[1:])  # fmt: skip
    assert np.allclose(chord, expected, rtol=1e-8)


def test_straight_lines_without_noise() -> None:
    scans = simulate(ScenarioConfig(n_targets=10, n_scans=5, q=0.0, seed=3))
    x0 = scans[0].truth_states
    for k, s in enumerate(scans):
        assert np.allclose(s.truth_states[:, :2], x0[:, :2] + k * x0[:, 2:])


def test_birth_and_death() -> None:
    scans = simulate(ScenarioConfig(n_targets=40, n_scans=100, birth_death=True, seed=9))
    alive = np.array([s.truth_ids.size for s in scans])
    assert alive[0] == 40
    assert 25 < alive.mean() < 55
    all_ids = np.unique(np.concatenate([s.truth_ids for s in scans]))
    # Mean lifetime 50 s: about 40 * 99 / 50 ≈ 80 births.
    assert 40 + 40 < all_ids.size < 40 + 130
    assert np.array_equal(all_ids, np.arange(all_ids.size))
    for a, b in itertools.pairwise(scans):
        assert np.all(np.diff(b.truth_ids) > 0)
        gone = np.setdiff1d(a.truth_ids, b.truth_ids)
        new = np.setdiff1d(b.truth_ids, a.truth_ids)
        assert gone.size == 0 or gone.max() <= a.truth_ids.max()
        assert new.size == 0 or new.min() > a.truth_ids.max()  # ids are never reused
        own = b.target_of_detection[b.target_of_detection >= 0]
        assert np.all(np.isin(own, b.truth_ids))  # only live targets are detected


def test_scale_scenario() -> None:
    config = scale_scenario(1000)
    assert config.area == ((-10000.0, 10000.0), (-10000.0, 10000.0))
    assert config.init_area == ((-8000.0, 8000.0), (-8000.0, 8000.0))
    assert config.init_velocity_std == 10.0 and config.sensors[0].clutter_mean == 1000.0
    scans = simulate(config)
    assert len(scans) == 30 and scans[0].truth_ids.size == 1000
    assert scans[0].clutter_density == pytest.approx(1000.0 / 20000.0**2)


def test_crossing_scenario() -> None:
    config = crossing_scenario(seed=1)
    assert config.n_targets == 4
    scans = simulate(config)
    start = scans[0].truth_states
    assert np.allclose(np.linalg.norm(start[:, :2], axis=1), 500.0)
    p = np.stack([s.truth_states[:, :2] for s in scans])  # (scan, target, 2)
    gaps = np.linalg.norm(p[:, :, None] - p[:, None, :], axis=-1)
    i, j = np.triu_indices(4, 1)
    assert gaps[0, i, j].min() > 150.0
    assert gaps[:, i, j].min(axis=0).max() < 120.0  # every pair comes close mid-run
    # Adjacent paths cross: the order of the targets across the mean heading flips.
    across = p[..., 1]
    assert np.all(np.diff(across[0]) < 0) and np.all(np.diff(across[-1]) > 0)
    # Without process noise they all meet at the origin at t = 50 s.
    exact = simulate(crossing_scenario(q=0.0))
    assert np.allclose(exact[50].truth_states[:, :2], 0.0, atol=1e-9)


def test_invalid_configs() -> None:
    with pytest.raises(ValueError):
        ScenarioConfig(dt=0.0)
    with pytest.raises(ValueError):
        ScenarioConfig(area=((1.0, -1.0), (0.0, 1.0)))
    with pytest.raises(ValueError):
        ScenarioConfig(sensors=())
    with pytest.raises(ValueError):
        ScenarioConfig(sensors=(SensorSpec("a"), SensorSpec("a")))
    with pytest.raises(ValueError):
        SensorSpec(pd=1.5)
    with pytest.raises(ValueError):
        ScenarioConfig(n_targets=2, initial_states=((0.0, 0.0, 0.0, 0.0),))
    assert simulate(ScenarioConfig(n_scans=0)) == []
    empty = simulate(ScenarioConfig(n_targets=0, n_scans=3))
    assert all(s.truth_states.shape == (0, 4) for s in empty)


def test_continuous_scenario_targets_come_and_go_one_by_one() -> None:
    import itertools

    from clients.scenarios.continuous import ContinuousScenario

    scenario = ContinuousScenario(seed=4)
    scans = list(itertools.islice(scenario.scans(), 300))
    again = list(itertools.islice(ContinuousScenario(seed=4).scans(), 300))
    assert all(np.array_equal(a.z, b.z) for a, b in zip(scans, again, strict=True))
    assert [s.time for s in scans[:3]] == [0.0, 1.0, 2.0]
    alive = [set(s.truth_ids.tolist()) for s in scans]
    ended = [len(a - b) for a, b in itertools.pairwise(alive)]
    born = [len(b - a) for a, b in itertools.pairwise(alive)]
    assert sum(ended) >= 50 and sum(born) >= 50  # a turnover, not one population
    assert max(ended) <= 5 and all(alive)  # never all at once
    assert 30 <= np.mean([len(a) for a in alive]) <= 70
    assert not alive[0] & alive[-1] or len(alive[0] & alive[-1]) < len(alive[0])
    speeds = np.concatenate([np.hypot(*s.truth_states[:, 2:].T) for s in scans])
    assert np.median(speeds) > 5 and speeds.max() < 300  # walkers to airliners
    clutter = [int((s.target_of_detection == -1).sum()) for s in scans]
    assert 10 < np.mean(clutter) < 30
    detected = sum(int((s.target_of_detection >= 0).sum()) for s in scans)
    assert 0.85 < detected / sum(len(a) for a in alive) < 0.95
    batch = scans[0].to_batch()
    assert batch["sensor_id"] == "radar-1" and batch["pd"] == 0.9
