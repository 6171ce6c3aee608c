"""Extended-object and group scenarios of paper 002: convoy in traffic, boat in a harbour."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from clients.scenarios.extended import (
    CONVOY_AREA,
    CONVOY_BRANCH,
    CONVOY_ROAD,
    HARBOUR_BACKWASH,
    MERGE_DISTANCE,
    ExtendedScenarioRun,
    convoy_scenario,
    harbour_scenario,
)
from trackers.pipeline import check_scan

N_MEMBERS = 9
OVERTAKER = 9
JUNCTIONS = np.array([CONVOY_ROAD[1], CONVOY_ROAD[2]])
FORK = np.array(CONVOY_BRANCH[3])


@pytest.fixture(scope="module")
def convoy() -> ExtendedScenarioRun:
    return convoy_scenario(seed=3)


@pytest.fixture(scope="module")
def harbour() -> ExtendedScenarioRun:
    return harbour_scenario(seed=3)


def truth(run: ExtendedScenarioRun) -> tuple[np.ndarray, np.ndarray]:
    """``(scans,)`` times and ``(scans, k, 4)`` truth states (ids are the same in every scan)."""
    times = np.array([s.scan.time for s in run.scans])
    states = np.array([s.scan.truth_states for s in run.scans])
    return times, states


def assert_same(a: ExtendedScenarioRun, b: ExtendedScenarioRun) -> None:
    assert len(a.scans) == len(b.scans)
    for x, y in zip(a.scans, b.scans, strict=True):
        for name in ("truth_ids", "truth_states", "z", "R", "target_of_detection"):
            np.testing.assert_array_equal(getattr(x.scan, name), getattr(y.scan, name))
        assert x.scan.detection_ids == y.scan.detection_ids
        np.testing.assert_array_equal(x.group_of_target, y.group_of_target)
        assert x.groups.keys() == y.groups.keys()


@pytest.mark.parametrize("factory", [convoy_scenario, harbour_scenario])
def test_reproducible_by_seed(factory):
    a, b, c = factory(seed=5), factory(seed=5), factory(seed=6)
    assert_same(a, b)
    assert a.split_time == b.split_time
    assert not all(
        x.scan.z.shape == y.scan.z.shape and np.array_equal(x.scan.z, y.scan.z)
        for x, y in zip(a.scans, c.scans, strict=True)
    )


def test_convoy_generation_is_fast():
    start = time.perf_counter()
    convoy_scenario(seed=1)
    assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize("name", ["convoy", "harbour"])
def test_scans_are_valid(name, request):
    run: ExtendedScenarioRun = request.getfixturevalue(name)
    times = np.array([s.scan.time for s in run.scans])
    assert np.all(np.diff(times) > 0)
    last = None
    for s in run.scans:
        scan = s.scan
        check_scan(scan.to_scan(), last)
        last = scan.time
        assert len(set(scan.detection_ids)) == len(scan.detection_ids)
        assert np.isfinite(scan.z).all() and np.isfinite(scan.truth_states).all()
        R = scan.R
        np.testing.assert_array_equal(R, R.transpose(0, 2, 1))
        assert (np.linalg.eigvalsh(R) > 0).all()
        for a in (
            scan.z,
            scan.R,
            scan.truth_ids,
            scan.truth_states,
            scan.target_of_detection,
            s.group_of_target,
            s.resolution_cell,
            *s.groups.values(),
        ):
            assert not a.flags.writeable
        assert s.group_of_target.shape == scan.truth_ids.shape
        batch = scan.to_batch()
        assert len(batch["detections"]) == scan.z.shape[0]
        assert set(run.target_class) == set(scan.truth_ids.tolist())


def test_convoy_classes_and_area(convoy):
    counts = {
        c: list(convoy.target_class.values()).count(c) for c in set(convoy.target_class.values())
    }
    assert counts == {"convoy": 9, "overtaker": 1, "vehicle": 19}
    assert [convoy.target_class[i] for i in range(N_MEMBERS)] == ["convoy"] * N_MEMBERS
    assert convoy.target_class[OVERTAKER] == "overtaker"
    times, states = truth(convoy)
    assert times[-1] >= 590.0 and np.allclose(np.diff(times), 5.0)
    (x0, x1), (y0, y1) = CONVOY_AREA
    for s in convoy.scans:
        z = s.scan.z
        assert ((z[:, 0] >= x0 - 100) & (z[:, 0] <= x1 + 100)).all()
        assert s.clutter_region is None
        assert s.scan.clutter_density == 1e-6 and s.scan.pd == 0.9
    p = states[:, :, :2]
    assert (p[..., 0] > x0).all() and (p[..., 0] < x1).all()
    assert (p[..., 1] > y0).all() and (p[..., 1] < y1).all()


def near_junction(points: np.ndarray, radius: float, fork: bool = True) -> np.ndarray:
    """Whether each point is within ``radius`` of J1, J2 (or the fork)."""
    corners = np.vstack([JUNCTIONS, FORK]) if fork else JUNCTIONS
    d = np.linalg.norm(points[..., None, :] - corners, axis=-1)
    return (d < radius).any(axis=-1)


def test_convoy_spacing_and_speeds(convoy):
    _, states = truth(convoy)
    members = states[:, :N_MEMBERS]
    speed = np.hypot(members[..., 2], members[..., 3])
    far = ~near_junction(members[..., :2], 200.0)
    assert far.sum() > 500
    np.testing.assert_allclose(speed[far], 10.0, atol=0.05)
    close = near_junction(members[..., :2], 30.0, fork=False)
    assert close.sum() >= 9 * 2  # every member is seen near J1 and J2
    assert (speed[close] < 5.0).all()
    branch = members[:, 6:]  # members 6-8 also slow down to turn off at the fork
    at_fork = np.linalg.norm(branch[..., :2] - FORK, axis=-1) < 30.0
    assert at_fork.sum() >= 3
    assert (np.hypot(branch[..., 2], branch[..., 3])[at_fork] < 5.0).all()
    # Spacing while the whole column drives straight at cruise speed, before the split.
    cruising = np.flatnonzero((speed > 9.9).all(axis=1))
    cruising = cruising[cruising < np.searchsorted([s.scan.time for s in convoy.scans], 500.0)]
    assert cruising.size > 20
    gaps = np.hypot(*np.diff(members[cruising, :, :2], axis=1).transpose(2, 0, 1))
    assert gaps.min() >= 30.0 and gaps.max() <= 150.0
    assert gaps.max() - gaps.min() > 50.0  # the spacing varies along the column


def test_convoy_turns_90_then_60_degrees(convoy):
    _, states = truth(convoy)
    lead = states[:, 0]
    heading = np.degrees(np.arctan2(lead[:, 3], lead[:, 2]))
    assert heading[0] == pytest.approx(0.0, abs=1e-6)
    assert heading[50] == pytest.approx(90.0, abs=1e-6)
    assert heading[-1] == pytest.approx(150.0, abs=1e-6)


def test_overtaker_passes_at_least_three_members(convoy):
    _, states = truth(convoy)
    over = states[:, OVERTAKER, :2]
    passed = set()
    for m in range(N_MEMBERS):
        member = states[:, m, :2]
        dist = np.hypot(*(member - over).T)
        for k in np.flatnonzero(dist < 30.0):
            if 2 <= k < len(dist) - 2:
                on_road_b = abs(member[k - 2, 0]) < 1.0 and abs(member[k + 2, 0]) < 1.0
                behind = over[k - 2, 1] < member[k - 2, 1]
                ahead = over[k + 2, 1] > member[k + 2, 1]
                if on_road_b and behind and ahead:
                    passed.add(m)
    assert len(passed) >= 3
    speed = np.hypot(states[:, OVERTAKER, 2], states[:, OVERTAKER, 3])
    assert speed.min() >= 15.0 and speed.max() <= 20.0


def test_convoy_splits_into_two_groups(convoy):
    split = convoy.split_time
    assert split is not None and convoy.scans[-1].scan.time - split >= 60.0
    _, states = truth(convoy)
    before = [s for s in convoy.scans if s.scan.time < split]
    after = [s for s in convoy.scans if s.scan.time >= split]
    assert before and after
    for s in before:
        assert set(s.groups) == {0}
        np.testing.assert_array_equal(s.group_of_target[:N_MEMBERS], 0)
        np.testing.assert_allclose(s.groups[0], s.scan.truth_states[:N_MEMBERS, :2].mean(axis=0))
    for s in after:
        assert set(s.groups) == {1, 2}
        np.testing.assert_array_equal(s.group_of_target[:N_MEMBERS], [1] * 6 + [2] * 3)
    for s in convoy.scans:
        assert (s.group_of_target[N_MEMBERS:] == -1).all()
    first = after[0]
    within = [s for s in after if s.scan.time <= first.scan.time + 60.0]
    d0 = np.linalg.norm(first.groups[1] - first.groups[2])
    d1 = np.linalg.norm(within[-1].groups[1] - within[-1].groups[2])
    assert d1 > 300.0 and d1 - d0 > 300.0
    # The two sub-convoys head about 90° apart at the end.
    v = states[-1]
    h1 = math.atan2(v[0, 3], v[0, 2])
    h2 = math.atan2(v[8, 3], v[8, 2])
    assert abs(math.degrees(h1 - h2)) == pytest.approx(90.0, abs=1.0)


def test_close_vehicles_give_one_merged_detection(convoy):
    merged = 0
    for s in convoy.scans:
        p = s.scan.truth_states[:, :2]
        d = np.hypot(*(p[:, None] - p[None, :]).transpose(2, 0, 1))
        owners = set(s.scan.target_of_detection.tolist())
        for i, j in zip(*np.nonzero(np.triu(d < MERGE_DISTANCE, k=1)), strict=True):
            assert j not in owners  # the higher id never gets its own detection
            assert s.resolution_cell[j] <= i
            merged += s.resolution_cell[j] in owners
    assert merged >= 3
    # The overtaker is merged with a member at least once while passing.
    assert any(
        (s.resolution_cell[OVERTAKER] < N_MEMBERS)
        and (s.resolution_cell[OVERTAKER] in s.scan.target_of_detection)
        for s in convoy.scans
    )


def test_convoy_detection_statistics(convoy):
    clutter = [int((s.scan.target_of_detection == -1).sum()) for s in convoy.scans]
    assert np.mean(clutter) == pytest.approx(400.0, abs=10.0)
    hits = {"convoy": [0, 0], "other": [0, 0]}
    for s in convoy.scans:
        owners = s.scan.target_of_detection
        resolved = s.resolution_cell == s.scan.truth_ids
        for tid in s.scan.truth_ids[resolved]:
            key = "convoy" if tid < N_MEMBERS else "other"
            hits[key][0] += int((owners == tid).sum())
            hits[key][1] += 1
        assert np.bincount(owners[owners >= 0]).max(initial=0) <= 1
    assert hits["convoy"][0] / hits["convoy"][1] == pytest.approx(0.7, abs=0.05)
    assert hits["other"][0] / hits["other"][1] == pytest.approx(0.9, abs=0.03)


def test_convoy_noise_is_10_m(convoy):
    err = []
    for s in convoy.scans:
        owners = s.scan.target_of_detection
        for j in np.flatnonzero(owners >= 0):
            tid = owners[j]
            if (s.resolution_cell == tid).sum() == 1:
                err.append(s.scan.z[j] - s.scan.truth_states[tid, :2])
    err = np.array(err)
    assert np.std(err, axis=0) == pytest.approx([10.0, 10.0], rel=0.1)
    R = convoy.scans[0].scan.R
    np.testing.assert_allclose(R, np.broadcast_to(100.0 * np.eye(2), R.shape), atol=1e-6)


def inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Points inside a convex counter-clockwise polygon."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    rel = points[:, None, :] - polygon[None]
    cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
    return (cross >= 0).all(axis=1)


def test_harbour_boat_buoys_and_backwash(harbour):
    assert dict(harbour.target_class) == {0: "boat", 1: "buoy", 2: "buoy", 3: "buoy", 4: "buoy"}
    assert harbour.split_time is None
    times, states = truth(harbour)
    assert times[-1] >= 290.0
    speed = np.hypot(states[:, 0, 2], states[:, 0, 3])
    assert speed.max() == pytest.approx(5.0) and speed.min() >= 2.5
    np.testing.assert_array_equal(states[:, 1:, 2:], 0.0)
    boat_counts, wash_counts, buoy_hits = [], [], 0
    for s in harbour.scans:
        owners = s.scan.target_of_detection
        boat_counts.append(int((owners == 0).sum()))
        buoy_hits += int((owners > 0).sum())
        region = s.clutter_region
        np.testing.assert_array_equal(region, HARBOUR_BACKWASH)
        in_region = inside(s.scan.z[owners == -1], region)
        wash_counts.append(int(in_region.sum()))
        assert not s.groups and (s.group_of_target == -1).all()
        # Boat points lie within its hull (plus a few noise standard deviations).
        boat = s.scan.z[owners == 0]
        assert (np.hypot(*(boat - s.scan.truth_states[0, :2]).T) < 15.0 + 60.0).all()
    boat_counts = np.array(boat_counts)
    assert boat_counts.max() == 2 and set(boat_counts.tolist()) <= {0, 1, 2}
    assert (boat_counts == 0).mean() == pytest.approx(0.1, abs=0.06)
    assert (boat_counts == 2).mean() == pytest.approx(0.45, abs=0.1)
    assert min(wash_counts) >= 5 and max(wash_counts) <= 15
    assert buoy_hits / (4 * len(harbour.scans)) == pytest.approx(0.9, abs=0.05)
    area = HARBOUR_BACKWASH
    sides = np.linalg.norm(np.diff(np.vstack([area, area[:1]]), axis=0), axis=1)
    np.testing.assert_allclose(sorted(sides), [100.0, 100.0, 300.0, 300.0])
