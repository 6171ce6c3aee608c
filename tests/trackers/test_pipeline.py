"""The tracking step over peers and individual tracks, and its refusal of bad scans."""

import math

import numpy as np
import pytest

from trackers.config import TrackerConfig
from trackers.pipeline import PeerOutput, ResolutionCell, TrackingPipeline, check_scan
from trackers.types import Scan, ScanRejected

#: Tracks that start at one detection, so that one scan makes a track to look at.
SINGLE_POINT = TrackerConfig().merged({"initiation": {"method": "single_point"}})


def scan_at(t, points, R=None, **kw):
    z = np.asarray(points, dtype=float).reshape(-1, 2)
    if R is None:
        R = np.tile(25.0 * np.eye(2), (len(z), 1, 1))
    return Scan("r1", float(t), z, R, **kw)


class DiscClaimer:
    """A peer that explains every detection within ``radius`` of ``center`` as its own and
    masks individual targets there (detection probability ``pd_inside``)."""

    kind = "extended"

    def __init__(self, center, radius, pd_inside):
        self.center = np.asarray(center, dtype=float)
        self.radius = radius
        self.pd_inside = pd_inside
        self.seen_individual = []

    def step(self, scan, individual):
        self.seen_individual.append(len(individual))
        inside = np.linalg.norm(scan.z - self.center, axis=1) <= self.radius
        cell = ResolutionCell(self.center, self.radius**2 * np.eye(2), self.pd_inside)
        return PeerOutput(claimed=inside, cells=(cell,))

    def snapshot(self):
        return ()


def state(p):
    return [(t.id, t.position, t.score, t.status) for t in p.snapshot()]


@pytest.mark.parametrize(
    ("scan", "reason", "text"),
    [
        (scan_at(float("nan"), [0, 0]), "invalid_scan", "time"),
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
        p.individual.step(scan_at(0.0, [0, 0]))
    s0 = plain.snapshot()[0].score
    plain.process(scan_at(1.0, np.zeros((0, 2))))
    hybrid.process(scan_at(1.0, np.zeros((0, 2))))
    assert plain.snapshot()[0].score == pytest.approx(s0 + math.log(1 - 0.9))
    assert hybrid.snapshot()[0].score == pytest.approx(s0 + math.log(1 - 0.2))


def test_peer_sees_individual_tracks_before_the_scan():
    peer = DiscClaimer(center=[1e6, 1e6], radius=1.0, pd_inside=0.5)
    p = TrackingPipeline(SINGLE_POINT, peers=[peer])
    p.process(scan_at(0.0, [[0, 0], [100, 0]]))
    p.process(scan_at(1.0, [[0, 0], [100, 0]]))
    assert peer.seen_individual == [0, 2]
