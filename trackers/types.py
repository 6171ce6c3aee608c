"""What crosses the boundary between the service and the trackers.

A :class:`Scan` is one sensor's detection batch as arrays; a :class:`TrackSnapshot` is an
immutable picture of one track after a scan; a :class:`StepResult` is what one tracking step
returns. Nothing here knows about JSON, Zenoh or HTTP.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from trackers.coverage import Coverage

__all__ = ["Extent", "Scan", "ScanRejected", "StepResult", "TrackSnapshot"]


class ScanRejected(ValueError):
    """A scan the tracker refuses as a whole; tracker state is left unchanged.

    ``reason`` is a short machine-readable code (``"out_of_sequence"``, ``"invalid_scan"``),
    ``detail`` a human-readable sentence.
    """

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True, eq=False)
class Scan:
    """One sensor's detections at one time.

    Attributes
    ----------
    sensor_id : the sensor that produced the scan.
    time : seconds on the shared epoch.
    z : ``(n, 2)`` measured positions ``[x, y]`` in metres.
    R : ``(n, 2, 2)`` measurement covariances in m² (symmetric positive definite).
    detection_ids : ``n`` optional detection ids, echoed back in tracks.
    pd : the sensor's detection probability for this scan, or ``None`` for the configured one.
    clutter_density : false-alarm density λ_fa per m², or ``None`` for the configured one.
    sensor_position : ``(2,)`` sensor position, needed to use range-rates.
    sensor_velocity : ``(2,)`` sensor velocity (m/s) for range-rates seen from a moving
        sensor (an airborne radar), or ``None`` for a sensor at rest.
    clutter_map : ``(n,)`` false-alarm densities per m² at the detections, learned by the
        pipeline's clutter map for a scan that states no ``clutter_density`` (or ``None``).
    clutter_scene : the false-alarm density per m² of the sensor's whole scene, learned by the
        same map for such a scan (or ``None``): how far apart its false alarms lie on average
        anywhere it looks, what a cluster of detections must beat to be a group.
    clutter_around : for such a scan, the false-alarm density per m² the same map learned
        about given positions ``(m, 2) -> (m,)`` (:meth:`~trackers.clutter.ClutterMap.around`:
        a block of cells a few kilometres across for a radar), or ``None``. It reads the
        pipeline's map when called: call it while the pipeline processes this scan (the map
        learns from the scan after every tracker has taken it).
    coverage : the area the sensor looked at (:class:`~trackers.coverage.Coverage`): a track
        outside it is not counted as missed. ``None``: everywhere, or, when several sensors
        report, where this one has been seeing things (the pipeline's learned coverage).
    range_rate : ``(n,)`` range-rates in m/s, NaN where a detection has none (or ``None``).
    amplitude : ``(n,)`` amplitudes, NaN where absent (or ``None``).
    """

    sensor_id: str
    time: float
    z: np.ndarray
    R: np.ndarray
    detection_ids: tuple[str | None, ...] = ()
    pd: float | None = None
    clutter_density: float | None = None
    sensor_position: np.ndarray | None = None
    range_rate: np.ndarray | None = None
    amplitude: np.ndarray | None = None
    sensor_velocity: np.ndarray | None = None
    coverage: Coverage | None = None
    clutter_map: np.ndarray | None = None
    clutter_scene: float | None = None
    clutter_around: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self) -> None:
        z = np.asarray(self.z, dtype=float).reshape(-1, 2)
        R = np.asarray(self.R, dtype=float).reshape(-1, 2, 2)
        if R.shape[0] != z.shape[0]:
            raise ScanRejected(
                "invalid_scan", f"{z.shape[0]} detections but {R.shape[0]} covariances"
            )
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "R", R)
        ids = tuple(self.detection_ids) if self.detection_ids else (None,) * z.shape[0]
        if len(ids) != z.shape[0]:
            raise ScanRejected("invalid_scan", f"{z.shape[0]} detections but {len(ids)} ids")
        object.__setattr__(self, "detection_ids", ids)
        for name in ("sensor_position", "sensor_velocity"):
            value = getattr(self, name)
            if value is not None:
                arr = np.asarray(value, dtype=float).reshape(-1)
                if arr.shape[0] != 2:
                    raise ScanRejected("invalid_scan", f"{name}: must be [x, y]")
                object.__setattr__(self, name, arr)
        for name in ("range_rate", "amplitude", "clutter_map"):
            value = getattr(self, name)
            if value is not None:
                arr = np.asarray(value, dtype=float).reshape(-1)
                if arr.shape[0] != z.shape[0]:
                    raise ScanRejected(
                        "invalid_scan", f"{z.shape[0]} detections but {arr.shape[0]} {name}s"
                    )
                object.__setattr__(self, name, arr)

    @property
    def size(self) -> int:
        """Number of detections."""
        return int(self.z.shape[0])

    @cached_property
    def detection_id_groups(self) -> np.ndarray:
        """``(n,)`` object array: each detection's id as the group of ids a track that takes
        it holds, ``(id,)``, or ``()`` for a detection without one (made once a scan)."""
        ids = self.detection_ids
        if ids.count(None) == len(ids):
            out = np.empty(len(ids), dtype=object)
            out.fill(())
            return out
        groups = [() if i is None else (i,) for i in ids]
        return np.fromiter(groups, dtype=object, count=len(groups))

    def subset(self, keep: np.ndarray) -> Scan:
        """The same scan restricted to the detections where the boolean mask ``keep`` is true."""
        keep = np.asarray(keep, dtype=bool)
        idx = np.flatnonzero(keep)
        return Scan(
            sensor_id=self.sensor_id,
            time=self.time,
            z=self.z[idx],
            R=self.R[idx],
            detection_ids=tuple([self.detection_ids[i] for i in idx.tolist()]),
            pd=self.pd,
            clutter_density=self.clutter_density,
            sensor_position=self.sensor_position,
            range_rate=None if self.range_rate is None else self.range_rate[idx],
            amplitude=None if self.amplitude is None else self.amplitude[idx],
            sensor_velocity=self.sensor_velocity,
            coverage=self.coverage,
            clutter_map=None if self.clutter_map is None else self.clutter_map[idx],
            clutter_scene=self.clutter_scene,
            clutter_around=self.clutter_around,
        )


@dataclass(frozen=True)
class Extent:
    """An extent ellipse: ``matrix`` (2x2, m²), its ``semi_axes`` (m) and ``orientation`` (rad)."""

    matrix: np.ndarray
    semi_axes: tuple[float, float]
    orientation: float


class TrackSnapshot(NamedTuple):
    """An immutable picture of one track at ``time``.

    ``covariance`` is 4x4 over ``[x, y, vx, vy]``. The optional fields are filled by the track
    kinds that have them (extent, point-pattern attitude and shape, formation membership).
    A named tuple, because thousands are made each scan and a tuple is the cheapest to build.
    """

    id: str
    kind: str
    status: str
    time: float
    position: tuple[float, float]
    velocity: tuple[float, float]
    covariance: np.ndarray
    score: float
    hits: int
    created: float
    updated: float
    model_probabilities: dict[str, float] | None = None
    detection_ids: tuple[str, ...] = ()
    extent: Extent | None = None
    attitude: float | None = None
    shape_probabilities: dict[str, float] | None = None
    members: tuple[str, ...] | None = None
    formation_id: str | None = None

    @property
    def confirmed(self) -> bool:
        return self.status == "confirmed"


@dataclass(frozen=True, eq=False)
class StepResult:
    """What one tracking step returns: the ids deleted, and every live track;
    ``range_rates``, the range-rates that came with the detections confirmed individual tracks
    took, and how many of them fitted their tracks and were used.

    ``tracks`` (tentative too) and ``confirmed()`` are built on first use from
    ``snapshot(confirmed_only)``, which reads the tracker's state as it was after this step:
    most callers want only the confirmed tracks, and thousands of short-lived tentative ones
    are not worth building for them.
    """

    time: float
    sensor_id: str
    deleted: tuple[str, ...]
    snapshot: Callable[[bool], tuple[TrackSnapshot, ...]]
    range_rates: tuple[int, int] = (0, 0)

    @cached_property
    def tracks(self) -> tuple[TrackSnapshot, ...]:
        return self.snapshot(False)

    @cached_property
    def _confirmed(self) -> tuple[TrackSnapshot, ...]:
        if "tracks" in self.__dict__:
            return tuple(t for t in self.tracks if t.confirmed)
        return self.snapshot(True)

    def confirmed(self) -> tuple[TrackSnapshot, ...]:
        return self._confirmed
