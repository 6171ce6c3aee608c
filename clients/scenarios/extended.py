"""Extended objects and groups: paper 002's convoy in traffic and boat entering a harbour.

Shared by the tests and the benchmarks. Both scenarios reuse :class:`SimulatedScan` for the
detections (so ``to_scan()`` / ``to_batch()`` work) and add per-scan truth about groups,
unresolved vehicles and localized clutter in :class:`ExtendedTruthScan`. States are
``[x, y, vx, vy]`` (m, m/s). The geometry is fixed; the seed draws the independent vehicles
of the convoy scenario and every detection (``numpy.random.Generator``), so a seed always
gives the same run.

Roads
-----
A road is a polyline whose corners are rounded by circular arcs of radius
``ROAD_TURN_RADIUS``. A vehicle on a road has an arc length ``s`` and a speed that depends on
``s``: ``cruise`` away from junctions, ``slow`` within ``JUNCTION_MARGIN`` metres of a
corner's arc, and in between it brakes and accelerates at ``accel`` (``v² = slow² + 2 a d``).
The time to reach ``s`` is ``∫ ds / v(s)`` (computed on a 0.5 m grid); a vehicle following
the same road ``τ`` seconds later is at ``S(t − τ)``, so it slows at the same places and the
column closes up at junctions. Truth velocity is ``v(s)`` along the road's tangent.

Convoy scenario (:func:`convoy_scenario`)
------------------------------------------
Paper 002, section V, simulated scenario. Truth ids: 0-8 convoy members (class
``"convoy"``), 9 the overtaker (``"overtaker"``), 10-28 independent vehicles
(``"vehicle"``). Everything stays inside ``CONVOY_AREA`` (20 km × 20 km centred on the
origin).

* The convoy drives east on ``y = −2000`` from ``(−3000, −2000)``, turns 90° left (north)
  at junction J1 = ``(0, −2000)``, 60° left again at J2 = ``(0, 500)`` (heading 150°) and
  after 800 m reaches the fork F = ``(−693, 900)``. Members 0-5 go on at 150°; members 6-8
  turn 90° right onto a road at 60° (the two roads are 90° apart) and drive off. Cruise
  10 m/s, 4 m/s at junctions, braking/accelerating at 0.5 m/s². Members follow each other
  at ``CONVOY_GAPS`` metres (at cruise; 45-140 m), so the column is 665 m long on straight
  road and shorter at junctions, where neighbours can come within 20 m.
* The overtaker drives north at 17 m/s on a lane ``OVERTAKER_OFFSET`` = 15 m east of the
  J1-J2 road and passes the whole column while it is between J1 and J2 (member 8 at
  t ≈ 230 s to member 0 at t ≈ 325 s), coming within 15-22 m of each member.
* Each of the 19 other vehicles drives a straight road from a point 2.5-6.5 km from the
  centre towards the centre (±45°) at 5-20 m/s; a third of them stop for 20-60 s on the
  way (1 m/s² braking and acceleration), a third change speed once (0.5 m/s²).
* Timeline: the lead takes J1 at t ≈ 108 s (member 8 at ≈ 175 s) and J2 at ≈ 374 s
  (member 8 at ≈ 441 s); ``split_time`` ≈ 523 s, leaving 77 s of separate driving.
* ``split_time`` is when member 6 passes the fork's corner. Before it, ``group_of_target``
  is 0 for members 0-8; from the first scan at or after it, 1 for members 0-5 and 2 for
  6-8. Others are −1.

One sensor at ``(0, −10000)`` (10 km from the centre) scans every 5 s from t = 0 to 600 s
(121 scans). Each vehicle is detected with probability 0.7 (convoy members) or 0.9 (the
others). Vehicles closer than ``MERGE_DISTANCE`` = 20 m to one another (chained: connected
components) are unresolved: they give one detection, if at least one of them is detected, at
their mean position plus noise, attributed to the lowest id (``resolution_cell`` gives each
vehicle's lowest id). Noise is polar: range std 10 m, bearing std ``10 m / range`` (so
``R ≈ 100 I`` m², computed as ``J diag(σ_ρ², σ_θ²) Jᵀ`` at the measured range and bearing).
``Poisson(400)`` false alarms are uniform over the area (density 1e-6 per m², the batch's
``clutter_density``); the batch's ``pd`` is 0.9.

Harbour scenario (:func:`harbour_scenario`)
-------------------------------------------
Paper 002's maritime case. Truth ids: 0 the boat (``"boat"``), 1-4 static buoys
(``"buoy"``). The boat (hull 30 m × 8 m) comes in from the south-west at 5 m/s along
``HARBOUR_BOAT_ROUTE``, slowing to 3 m/s at the bends of the channel (0.2 m/s²; it passes
the first bend at t ≈ 230 s and is ~1.2 km along its route at the end). Per scan
it gives no detection with probability 0.1, else one, plus a second with probability 0.5;
each is uniform over its hull ellipse (semi-axes 15 m and 4 m along and across its heading)
plus measurement noise. Each buoy is detected with probability 0.9. A backwash patch
(``HARBOUR_BACKWASH``: 300 m × 100 m rectangle along the coast, rotated 20°) gives a
uniform integer 5..15 of false alarms a scan uniformly inside it (``clutter_region`` holds
its corners); elsewhere in the 5 km × 5 km area false alarms have density 1e-7 per m²
(``Poisson`` count, none inside the backwash rectangle; the batch's ``clutter_density``).
One sensor at ``(0, −3000)`` (range std 10 m, bearing std 1 mrad) scans every 2 s from
t = 0 to 300 s (151 scans). The boat's truth is its centre.

Not modelled: Doppler / range-rate, minimum detectable velocity and terrain masks, sensor
motion, and the off-road stops of paper 002's sub-convoys.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from clients.scenarios.multitarget import Area, SimulatedScan

__all__ = [
    "CONVOY_AREA",
    "CONVOY_BRANCH",
    "CONVOY_GAPS",
    "CONVOY_ROAD",
    "HARBOUR_AREA",
    "HARBOUR_BACKWASH",
    "HARBOUR_BOAT_ROUTE",
    "HARBOUR_BUOYS",
    "MERGE_DISTANCE",
    "OVERTAKER_OFFSET",
    "ROAD_TURN_RADIUS",
    "ExtendedScenarioRun",
    "ExtendedTruthScan",
    "convoy_scenario",
    "designate_boat",
    "harbour_scenario",
    "run_figures",
]

ROAD_TURN_RADIUS = 25.0
"""Radius (m) of the arcs that round the road corners."""

JUNCTION_MARGIN = 15.0
"""Distance (m) beyond a corner's arc over which a vehicle still drives at the slow speed."""

MERGE_DISTANCE = 20.0
"""Vehicles closer than this (m) give one detection in the convoy scenario."""

CONVOY_AREA: Area = ((-10e3, 10e3), (-10e3, 10e3))
CONVOY_SENSOR = (0.0, -10e3)
_FORK = (800.0 * math.cos(math.radians(150.0)), 500.0 + 800.0 * math.sin(math.radians(150.0)))
CONVOY_ROAD: tuple[tuple[float, float], ...] = (
    (-3000.0, -2000.0),
    (0.0, -2000.0),  # J1: 90° left
    (0.0, 500.0),  # J2: 60° left, then heading 150°
    (
        _FORK[0] + 4000.0 * math.cos(math.radians(150.0)),
        _FORK[1] + 4000.0 * math.sin(math.radians(150.0)),
    ),
)
"""Waypoints of the road of members 0-5 (the main sub-convoy)."""
CONVOY_BRANCH: tuple[tuple[float, float], ...] = (
    *CONVOY_ROAD[:3],
    _FORK,  # F: 90° right, then heading 60°
    (
        _FORK[0] + 4000.0 * math.cos(math.radians(60.0)),
        _FORK[1] + 4000.0 * math.sin(math.radians(60.0)),
    ),
)
"""Waypoints of the road of members 6-8 (they leave the main road at the fork)."""
CONVOY_GAPS = (70.0, 45.0, 120.0, 60.0, 95.0, 140.0, 50.0, 85.0)
"""Distances (m) between consecutive members at cruise speed (member 0 leads)."""
_CONVOY_LEAD_START = 2000.0  # lead's arc length at t = 0 (1000 m before J1)
_CONVOY_SPLIT = 6  # members >= this take the branch
OVERTAKER_OFFSET = 15.0
"""Lateral distance (m) of the overtaker's lane east of the J1-J2 road."""
_OVERTAKER_SPEED = 17.0

HARBOUR_AREA: Area = ((-2500.0, 2500.0), (-2500.0, 2500.0))
HARBOUR_SENSOR = (0.0, -3000.0)
HARBOUR_BOAT_ROUTE: tuple[tuple[float, float], ...] = (
    (-900.0, -1000.0),
    (-150.0, -150.0),
    (0.0, 250.0),
    (-200.0, 550.0),
)
HARBOUR_BUOYS: tuple[tuple[float, float], ...] = (
    (-300.0, -150.0),
    (-80.0, -330.0),
    (-110.0, 180.0),
    (110.0, 300.0),
)


def _rectangle(centre: tuple[float, float], length: float, width: float, angle: float):
    c, s = math.cos(angle), math.sin(angle)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2.0, width / 2.0]
    corners = np.asarray(centre) + local @ np.array([[c, s], [-s, c]])
    corners.setflags(write=False)
    return corners


_BACKWASH_CENTRE = (700.0, 80.0)
_BACKWASH_SIZE = (300.0, 100.0)
_BACKWASH_ANGLE = math.radians(20.0)
HARBOUR_BACKWASH = _rectangle(_BACKWASH_CENTRE, *_BACKWASH_SIZE, _BACKWASH_ANGLE)
"""``(4, 2)`` corners of the backwash rectangle (counter-clockwise)."""


@dataclass(frozen=True, eq=False)
class ExtendedTruthScan:
    """One scan with the extra truth of groups and localized clutter. Arrays are read-only.

    ``scan.truth_ids`` / ``scan.truth_states`` hold every point target alive (convoy members,
    vehicles, boat centre, buoys). ``group_of_target`` ``(k,)`` gives, per truth id in that
    order, −1 for an independent target or the group ``g >= 0`` it belongs to (convoy: 0
    before the split, then 1 = members 0-5 and 2 = members 6-8); ``groups`` maps each group
    to the ``(2,)`` centroid of its members' positions. ``resolution_cell`` ``(k,)`` is the
    lowest truth id among the targets unresolved from this one (its own id when resolved):
    the id a merged detection is attributed to. ``clutter_region`` is the ``(4, 2)``
    polygon of localized clutter (the harbour's backwash), else ``None``.
    """

    scan: SimulatedScan
    group_of_target: np.ndarray
    groups: Mapping[int, np.ndarray]
    resolution_cell: np.ndarray
    clutter_region: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ExtendedScenarioRun:
    """A whole run: ``scans`` in time order, ``target_class`` (truth id → ``"convoy"``,
    ``"vehicle"``, ``"overtaker"``, ``"boat"`` or ``"buoy"``) and ``split_time`` (s), when
    the convoy separates (``None`` without convoy)."""

    name: str
    scans: tuple[ExtendedTruthScan, ...]
    target_class: Mapping[int, str]
    split_time: float | None

    @property
    def simulated_scans(self) -> list[SimulatedScan]:
        """The plain :class:`SimulatedScan` of every scan, in time order."""
        return [s.scan for s in self.scans]


# --------------------------------------------------------------------------- roads


class _Road:
    """A polyline with corners rounded by arcs; positions and headings by arc length.

    Before ``s = 0`` and after the end the first and last segments extend straight.
    """

    def __init__(self, waypoints: Sequence[tuple[float, float]], radius: float) -> None:
        pts = np.asarray(waypoints, dtype=float)
        legs = np.diff(pts, axis=0)
        headings = np.arctan2(legs[:, 1], legs[:, 0])
        starts: list[np.ndarray] = []
        h0: list[float] = []
        kappa: list[float] = []
        lengths: list[float] = []
        corners: list[tuple[float, float]] = []  # (arc length of the arc's middle, half arc)
        current = pts[0]
        s = 0.0
        for k in range(1, len(pts) - 1):
            h_in, h_out = headings[k - 1], headings[k]
            phi = (h_out - h_in + math.pi) % (2.0 * math.pi) - math.pi
            d = radius * math.tan(abs(phi) / 2.0)
            u_in = np.array([math.cos(h_in), math.sin(h_in)])
            u_out = np.array([math.cos(h_out), math.sin(h_out)])
            a = pts[k] - d * u_in
            straight = float(np.dot(a - current, u_in))
            if straight < 0:
                raise ValueError("road: segment too short for its rounded corners")
            starts.append(current)
            h0.append(h_in)
            kappa.append(0.0)
            lengths.append(straight)
            s += straight
            arc = radius * abs(phi)
            if arc > 0:
                starts.append(a)
                h0.append(h_in)
                kappa.append(math.copysign(1.0 / radius, phi))
                lengths.append(arc)
                corners.append((s + arc / 2.0, arc / 2.0))
                s += arc
            current = pts[k] + d * u_out
        last = float(np.linalg.norm(pts[-1] - current))
        starts.append(current)
        h0.append(float(headings[-1]))
        kappa.append(0.0)
        lengths.append(last)
        self.s0 = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        self.p0 = np.array(starts)
        self.h0 = np.array(h0)
        self.kappa = np.array(kappa)
        self.length = s + last
        self.corners = tuple(corners)

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(n, 2)`` positions and ``(n,)`` headings at arc lengths ``s``."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        i = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, self.s0.size - 1)
        u = s - self.s0[i]
        h0, k = self.h0[i], self.kappa[i]
        h = h0 + k * u
        straight = k == 0.0
        ks = np.where(straight, 1.0, k)
        dx = np.where(straight, u * np.cos(h0), (np.sin(h) - np.sin(h0)) / ks)
        dy = np.where(straight, u * np.sin(h0), (np.cos(h0) - np.cos(h)) / ks)
        return self.p0[i] + np.column_stack([dx, dy]), h


class _Drive:
    """Driving along a road with a speed profile ``v(s)`` that slows at its corners.

    ``states(t)`` is the state of the vehicle at arc length ``S(t)``, ``S(0) = start``; a
    vehicle following ``τ`` seconds behind is at ``states(t − τ)``. ``span`` metres of
    straight road are added before and after the road.
    """

    STEP = 0.5

    def __init__(
        self, road: _Road, cruise: float, slow: float, accel: float, start: float, span: float
    ) -> None:
        self.road = road
        self.cruise, self.slow, self.accel = cruise, slow, accel
        grid = np.arange(-span, road.length + span, self.STEP)
        mid = grid[:-1] + self.STEP / 2.0
        dt = self.STEP / self.speed(mid)
        t = np.concatenate([[0.0], np.cumsum(dt)])
        self.grid = grid
        self.t = t - np.interp(start, grid, t)

    def speed(self, s: np.ndarray) -> np.ndarray:
        v = np.full(np.shape(s), self.cruise, dtype=float)
        for middle, half in self.road.corners:
            d = np.maximum(0.0, np.abs(s - middle) - half - JUNCTION_MARGIN)
            v = np.minimum(v, np.sqrt(self.slow**2 + 2.0 * self.accel * d))
        return v

    def arc_length(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        if np.any(t < self.t[0]) or np.any(t > self.t[-1]):
            raise ValueError("drive: time beyond the simulated stretch of road")
        return np.interp(t, self.t, self.grid)

    def states(self, t: np.ndarray) -> np.ndarray:
        """``(n, 4)`` states at times ``t``."""
        s = self.arc_length(t)
        p, h = self.road.at(s)
        v = self.speed(s)
        return np.column_stack([p, v * np.cos(h), v * np.sin(h)])


def _distance_integral(knots_t: np.ndarray, knots_v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``∫_0^t v`` for the piecewise-linear speed through the knots (constant beyond)."""
    dt = np.diff(knots_t)
    s_knots = np.concatenate([[0.0], np.cumsum(dt * (knots_v[:-1] + knots_v[1:]) / 2.0)])
    i = np.clip(np.searchsorted(knots_t, t, side="right") - 1, 0, knots_t.size - 2)
    u = np.clip(t - knots_t[i], 0.0, None)
    slope = (knots_v[i + 1] - knots_v[i]) / dt[i]
    inside = u <= dt[i]
    s_in = s_knots[i] + knots_v[i] * u + 0.5 * slope * u**2
    s_out = s_knots[i + 1] + knots_v[i + 1] * (u - dt[i])
    return np.where(inside, s_in, s_out)


@dataclass(frozen=True)
class _LineVehicle:
    """A vehicle on a straight road from ``start`` along ``heading``, speed through knots."""

    start: tuple[float, float]
    heading: float
    knots_t: np.ndarray
    knots_v: np.ndarray

    def states(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        s = _distance_integral(self.knots_t, self.knots_v, t)
        v = np.interp(t, self.knots_t, self.knots_v)
        u = np.array([math.cos(self.heading), math.sin(self.heading)])
        return np.column_stack([np.asarray(self.start) + s[:, None] * u, v[:, None] * u])


def _random_vehicle(rng: np.random.Generator, duration: float) -> _LineVehicle:
    radius, angle = rng.uniform(2500.0, 6500.0), rng.uniform(-math.pi, math.pi)
    start = (radius * math.cos(angle), radius * math.sin(angle))
    heading = angle + math.pi + rng.uniform(-math.pi / 4, math.pi / 4)
    v0 = rng.uniform(5.0, 20.0)
    kind = rng.integers(3)
    end = duration + 1.0
    if kind == 1:  # stop for a while
        t_a = rng.uniform(50.0, 400.0)
        wait = rng.uniform(20.0, 60.0)
        knots = [(0.0, v0), (t_a, v0), (t_a + v0, 0.0), (t_a + v0 + wait, 0.0)]
        knots.append((t_a + 2.0 * v0 + wait, v0))
    elif kind == 2:  # change speed once
        t_a = rng.uniform(50.0, 450.0)
        v1 = rng.uniform(5.0, 20.0)
        knots = [(0.0, v0), (t_a, v0), (t_a + abs(v1 - v0) / 0.5 + 1e-3, v1)]
    else:
        knots = [(0.0, v0)]
    knots.append((max(end, knots[-1][0] + 1.0), knots[-1][1]))
    kt, kv = np.array(knots).T
    return _LineVehicle(start, heading, kt, kv)


# --------------------------------------------------------------------------- detections


def _polar_cov(rho: np.ndarray, theta: np.ndarray, range_std: float, bearing_std) -> np.ndarray:
    """``R = J diag(σ_ρ², σ_θ²) Jᵀ`` at range ``rho`` and bearing ``theta``."""
    c, s = np.cos(theta), np.sin(theta)
    sr2 = range_std**2
    sc2 = (rho * np.asarray(bearing_std)) ** 2 * np.ones_like(rho)  # cross-range variance
    R = np.empty((rho.size, 2, 2))
    R[:, 0, 0] = c * c * sr2 + s * s * sc2
    R[:, 1, 1] = s * s * sr2 + c * c * sc2
    R[:, 0, 1] = R[:, 1, 0] = c * s * (sr2 - sc2)
    return R


class _Sensor:
    """Polar measurements; ``cross_range_std`` (m) if given, else ``bearing_std`` (rad)."""

    def __init__(
        self,
        position: tuple[float, float],
        range_std: float,
        bearing_std: float | None = None,
        cross_range_std: float | None = None,
    ) -> None:
        self.position = position
        self.range_std = range_std
        self.bearing_std = bearing_std
        self.cross_range_std = cross_range_std

    def _bearing_std(self, rho: np.ndarray):
        if self.cross_range_std is not None:
            return self.cross_range_std / np.maximum(rho, 1.0)
        return self.bearing_std

    def measure(self, rng: np.random.Generator, points: np.ndarray):
        """Noisy positions of ``points`` and their covariances."""
        d = points - np.asarray(self.position)
        rho, theta = np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])
        rho_m = rho + self.range_std * rng.standard_normal(rho.size)
        theta_m = theta + self._bearing_std(rho) * rng.standard_normal(rho.size)
        z = np.asarray(self.position) + np.column_stack(
            [rho_m * np.cos(theta_m), rho_m * np.sin(theta_m)]
        )
        return z, _polar_cov(rho_m, theta_m, self.range_std, self._bearing_std(rho_m))

    def covariance(self, points: np.ndarray) -> np.ndarray:
        """Covariances of false alarms reported at ``points``."""
        d = points - np.asarray(self.position)
        rho, theta = np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])
        return _polar_cov(rho, theta, self.range_std, self._bearing_std(rho))


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _assemble(
    rng: np.random.Generator,
    index: int,
    time: float,
    sensor: _Sensor,
    ids: np.ndarray,
    states: np.ndarray,
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
    pd: float,
    clutter_density: float,
) -> SimulatedScan:
    """A shuffled :class:`SimulatedScan` from ``(z, R, owner)`` parts."""
    z = np.vstack([p[0].reshape(-1, 2) for p in parts])
    R = np.concatenate([p[1].reshape(-1, 2, 2) for p in parts])
    owner = np.concatenate([p[2].astype(np.int64) for p in parts])
    perm = rng.permutation(z.shape[0])
    return SimulatedScan(
        time=float(time),
        sensor_id="radar-1",
        truth_ids=_readonly(ids.copy()),
        truth_states=_readonly(states.copy()),
        z=_readonly(z[perm]),
        R=_readonly(R[perm]),
        target_of_detection=_readonly(owner[perm]),
        detection_ids=tuple(f"s{index}-d{j}" for j in range(z.shape[0])),
        pd=float(pd),
        clutter_density=float(clutter_density),
        sensor_position=sensor.position,
    )


def _resolution_cells(points: np.ndarray, ids: np.ndarray, distance: float) -> np.ndarray:
    """Per point, the lowest id of its connected component under ``|p_i − p_j| < distance``."""
    d = np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))
    close = d < distance
    labels = ids.copy()
    while True:
        new = np.where(close, labels[None, :], np.iinfo(np.int64).max).min(axis=1)
        if np.array_equal(new, labels):
            return labels
        labels = new


def _uniform(rng: np.random.Generator, area: Area, count: int) -> np.ndarray:
    (x0, x1), (y0, y1) = area
    return rng.uniform((x0, y0), (x1, y1), size=(count, 2))


def _area_size(area: Area) -> float:
    (x0, x1), (y0, y1) = area
    return (x1 - x0) * (y1 - y0)


# --------------------------------------------------------------------------- convoy


def _convoy_drives() -> tuple[_Drive, _Drive, np.ndarray]:
    main = _Drive(_Road(CONVOY_ROAD, ROAD_TURN_RADIUS), 10.0, 4.0, 0.5, _CONVOY_LEAD_START, 1e3)
    branch = _Drive(_Road(CONVOY_BRANCH, ROAD_TURN_RADIUS), 10.0, 4.0, 0.5, _CONVOY_LEAD_START, 1e3)
    delays = np.concatenate([[0.0], np.cumsum(CONVOY_GAPS) / 10.0])
    return main, branch, delays


def convoy_scenario(seed: int = 0) -> ExtendedScenarioRun:
    """Paper 002's convoy of 9 in traffic of 20 vehicles, one of which overtakes it; the
    convoy turns at two junctions and splits into two sub-convoys (see the module docstring
    for the geometry and the sensor). Reproducible by ``seed``."""
    rng = np.random.default_rng(seed)
    duration, period = 600.0, 5.0
    times = np.arange(0.0, duration + period / 2.0, period)
    main, branch, delays = _convoy_drives()
    n_members = delays.size

    # Members: their state at every scan time.
    members = np.empty((times.size, n_members, 4))
    for i, tau in enumerate(delays):
        drive = branch if i >= _CONVOY_SPLIT else main
        members[:, i] = drive.states(times - tau)
    fork_middle = branch.road.corners[-1][0]
    split_time = float(np.interp(fork_middle, branch.grid, branch.t) + delays[_CONVOY_SPLIT])

    # Overtaker: 60 m behind the last member when it is 300 m past J1 (cruising north).
    j1 = main.road.corners[0]
    t_last = float(np.interp(j1[0] + j1[1] + 300.0, main.grid, main.t) + delays[-1])
    y_last = CONVOY_ROAD[1][1] + 300.0  # close enough: the arc ends ~ at J1's y
    y0 = y_last - 60.0 - _OVERTAKER_SPEED * t_last
    overtaker = _LineVehicle(
        (OVERTAKER_OFFSET, y0),
        math.pi / 2.0,
        np.array([0.0, duration + 1.0]),
        np.array([_OVERTAKER_SPEED, _OVERTAKER_SPEED]),
    )
    vehicles = [overtaker] + [_random_vehicle(rng, duration) for _ in range(19)]
    others = np.stack([v.states(times) for v in vehicles], axis=1)
    states_all = np.concatenate([members, others], axis=1)
    n = states_all.shape[1]
    ids = np.arange(n, dtype=np.int64)
    pd = np.where(ids < n_members, 0.7, 0.9)
    classes = {i: "convoy" for i in range(n_members)}
    classes[n_members] = "overtaker"
    classes.update({i: "vehicle" for i in range(n_members + 1, n)})

    sensor = _Sensor(CONVOY_SENSOR, range_std=10.0, cross_range_std=10.0)
    density = 1e-6
    clutter_mean = density * _area_size(CONVOY_AREA)
    scans: list[ExtendedTruthScan] = []
    for index, t in enumerate(times):
        states = states_all[index]
        pos = states[:, :2]
        cells = _resolution_cells(pos, ids, MERGE_DISTANCE)
        hit = rng.random(n) < pd
        detected = np.unique(cells[hit])
        centres = np.array([pos[cells == c].mean(axis=0) for c in detected]).reshape(-1, 2)
        z_hit, R_hit = sensor.measure(rng, centres)
        z_fa = _uniform(rng, CONVOY_AREA, int(rng.poisson(clutter_mean)))
        R_fa = sensor.covariance(z_fa)
        owner_fa = np.full(z_fa.shape[0], -1)
        scan = _assemble(
            rng,
            index,
            t,
            sensor,
            ids,
            states,
            [(z_hit, R_hit, detected), (z_fa, R_fa, owner_fa)],
            0.9,
            density,
        )
        group = np.full(n, -1, dtype=np.int64)
        if t < split_time:
            group[:n_members] = 0
            groups = {0: _readonly(pos[:n_members].mean(axis=0))}
        else:
            group[:_CONVOY_SPLIT] = 1
            group[_CONVOY_SPLIT:n_members] = 2
            groups = {
                1: _readonly(pos[:_CONVOY_SPLIT].mean(axis=0)),
                2: _readonly(pos[_CONVOY_SPLIT:n_members].mean(axis=0)),
            }
        scans.append(
            ExtendedTruthScan(
                scan=scan,
                group_of_target=_readonly(group),
                groups=MappingProxyType(groups),
                resolution_cell=_readonly(cells),
                clutter_region=None,
            )
        )
    return ExtendedScenarioRun("convoy", tuple(scans), MappingProxyType(classes), split_time)


# --------------------------------------------------------------------------- harbour


def _inside_rectangle(points: np.ndarray) -> np.ndarray:
    c, s = math.cos(_BACKWASH_ANGLE), math.sin(_BACKWASH_ANGLE)
    d = points - np.asarray(_BACKWASH_CENTRE)
    u, v = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
    return (np.abs(u) <= _BACKWASH_SIZE[0] / 2.0) & (np.abs(v) <= _BACKWASH_SIZE[1] / 2.0)


def harbour_scenario(seed: int = 0) -> ExtendedScenarioRun:
    """Paper 002's maritime case: a 30 m boat entering a harbour that gives at most two
    detections a scan, four buoys and a patch of backwash full of false alarms (see the
    module docstring). Reproducible by ``seed``."""
    rng = np.random.default_rng(seed)
    duration, period = 300.0, 2.0
    times = np.arange(0.0, duration + period / 2.0, period)
    boat = _Drive(_Road(HARBOUR_BOAT_ROUTE, 60.0), 5.0, 3.0, 0.2, 0.0, 500.0)
    boat_states = boat.states(times)
    buoys = np.array([[x, y, 0.0, 0.0] for x, y in HARBOUR_BUOYS])
    n = 1 + buoys.shape[0]
    ids = np.arange(n, dtype=np.int64)
    classes = {0: "boat", **{i: "buoy" for i in range(1, n)}}
    sensor = _Sensor(HARBOUR_SENSOR, range_std=10.0, bearing_std=1e-3)
    density = 1e-7
    background_mean = density * (_area_size(HARBOUR_AREA) - _BACKWASH_SIZE[0] * _BACKWASH_SIZE[1])
    c, s = math.cos(_BACKWASH_ANGLE), math.sin(_BACKWASH_ANGLE)
    rotation = np.array([[c, s], [-s, c]])
    scans: list[ExtendedTruthScan] = []
    for index, t in enumerate(times):
        states = np.vstack([boat_states[index], buoys])
        # Boat: 0, 1 or 2 points uniform over its hull ellipse.
        count = 0 if rng.random() >= 0.9 else 1 + int(rng.random() < 0.5)
        r = np.sqrt(rng.random(count))
        a = rng.uniform(0.0, 2.0 * math.pi, count)
        heading = math.atan2(states[0, 3], states[0, 2])
        along, across = 15.0 * r * np.cos(a), 4.0 * r * np.sin(a)
        ch, sh = math.cos(heading), math.sin(heading)
        hull = states[0, :2] + np.column_stack([along * ch - across * sh, along * sh + across * ch])
        buoy_hit = rng.random(buoys.shape[0]) < 0.9
        points = np.vstack([hull, buoys[buoy_hit, :2]])
        owner = np.concatenate([np.zeros(count, dtype=np.int64), ids[1:][buoy_hit]])
        z_hit, R_hit = sensor.measure(rng, points)
        # Backwash: 5..15 false alarms uniform in the rectangle.
        n_wash = int(rng.integers(5, 16))
        local = rng.uniform(-0.5, 0.5, size=(n_wash, 2)) * _BACKWASH_SIZE
        wash = np.asarray(_BACKWASH_CENTRE) + local @ rotation
        # Background clutter elsewhere (redrawn where it falls in the backwash).
        bg = _uniform(rng, HARBOUR_AREA, int(rng.poisson(background_mean)))
        while (inside := _inside_rectangle(bg)).any():
            bg[inside] = _uniform(rng, HARBOUR_AREA, int(inside.sum()))
        z_fa = np.vstack([wash, bg])
        scan = _assemble(
            rng,
            index,
            t,
            sensor,
            ids,
            states,
            [
                (z_hit, R_hit, owner),
                (z_fa, sensor.covariance(z_fa), np.full(z_fa.shape[0], -1)),
            ],
            0.9,
            density,
        )
        scans.append(
            ExtendedTruthScan(
                scan=scan,
                group_of_target=_readonly(np.full(n, -1, dtype=np.int64)),
                groups=MappingProxyType({}),
                resolution_cell=_readonly(ids.copy()),
                clutter_region=HARBOUR_BACKWASH,
            )
        )
    return ExtendedScenarioRun("harbour", tuple(scans), MappingProxyType(classes), None)


def designate_boat(run: ExtendedScenarioRun, pipeline: Any, index: int) -> bool:
    """Start the boat's extended track by hand, as paper 002 does, if scan ``index`` of
    ``run`` (just processed by ``pipeline``, a :class:`trackers.pipeline.TrackingPipeline`
    with an extended peer) has a detection of it: an operator's designation, from what the
    sensor shows. Centroid: the mean of the boat's detections, 20 m std; velocity 0 with a
    5 m/s std (a harbour craft's speed, heading unknown); extent a 20 m circle; 1.5
    detections a scan expected. Returns whether it started one."""
    sim = run.scans[index].scan
    boat = [i for i, c in run.target_class.items() if c == "boat"]
    rows = np.flatnonzero(np.isin(np.asarray(sim.target_of_detection), boat))
    peer = next((p for p in getattr(pipeline, "peers", ()) if p.kind == "extended"), None)
    if peer is None or rows.size == 0:
        return False
    peer.start(
        float(sim.time),
        sim.z[rows].mean(axis=0),
        np.zeros(2),
        np.eye(2) * 20.0**2,
        position_std=20.0,
        velocity_std=5.0,
        expected_detections=1.5,
    )
    return True


def run_figures(
    run: ExtendedScenarioRun, pipeline: Any, *, designate: bool = False
) -> dict[str, float]:
    """Track ``run`` with ``pipeline`` (anything with ``process(Scan)`` returning a step
    result, e.g. :class:`trackers.pipeline.TrackingPipeline`) and measure it; with
    ``designate``, the boat of a harbour run is started by hand at its first detection
    (:func:`designate_boat`). Always:
    ``false``, confirmed individual tracks more than 50 m from every target per scan, and
    ``ms``, the median milliseconds per scan. Convoy runs: ``near_false`` (those within 300 m
    of a convoy member per scan once the convoy has had a confirmed extended track), ``held``
    (extended tracks that were the nearest to the convoy's centroid before the split),
    ``rmse`` (that centroid's error, m), ``split`` (scans after the split until both groups
    have an extended track within 150 m), ``breaks`` (scans at which the overtaker's nearest
    confirmed individual track within 50 m is another than before, or none). Harbour runs:
    ``backwash`` (extended tracks within 150 m of the backwash after 20 scans), ``boat_breaks``
    and ``boat_held`` (the same for the extended track nearest the boat, within 100 m)."""
    convoy = run.split_time is not None
    times, false, scans = [], 0, 0
    held, errors, split_found = set(), [], {}
    backwash: set[str] = set()
    prev_ovt, breaks, ovt_scans = None, 0, 0
    near_false, near_scans = 0, 0
    boat = [i for i, c in run.target_class.items() if c == "boat"]
    prev_boat, boat_breaks, boat_scans = None, 0, 0
    centre = None if run.scans[0].clutter_region is None else run.scans[0].clutter_region.mean(0)
    designated = not (designate and boat)
    for k, ts in enumerate(run.scans):
        sim = ts.scan
        start = time.perf_counter()
        result = pipeline.process(sim.to_scan())
        times.append(1e3 * (time.perf_counter() - start))
        if not designated and designate_boat(run, pipeline, k):
            designated = True
        conf = result.confirmed()
        X = sim.truth_states[:, :2]
        ext = [t for t in conf if t.kind == "extended"]
        ind = [t for t in conf if t.kind == "individual"]
        false += sum(float(np.min(np.hypot(*(X - t.position).T))) > 50 for t in ind)
        scans += 1
        ids = list(sim.truth_ids)
        if convoy:
            members = [
                X[ids.index(i)]
                for i in run.target_class
                if run.target_class[i] == "convoy" and i in ids
            ]
            if held:  # the convoy has had a confirmed extended track
                near_scans += 1
                near_false += sum(
                    float(np.min(np.hypot(*(X - t.position).T))) > 50
                    and float(np.min(np.hypot(*(np.asarray(members) - t.position).T))) < 300
                    for t in ind
                )
            if 0 in ts.groups and ext:
                c = ts.groups[0]
                best = min(ext, key=lambda t: float(np.hypot(*(np.array(t.position) - c))))
                held.add(best.id)
                errors.append(float(np.hypot(*(np.array(best.position) - c))))
            for g in (1, 2):
                if g in ts.groups and g not in split_found:
                    c = ts.groups[g]
                    if any(np.hypot(*(np.array(t.position) - c)) < 150 for t in ext):
                        split_found[g] = (sim.time - run.split_time) / 5.0
            if 9 in ids:
                x9 = X[ids.index(9)]
                near = [(float(np.hypot(*(np.array(t.position) - x9))), t.id) for t in ind]
                near = [n for n in near if n[0] < 50]
                now = min(near)[1] if near else None
                if prev_ovt is not None:
                    ovt_scans += 1
                    breaks += now != prev_ovt
                prev_ovt = now if now is not None else prev_ovt
        else:
            if centre is not None and k >= 20:
                backwash |= {t.id for t in ext if np.hypot(*(np.array(t.position) - centre)) < 150}
            if boat and boat[0] in ids:
                xb = X[ids.index(boat[0])]
                near = [(float(np.hypot(*(np.array(t.position) - xb))), t.id) for t in ext]
                now = min(near)[1] if near and min(near)[0] < 100 else None
                if prev_boat is not None:
                    boat_scans += 1
                    boat_breaks += now != prev_boat
                prev_boat = now if now is not None else prev_boat
    out = {"false": false / scans, "ms": statistics.median(times)}
    if convoy:
        out["held"] = len(held)
        out["rmse"] = float(np.sqrt(np.mean(np.square(errors)))) if errors else float("nan")
        out["split"] = max(split_found.get(1, np.inf), split_found.get(2, np.inf))
        out["breaks"] = breaks
        out["near_false"] = near_false / max(near_scans, 1)
    else:
        out["backwash"] = len(backwash)
        out["boat_breaks"] = boat_breaks
        out["boat_held"] = float(prev_boat is not None)
    return out
