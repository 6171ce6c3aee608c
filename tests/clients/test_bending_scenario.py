"""Paper 000's bending extended target scenario (:mod:`clients.scenarios.bending`)."""

from __future__ import annotations

import math

import numpy as np

from clients.scenarios.bending import (
    MIN_POINT_SPACING,
    bending_scenario,
    paper_patterns,
    truth_modes,
)
from trackers.pattern.bending import measure


def test_truth_follows_the_stated_segments():
    run = bending_scenario(seed=1)
    assert len(run.scans) == 30
    modes = np.array([s.modes for s in run.scans])
    k = np.arange(1, 31)
    np.testing.assert_array_equal(modes[:, 0], ((k >= 11) & (k <= 20)).astype(int))
    np.testing.assert_array_equal(modes[:, 1], (k >= 18).astype(int))
    np.testing.assert_array_equal(modes[:, 2], (k >= 16).astype(int))
    assert [truth_modes(i) for i in (1, 11, 16, 18, 21, 30)] == [
        (0, 0, 0),
        (1, 0, 0),
        (1, 0, 1),
        (1, 1, 1),
        (0, 1, 1),
        (0, 1, 1),
    ]
    states = np.array([s.state for s in run.scans])
    times = np.array([s.time for s in run.scans])
    np.testing.assert_array_equal(times, k.astype(float))
    speed = np.hypot(states[:, 1], states[:, 3])
    np.testing.assert_allclose(speed, 100 * math.sqrt(2))
    heading = np.degrees(np.arctan2(states[:, 3], states[:, 1]))
    np.testing.assert_allclose(heading[:10], 45.0)
    np.testing.assert_allclose(heading[10:20], 45.0 - 3.0 * np.arange(1, 11))
    np.testing.assert_allclose(heading[20:], 15.0)
    np.testing.assert_allclose(states[:10, 0], 100.0 * k[:10])  # straight at 100 m/s per axis
    att = np.degrees(states[:, 4])
    np.testing.assert_allclose(att[:17], 45.0)
    np.testing.assert_allclose(att[17:], 45.0 + 5.0 * np.arange(1, 14))
    np.testing.assert_allclose(np.degrees(states[17:, 5]), 5.0)


def test_detections_are_pattern_points_plus_clutter_and_reproducible():
    a, b, c = bending_scenario(seed=4), bending_scenario(seed=4), bending_scenario(seed=5)
    for x, y in zip(a.scans, b.scans, strict=True):
        np.testing.assert_array_equal(x.detections, y.detections)
    assert any(
        len(x.detections) != len(y.detections) or not np.array_equal(x.detections, y.detections)
        for x, y in zip(a.scans, c.scans, strict=True)
    )
    n_target = n_clutter = 0
    for scan in a.scans:
        pattern = a.patterns[scan.modes[2]]
        t = scan.target_detections
        pts = measure(scan.state, pattern[scan.point_of_detection[t]])
        assert np.all(np.abs(scan.detections[t] - pts) < 5 * 0.3)
        fa = scan.point_of_detection < 0
        assert np.all(np.abs(scan.detections[fa] - scan.state[[0, 2]]) <= 15.0)
        n_target += len(t)
        n_clutter += int(fa.sum())
        assert len(np.unique(scan.point_of_detection[t])) == len(t)
    assert 0.75 < n_target / (15 * 5 + 15 * 4) < 1.0  # Pd 0.9
    assert 60 < n_clutter < 220  # Poisson(4.5) per scan over 30 scans


def test_patterns_are_in_the_square_and_spaced():
    p1, p2 = paper_patterns(0)
    assert p1.shape == (5, 2) and p2.shape == (4, 2)
    for p in (p1, p2):
        assert np.all(np.abs(p) <= 10.0)
        d = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
        assert d[np.triu_indices(len(p), 1)].min() >= MIN_POINT_SPACING
    np.testing.assert_array_equal(paper_patterns(0)[0], p1)
    assert not np.array_equal(paper_patterns(1)[0], p1)


def test_a_scan_of_the_run_for_the_tracker():
    run = bending_scenario(seed=2)
    sc = run.scans[4]
    scan = run.to_scan(4)
    assert (scan.sensor_id, scan.time, scan.size) == ("radar", sc.time, len(sc.detections))
    np.testing.assert_array_equal(scan.z, sc.detections)
    np.testing.assert_array_equal(scan.R, np.broadcast_to(run.R, (scan.size, 2, 2)))
    assert scan.detection_ids[0] == "k5d0" and scan.pd == run.pd
    assert scan.clutter_density == run.clutter_density
