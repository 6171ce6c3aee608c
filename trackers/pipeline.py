"""One tracking step over all track kinds.

The pipeline checks a scan once, then lets its *peer* trackers (extended objects, formations,
point patterns: anything that takes many detections a scan) go first. Each peer may

- claim detections: a claimed detection is explained by the peer and never starts or updates
  an individual track;
- declare resolution cells: ellipses inside which an individual target cannot be resolved
  from the peer's object, where individual tracks are scored with the cell's detection
  probability instead of the sensor's (paper 002, section III.C, the hybridization).

The individual-target tracker then runs on the unclaimed detections. A rejected scan raises
:class:`~trackers.types.ScanRejected` before any tracker has changed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from trackers.config import TrackerConfig
from trackers.individual import IndividualTracker
from trackers.types import Scan, ScanRejected, StepResult, TrackSnapshot

__all__ = [
    "MAX_ABS_POSITION",
    "MAX_VARIANCE",
    "PeerOutput",
    "PeerTracker",
    "ResolutionCell",
    "TrackingPipeline",
    "check_scan",
]

#: Largest |x| or |y| a detection may have (m): far beyond any sensor of a local frame, and
#: small enough that squared distances and covariances stay finite in double precision.
MAX_ABS_POSITION = 1e9
#: Largest magnitude of a detection covariance entry (m²): a standard deviation of 10,000 km.
MAX_VARIANCE = 1e14


@dataclass(frozen=True)
class ResolutionCell:
    """The ellipse ``(p − c)ᵀ M⁻¹ (p − c) ≤ 1`` inside which individual targets are detected
    with probability ``pd`` (often much lower than the sensor's: the peer's object masks them)."""

    center: np.ndarray
    matrix: np.ndarray
    pd: float

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of the ``(n, 2)`` points inside the cell."""
        d = np.asarray(points, dtype=float).reshape(-1, 2) - self.center
        return np.einsum("ni,ij,nj->n", d, np.linalg.inv(self.matrix), d) <= 1.0


@dataclass(frozen=True)
class PeerOutput:
    """What a peer tracker returns for one scan."""

    claimed: np.ndarray
    tracks: tuple[TrackSnapshot, ...] = ()
    deleted: tuple[str, ...] = ()
    cells: tuple[ResolutionCell, ...] = field(default_factory=tuple)


class PeerTracker(Protocol):
    """A tracker of another kind that runs before the individual tracker on each scan.

    ``step`` sees the scan and the individual tracks as they were before it, and must leave
    its own state unchanged when it raises.
    """

    kind: str

    def step(self, scan: Scan, individual: tuple[TrackSnapshot, ...]) -> PeerOutput: ...

    def snapshot(self) -> tuple[TrackSnapshot, ...]: ...


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
    """Peers first, then individual tracks; one ``process`` call per scan, in time order."""

    def __init__(
        self, config: TrackerConfig | None = None, peers: Sequence[PeerTracker] = ()
    ) -> None:
        self.individual = IndividualTracker(config or TrackerConfig())
        self.peers: tuple[PeerTracker, ...] = tuple(peers)
        self._last_time: float | None = None

    @property
    def config(self) -> TrackerConfig:
        return self.individual.config

    @property
    def last_time(self) -> float | None:
        """Time of the last processed scan, or ``None`` before the first."""
        return self._last_time

    def reconfigure(self, config: TrackerConfig) -> None:
        """Use ``config`` from the next scan on; tracks and ids are kept."""
        self.individual.reconfigure(config)

    def process(self, scan: Scan) -> StepResult:
        """Run one scan through every tracker; raise ``ScanRejected`` and change nothing when
        the scan is unusable."""
        check_scan(scan, self._last_time)
        before = self.individual.snapshot() if self.peers else ()
        claimed = np.zeros(scan.size, dtype=bool)
        cells: list[ResolutionCell] = []
        peer_tracks: list[TrackSnapshot] = []
        deleted: list[str] = []
        for peer in self.peers:
            out = peer.step(scan, before)
            claimed |= np.asarray(out.claimed, dtype=bool)
            cells.extend(out.cells)
            peer_tracks.extend(out.tracks)
            deleted.extend(out.deleted)
        result = self.individual.step(scan.subset(~claimed), cells=tuple(cells))
        self._last_time = scan.time
        peer_all = tuple(peer_tracks)
        peer_confirmed = tuple(t for t in peer_all if t.confirmed)
        return StepResult(
            time=scan.time,
            sensor_id=scan.sensor_id,
            deleted=tuple(deleted) + result.deleted,
            snapshot=lambda confirmed_only: (
                (peer_confirmed if confirmed_only else peer_all) + result.snapshot(confirmed_only)
            ),
        )

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        """Every live track of every kind, as of the last processed scan."""
        out: list[TrackSnapshot] = []
        for peer in self.peers:
            out.extend(peer.snapshot())
        out.extend(self.individual.snapshot())
        return tuple(out)
