"""One tracking step over all track kinds.

The pipeline checks a scan once, then runs its trackers in two phases (see
:mod:`trackers.peers`): every *peer* (extended objects, formations, point patterns) proposes
what it would do with the scan, seeing the point tracks predicted to the scan's time; the
*point tracker* proposes its step on the detections no peer claimed, under what the peers
asked of it (detection probabilities, tracks taken over and handed back); only then does each
commit. A rejected scan raises :class:`~trackers.types.ScanRejected`, and a failing or
ill-formed peer :class:`~trackers.peers.PeerError`, before any tracker has changed.

The point tracker is chosen by ``association.method`` (:data:`POINT_TRACKERS`) or injected.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from trackers.config import TrackerConfig
from trackers.individual import IndividualTracker
from trackers.peers import (
    PeerError,
    PeerProposal,
    PeerTracker,
    PointDirectives,
    PointTracker,
    check_proposal,
    combine_directives,
)
from trackers.types import Scan, ScanRejected, StepResult, TrackSnapshot

__all__ = [
    "MAX_ABS_POSITION",
    "MAX_VARIANCE",
    "POINT_TRACKERS",
    "TrackingPipeline",
    "check_scan",
    "make_point_tracker",
]

#: Largest |x| or |y| a detection may have (m): far beyond any sensor of a local frame, and
#: small enough that squared distances and covariances stay finite in double precision.
MAX_ABS_POSITION = 1e9
#: Largest magnitude of a detection covariance entry (m²): a standard deviation of 10,000 km.
MAX_VARIANCE = 1e14


#: The point trackers by ``association.method``.
POINT_TRACKERS: dict[str, Callable[[TrackerConfig], PointTracker]] = {"gnn": IndividualTracker}


def make_point_tracker(config: TrackerConfig) -> PointTracker:
    """The point tracker that ``config.association.method`` names."""
    return POINT_TRACKERS[config.association.method](config)


def check_scan(scan: Scan, last_time: float | None) -> None:
    """Raise :class:`ScanRejected` unless the scan's numbers are usable and in time order.

    Checks: finite time not older than ``last_time``; finite positions with
    ``|x|, |y| ≤ MAX_ABS_POSITION``; symmetric positive definite covariances with entries
    ``≤ MAX_VARIANCE`` in magnitude; ``pd`` in (0, 1] and ``clutter_density`` > 0 when given.
    """
    if not math.isfinite(scan.time):
        raise ScanRejected("invalid_scan", "time: not a finite number")
    if last_time is not None and scan.time < last_time:
        raise ScanRejected(
            "out_of_sequence",
            f"time {scan.time} is older than the last processed time {last_time}",
        )
    if scan.size:
        bad = np.flatnonzero(~np.isfinite(scan.z).all(axis=1))
        if bad.size:
            raise ScanRejected("invalid_scan", f"detections[{bad[0]}]: position not finite")
        bad = np.flatnonzero((np.abs(scan.z) > MAX_ABS_POSITION).any(axis=1))
        if bad.size:
            raise ScanRejected(
                "invalid_scan",
                f"detections[{bad[0]}]: position beyond ±{MAX_ABS_POSITION:g} m",
            )
        R = scan.R
        bad = np.flatnonzero(~np.isfinite(R).all(axis=(1, 2)))
        if bad.size:
            raise ScanRejected("invalid_scan", f"detections[{bad[0]}].cov: not finite")
        bad = np.flatnonzero((np.abs(R) > MAX_VARIANCE).any(axis=(1, 2)))
        if bad.size:
            raise ScanRejected(
                "invalid_scan", f"detections[{bad[0]}].cov: an entry above {MAX_VARIANCE:g} m²"
            )
        asym = np.abs(R[:, 0, 1] - R[:, 1, 0]) > 1e-9 * (1.0 + np.abs(R[:, 0, 1]))
        det = R[:, 0, 0] * R[:, 1, 1] - R[:, 0, 1] * R[:, 1, 0]
        bad = np.flatnonzero(asym | (R[:, 0, 0] <= 0) | (det <= 0))
        if bad.size:
            raise ScanRejected(
                "invalid_scan", f"detections[{bad[0]}].cov: not symmetric positive definite"
            )
    if scan.pd is not None and not (0 < scan.pd <= 1):
        raise ScanRejected("invalid_scan", f"pd: must be in (0, 1], got {scan.pd}")
    if scan.clutter_density is not None and not (
        math.isfinite(scan.clutter_density) and scan.clutter_density > 0
    ):
        raise ScanRejected("invalid_scan", "clutter_density: must be a finite number > 0")


class TrackingPipeline:
    """Peers and the point tracker; one ``process`` call per scan, in time order."""

    def __init__(
        self,
        config: TrackerConfig | None = None,
        peers: Sequence[PeerTracker] = (),
        point_tracker: PointTracker | None = None,
    ) -> None:
        config = config or TrackerConfig()
        self.point: PointTracker = point_tracker or make_point_tracker(config)
        self.peers: tuple[PeerTracker, ...] = tuple(peers)
        kinds = [p.kind for p in self.peers]
        if len(set(kinds)) != len(kinds):
            raise ValueError(f"two peers of one kind: {kinds}")
        self._last_time: float | None = None

    @property
    def individual(self) -> PointTracker:
        """The point tracker (the individual-target tracks)."""
        return self.point

    @property
    def config(self) -> TrackerConfig:
        return self.point.config

    @property
    def last_time(self) -> float | None:
        """Time of the last processed scan, or ``None`` before the first."""
        return self._last_time

    def reconfigure(self, config: TrackerConfig) -> None:
        """Use ``config`` from the next scan on, in every tracker; tracks and ids are kept."""
        self.point.reconfigure(config)
        for peer in self.peers:
            peer.reconfigure(config)

    def process(self, scan: Scan) -> StepResult:
        """Run one scan through every tracker. Raise ``ScanRejected`` for an unusable scan and
        ``PeerError`` for a failing peer; either way no tracker changes."""
        check_scan(scan, self._last_time)
        if not self.peers:
            proposal = self.point.propose(scan, PointDirectives())
            self.point.commit(proposal)
            self._last_time = scan.time
            return proposal.result
        view = self.point.predicted(scan.time)
        proposals: list[PeerProposal] = []
        for peer in self.peers:
            try:
                prop = peer.propose(scan, view)
            except ScanRejected:
                raise
            except Exception as exc:
                raise PeerError(peer.kind, f"{type(exc).__name__}: {exc}") from exc
            check_proposal(peer.kind, prop, scan, view)
            proposals.append(prop)
        kinds = tuple(p.kind for p in self.peers)
        directives = combine_directives(kinds, tuple(proposals), view)
        claimed = np.zeros(scan.size, dtype=bool)
        for prop in proposals:
            claimed |= prop.claimed
        point = self.point.propose(scan.subset(~claimed), directives)
        # Commit: every tracker has proposed without error.
        for peer, prop in zip(self.peers, proposals, strict=True):
            peer.commit(prop)
        self.point.commit(point)
        self._last_time = scan.time
        peer_all = tuple(t for prop in proposals for t in prop.tracks)
        peer_confirmed = tuple(t for t in peer_all if t.confirmed)
        deleted = tuple(d for prop in proposals for d in prop.deleted)
        result = point.result
        return StepResult(
            time=scan.time,
            sensor_id=scan.sensor_id,
            deleted=deleted + result.deleted,
            snapshot=lambda confirmed_only: (
                (peer_confirmed if confirmed_only else peer_all) + result.snapshot(confirmed_only)
            ),
        )

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        """Every live track of every kind, as of the last processed scan."""
        out: list[TrackSnapshot] = []
        for peer in self.peers:
            out.extend(peer.snapshot())
        out.extend(self.point.snapshot())
        return tuple(out)
