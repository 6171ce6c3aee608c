"""Scripted scenarios with radars that measure range and bearing: targets of every speed.

Shared by the tests and the benchmarks (``python -m benchmarks.speeds``).

Truth
-----
Each :class:`ScriptedTarget` has a class name (``"parked"``, ``"airliner"``, ...), an initial
state ``[x, y, vx, vy]`` at ``t = 0`` and manoeuvres: intervals during which it turns at a
constant rate ω (rad/s), flying straight otherwise. Motion is the exact coordinated turn at ω
(straight at ω = 0), intervals split at the manoeuvre boundaries, plus the nearly constant
velocity noise of PSD ``q`` (m²/s³) of the target.

Detections
----------
A :class:`PolarRadar` at ``position`` scans every ``period`` seconds from ``time_offset``.
Each target is detected with probability ``pd``; its range ``ρ`` and bearing ``θ`` from the
radar get Gaussian noise of standard deviations ``range_std`` (m) and ``bearing_std`` (rad),
and the detection is reported in Cartesian coordinates with the linearized covariance

    R = J diag(σ_ρ², σ_θ²) Jᵀ,   J = [[cos θ, −ρ sin θ], [sin θ, ρ cos θ]]

at the measured range and bearing. False alarms: ``Poisson(clutter_mean)`` uniform over
``clutter_area``, and ``Poisson(local_clutter_mean)`` uniform in a square of half-side
``local_clutter_half_size`` around the centre of each group of targets in ``groups``
(clutter near formations), each with the covariance of its position. The batch's clutter
density is the larger of the two densities.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from clients.scenarios.multitarget import Area, SimulatedScan, move_targets, ncv_noise

__all__ = [
    "ACCELERATION_STEP",
    "AT_REST_SPEED",
    "FORMATION_GROUPS",
    "Manoeuvre",
    "PolarRadar",
    "RadarHits",
    "ScriptedScenario",
    "ScriptedTarget",
    "apron_scenario",
    "formation_scenario",
    "manoeuvre_scenario",
    "mixed_speed_scenario",
    "path_ranges",
    "radar_hits",
    "radar_scan",
    "runway_scenario",
    "simulate_scripted",
    "weaving_scenario",
]

G = 9.80665  # m/s²


@dataclass(frozen=True)
class Manoeuvre:
    """A turn at ``turn_rate`` (rad/s, counter-clockwise positive) from ``start`` for
    ``duration`` seconds, the speed changing meanwhile at ``acceleration`` (m/s² along the
    velocity; a target that brakes stops at 0, and one at rest has no heading to speed up
    along: it stays)."""

    start: float
    duration: float
    turn_rate: float
    acceleration: float = 0.0


@dataclass(frozen=True)
class ScriptedTarget:
    target_class: str
    state: tuple[float, float, float, float]
    manoeuvres: tuple[Manoeuvre, ...] = ()
    q: float = 0.0


@dataclass(frozen=True)
class PolarRadar:
    sensor_id: str
    position: tuple[float, float] = (0.0, 0.0)
    range_std: float = 50.0
    bearing_std: float = 1e-3
    pd: float = 0.9
    period: float = 4.0
    time_offset: float = 0.0
    clutter_mean: float = 100.0
    clutter_area: Area = ((-75e3, 75e3), (-75e3, 75e3))
    local_clutter_mean: float = 0.0
    local_clutter_half_size: float = 1500.0


@dataclass(frozen=True)
class ScriptedScenario:
    targets: tuple[ScriptedTarget, ...]
    radars: tuple[PolarRadar, ...]
    duration: float
    groups: tuple[tuple[int, ...], ...] = ()
    seed: int = 0

    @property
    def classes(self) -> dict[int, str]:
        """Target id → class name."""
        return {i: t.target_class for i, t in enumerate(self.targets)}


def turn_rate_at(target: ScriptedTarget, t: float) -> float:
    """The target's scripted turn rate (rad/s) at time ``t``: its manoeuvre's, or 0."""
    for m in target.manoeuvres:
        if m.start <= t < m.start + m.duration:
            return m.turn_rate
    return 0.0


def acceleration_at(target: ScriptedTarget, t: float) -> float:
    """The target's scripted acceleration along its velocity (m/s²) at time ``t``, or 0."""
    for m in target.manoeuvres:
        if m.start <= t < m.start + m.duration:
            return m.acceleration
    return 0.0


#: Step (s) of the integration of a manoeuvre that changes the speed.
ACCELERATION_STEP = 0.05


def _propagate(
    target: ScriptedTarget, state: np.ndarray, t0: float, t1: float, rng: np.random.Generator
) -> np.ndarray:
    cuts = sorted(
        {t0, t1}
        | {c for m in target.manoeuvres for c in (m.start, m.start + m.duration) if t0 < c < t1}
    )
    for a, b in itertools.pairwise(cuts):
        omega = np.array([turn_rate_at(target, a)])
        accel = acceleration_at(target, a)
        if accel == 0.0:
            state = move_targets(state[None, :], omega, b - a)[0]
            continue
        # The turn is exact over each step; the speed changes at the step's middle (the
        # midpoint rule: exact for a constant acceleration in a straight line).
        steps = max(1, math.ceil((b - a) / ACCELERATION_STEP))
        h = (b - a) / steps
        for _ in range(steps):
            state = _speed_changed(state, 0.5 * h * accel)
            state = move_targets(state[None, :], omega, h)[0]
            state = _speed_changed(state, 0.5 * h * accel)
    T = t1 - t0
    if target.q > 0 and T > 0:
        state = state + ncv_noise(rng, target.q, T, 1)[0]
    return state


def _speed_changed(state: np.ndarray, dv: float) -> np.ndarray:
    """``state [x, y, vx, vy]`` with its speed changed by ``dv`` (not below 0), the heading
    kept."""
    speed = math.hypot(state[2], state[3])
    if speed == 0.0:
        return state
    k = max(speed + dv, 0.0) / speed
    return np.array([state[0], state[1], k * state[2], k * state[3]])


def _polar_covariance(rho: np.ndarray, theta: np.ndarray, radar: PolarRadar) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    J = np.empty((rho.size, 2, 2))
    J[:, 0, 0], J[:, 0, 1] = c, -rho * s
    J[:, 1, 0], J[:, 1, 1] = s, rho * c
    D = np.diag([radar.range_std**2, radar.bearing_std**2])
    R = J @ D @ J.transpose(0, 2, 1)
    return 0.5 * (R + R.transpose(0, 2, 1))


def _polar(points: np.ndarray, radar: PolarRadar) -> tuple[np.ndarray, np.ndarray]:
    d = points - np.asarray(radar.position)
    return np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])


def _cartesian(rho: np.ndarray, theta: np.ndarray, radar: PolarRadar) -> np.ndarray:
    return np.asarray(radar.position) + np.column_stack([rho * np.cos(theta), rho * np.sin(theta)])


@dataclass(frozen=True)
class RadarHits:
    """The targets a radar detected in one scan: the mask ``detected`` over the targets,
    their noisy range ``rho`` and bearing ``theta``, and those as positions ``z``."""

    detected: np.ndarray
    rho: np.ndarray
    theta: np.ndarray
    z: np.ndarray


def radar_hits(rng: np.random.Generator, radar: PolarRadar, states: np.ndarray) -> RadarHits:
    """Each target of ``states (n, 4)`` detected with probability ``pd``, its range and
    bearing with Gaussian noise (draws in this order: detections, ranges, bearings)."""
    detected = rng.random(states.shape[0]) < radar.pd
    rho, theta = _polar(states[detected, :2], radar)
    rho = rho + radar.range_std * rng.standard_normal(rho.size)
    theta = theta + radar.bearing_std * rng.standard_normal(theta.size)
    return RadarHits(detected, rho, theta, _cartesian(rho, theta, radar))


def radar_scan(
    rng: np.random.Generator,
    radar: PolarRadar,
    t: float,
    index: int,
    states: np.ndarray,
    hits: RadarHits,
    clutter: np.ndarray,
    density: float,
) -> SimulatedScan:
    """The scan number ``index`` at ``t``: the hits and the false alarms ``clutter (m, 2)``
    in a random order, each with the polar covariance at its measured range and bearing;
    truth ``states`` with ids ``0..n−1``; arrays read-only."""
    ids = np.arange(states.shape[0], dtype=np.int64)
    c_rho, c_theta = _polar(clutter, radar)
    z = np.vstack([hits.z, clutter])
    R = _polar_covariance(
        np.concatenate([hits.rho, c_rho]), np.concatenate([hits.theta, c_theta]), radar
    )
    owner = np.concatenate([ids[hits.detected], np.full(clutter.shape[0], -1, dtype=np.int64)])
    perm = rng.permutation(z.shape[0])
    z, R, owner = z[perm], R[perm], owner[perm]
    truth = states.copy()
    for a in (z, R, owner, truth, ids):
        a.setflags(write=False)
    return SimulatedScan(
        time=float(t),
        sensor_id=radar.sensor_id,
        truth_ids=ids,
        truth_states=truth,
        z=z,
        R=R,
        target_of_detection=owner,
        detection_ids=tuple(f"s{index}-d{j}" for j in range(z.shape[0])),
        pd=float(radar.pd),
        clutter_density=float(density),
        sensor_position=radar.position,
    )


def simulate_scripted(scenario: ScriptedScenario) -> list[SimulatedScan]:
    """Every radar's scans in time order (ties in radar order), reproducible by seed."""
    rng = np.random.default_rng(scenario.seed)
    slots = sorted(
        (r.time_offset + k * r.period, i)
        for i, r in enumerate(scenario.radars)
        for k in range(math.floor((scenario.duration - r.time_offset) / r.period) + 1)
        if r.time_offset + k * r.period <= scenario.duration
    )
    states = np.array([t.state for t in scenario.targets], dtype=float).reshape(-1, 4)
    now = 0.0
    scans: list[SimulatedScan] = []
    for index, (t, ri) in enumerate(slots):
        if t > now:
            states = np.array(
                [
                    _propagate(target, s, now, t, rng)
                    for target, s in zip(scenario.targets, states, strict=True)
                ]
            ).reshape(-1, 4)
            now = t
        radar = scenario.radars[ri]
        hits = radar_hits(rng, radar, states)
        (x0, x1), (y0, y1) = radar.clutter_area
        n_uniform = int(rng.poisson(radar.clutter_mean))
        clutter = [rng.uniform((x0, y0), (x1, y1), size=(n_uniform, 2))]
        h = radar.local_clutter_half_size
        for group in scenario.groups:
            centre = states[list(group), :2].mean(axis=0)
            n_local = int(rng.poisson(radar.local_clutter_mean))
            clutter.append(centre + rng.uniform(-h, h, size=(n_local, 2)))
        density = radar.clutter_mean / ((x1 - x0) * (y1 - y0))
        if scenario.groups and radar.local_clutter_mean > 0:
            density = max(density, radar.local_clutter_mean / (2.0 * h) ** 2)
        scans.append(radar_scan(rng, radar, t, index, states, hits, np.vstack(clutter), density))
    return scans


def _heading_state(
    mid: tuple[float, float], speed: float, heading: float, t_mid: float
) -> tuple[float, float, float, float]:
    """The initial state of a straight flight at ``speed`` along ``heading`` that passes
    ``mid`` at ``t_mid``."""
    vx, vy = speed * math.cos(heading), speed * math.sin(heading)
    return (mid[0] - vx * t_mid, mid[1] - vy * t_mid, vx, vy)


SPEED_CLASSES = ("parked", "ground", "helicopter", "airliner", "jet")


def path_ranges(
    target: ScriptedTarget, duration: float, origin: tuple[float, float] = (0.0, 0.0)
) -> np.ndarray:
    """Distances (m) from ``origin`` of the target's noise-free path (its script without
    process noise) at every second from 0 to ``duration``."""
    bare = ScriptedTarget(target.target_class, target.state, target.manoeuvres, q=0.0)
    rng = np.random.default_rng(0)  # unused: no process noise
    state = np.asarray(target.state, dtype=float)
    points = [state[:2]]
    for t in range(1, math.floor(duration) + 1):
        state = _propagate(bare, state, t - 1.0, float(t), rng)
        points.append(state[:2])
    return np.hypot(*(np.asarray(points) - np.asarray(origin)).T)


def _drawn_within(draw, duration: float, lo: float, hi: float, attempts: int = 1000):
    """The first target ``draw()`` gives whose noise-free path stays between ``lo`` and ``hi``
    metres from the radar for the whole scenario."""
    for _ in range(attempts):
        target = draw()
        r = path_ranges(target, duration)
        if r.min() >= lo and r.max() <= hi:
            return target
    raise RuntimeError(f"no path within {lo:.0f}-{hi:.0f} m in {attempts} draws")


def mixed_speed_scenario(period: float = 4.0, duration: float = 160.0, seed: int = 0):
    """Scenario 1 of the issue on targets of every speed: one radar at the origin (range noise
    50 m, bearing 1 mrad, Pd 0.9, about 100 false alarms a scan over 150 km × 150 km) scanning
    every ``period`` seconds, watching 4 parked vehicles, 8 ground vehicles (3-35 m/s),
    4 helicopters (30-90 m/s), 8 airliners (180-280 m/s; four turn at 2-4°/s for 20-40 s) and
    two jets at 500 and 680 m/s, the faster pulling 5 g for 15 s. Every target's path (its
    script without process noise) stays 5-60 km from the radar for the whole scenario: a
    moving target's draw is repeated until it does."""
    rng = np.random.default_rng(1000 + seed)
    t_mid = duration / 2.0
    lo, hi = 5e3, 60e3
    targets: list[ScriptedTarget] = []

    def place(r_lo: float, r_hi: float) -> tuple[float, float]:
        r, a = rng.uniform(r_lo, r_hi), rng.uniform(-math.pi, math.pi)
        return r * math.cos(a), r * math.sin(a)

    for _ in range(4):
        x, y = place(lo, 50e3)
        targets.append(ScriptedTarget("parked", (x, y, 0.0, 0.0)))
    # (class, count, range band m, speed band m/s, process noise q)
    for name, count, ranges, speeds, q in (
        ("ground", 8, (8e3, 50e3), (3, 35), 0.05),
        ("helicopter", 4, (10e3, 45e3), (30, 90), 0.1),
    ):
        for _ in range(count):

            def ground_or_helicopter(name=name, ranges=ranges, speeds=speeds, q=q):
                mid, speed = place(*ranges), rng.uniform(*speeds)
                heading = rng.uniform(-math.pi, math.pi)
                return ScriptedTarget(name, _heading_state(mid, speed, heading, t_mid), q=q)

            targets.append(_drawn_within(ground_or_helicopter, duration, lo, hi))
    for i in range(8):

        def airliner(turns=i % 2 == 0):
            speed = rng.uniform(180, 280)
            manoeuvres = ()
            if turns:
                rate = math.radians(rng.uniform(2, 4)) * rng.choice([-1.0, 1.0])
                manoeuvres = (
                    Manoeuvre(rng.uniform(0.2, 0.6) * duration, rng.uniform(20, 40), float(rate)),
                )
            # Airliners cross the area on chords 12-30 km from the radar.
            heading = rng.uniform(-math.pi, math.pi)
            offset = rng.uniform(12e3, 30e3)
            mid = (-offset * math.sin(heading), offset * math.cos(heading))
            state = _heading_state(mid, speed, heading, t_mid)
            return ScriptedTarget("airliner", state, manoeuvres, 0.05)

        targets.append(_drawn_within(airliner, duration, lo, hi))
    for speed, turn in ((500.0, None), (680.0, 5.0)):

        def jet(speed=speed, turn=turn):
            # Jets cross on chords 5-25 km from the radar; the faster turns near the middle.
            heading = rng.uniform(-math.pi, math.pi)
            offset = rng.uniform(5e3, 25e3)
            mid = (-offset * math.sin(heading), offset * math.cos(heading))
            manoeuvres = ()
            if turn is not None:
                rate = turn * G / speed * rng.choice([-1.0, 1.0])
                manoeuvres = (Manoeuvre(0.45 * duration, 15.0, float(rate)),)
            state = _heading_state(mid, speed, heading, t_mid)
            return ScriptedTarget("jet", state, manoeuvres, 0.1)

        targets.append(_drawn_within(jet, duration, lo, hi))
    radar = PolarRadar("radar-1", period=period)
    return ScriptedScenario(tuple(targets), (radar,), duration, seed=seed)


#: The two formations of paper 003 (section IV, environment 1): target indices.
FORMATION_GROUPS = ((0, 1, 2, 3), (4, 5, 6, 7))


def formation_scenario(
    period: float = 1.0, duration: float = 60.0, local_clutter_mean: float = 6.0, seed: int = 0
) -> ScriptedScenario:
    """Scenario 2: paper 003's two formations of four (from (5000, 800) m at (−200, 300) m/s,
    and from (−5000, 8000) m at (100, 300) m/s, members 200-350 m apart), watched by three
    radars at (−20, 0), (0, −20) and (20, 0) km with range noise 40 m and bearing noise
    2 mrad, Pd 0.9, scanning every ``period`` seconds, each a third of a period after the
    previous one; ``local_clutter_mean`` false alarms per scan within 1.5 km of each formation
    and 10 more over 60 km × 60 km."""
    first = ((5000.0, 800.0), (5200.0, 1000.0), (5550.0, 1200.0), (5700.0, 1400.0))
    second = ((-5000.0, 8000.0), (-5200.0, 8200.0), (-5550.0, 8400.0), (-5700.0, 8600.0))
    targets = tuple(
        ScriptedTarget(f"formation-{k + 1}", (x, y, vx, vy), q=0.1)
        for k, (points, (vx, vy)) in enumerate(((first, (-200.0, 300.0)), (second, (100.0, 300.0))))
        for x, y in points
    )
    radars = tuple(
        PolarRadar(
            f"radar-{i + 1}",
            position=pos,
            range_std=40.0,
            bearing_std=2e-3,
            pd=0.9,
            period=period,
            time_offset=i * period / 3.0,
            clutter_mean=10.0,
            clutter_area=((-30e3, 30e3), (-10e3, 50e3)),
            local_clutter_mean=local_clutter_mean,
        )
        for i, pos in enumerate(((-20e3, 0.0), (0.0, -20e3), (20e3, 0.0)))
    )
    return ScriptedScenario(targets, radars, duration, groups=FORMATION_GROUPS, seed=seed)


def manoeuvre_scenario(
    speed: float = 450.0, g_load: float = 4.0, period: float = 2.0, seed: int = 0
) -> ScriptedScenario:
    """One target at ``speed`` pulling ``g_load`` g through a 90° turn after 40 s straight,
    then straight again, 30 km from a radar of range noise 50 m and bearing noise 1 mrad
    scanning every ``period`` seconds, 100 false alarms a scan over 150 km × 150 km."""
    omega = g_load * G / speed
    turn = (math.pi / 2) / omega
    duration = 40.0 + turn + 40.0
    target = ScriptedTarget(
        "manoeuvring", (-speed * 40.0, 30e3, speed, 0.0), (Manoeuvre(40.0, turn, omega),), 0.1
    )
    radar = PolarRadar("radar-1", period=period)
    return ScriptedScenario((target,), (radar,), duration, seed=seed)


def weaving_scenario(
    speed: float = 40.0, turn_rate_deg: float = 20.0, period: float = 1.0, seed: int = 0
) -> ScriptedScenario:
    """A small drone at ``speed`` weaving past a short-range radar (range noise 3 m, bearing
    noise 5 mrad, so 15-25 m across the beam; ``period`` seconds, P_D 0.8, 20 false alarms a
    scan over 12 km x 12 km), 150 s: it crosses the line of sight 3 km out, from 3 km before
    the crossing point to 3 km after it (3-4.3 km from the radar), turning ``turn_rate_deg``
    degrees a second for 1.5 s from t = 5 s (30° left) and then every 10 s for 3 s, right and
    left in turn (60°), so that its heading swings ±30° about its course. A second
    ``"drone"`` weaves the same way at half the rate 4 km out, the other way. A
    counter-drone newcomer's fixed-wing drone, which the defaults of the time lost at almost
    every turn (43 ids in 10 minutes)."""
    rng = np.random.default_rng(seed)
    omega = math.radians(turn_rate_deg)
    duration = 150.0
    targets = []
    for k, (rho, rate, side) in enumerate(((3e3, omega, 1.0), (4e3, 0.5 * omega, -1.0))):
        bearing = rng.uniform(0, 2 * math.pi)
        course = bearing + side * math.pi / 2.0
        half = 0.5 * speed * duration  # from half the path before the crossing point
        x0 = rho * math.cos(bearing) - half * math.cos(course)
        y0 = rho * math.sin(bearing) - half * math.sin(course)
        swings = (Manoeuvre(5.0 + 10.0 * i, 3.0, -rate if i % 2 else rate) for i in range(1, 15))
        turns = (Manoeuvre(5.0, 1.5, rate), *swings)
        state = (x0, y0, speed * math.cos(course), speed * math.sin(course))
        targets.append(ScriptedTarget("drone" if k else "weaving", state, turns, 0.05))
    radar = PolarRadar(
        "radar-1",
        range_std=3.0,
        bearing_std=5e-3,
        pd=0.8,
        period=period,
        clutter_mean=20.0,
        clutter_area=((-6e3, 6e3), (-6e3, 6e3)),
    )
    return ScriptedScenario(tuple(targets), (radar,), duration, seed=seed)


def runway_scenario(period: float = 4.0, seed: int = 0) -> ScriptedScenario:
    """Aircraft that change speed along straight paths starting 4-9 km from a radar (range
    noise 50 m, bearing noise 1 mrad, ``period`` seconds, P_D 0.9, 20 false alarms a scan over
    20 km x 20 km), 116 s: four ``"landing"`` aircraft at 80 m/s that brake at 2 m/s² from
    t = 40 s to 10 m/s and taxi on, and four ``"take-off"`` aircraft that taxi at 10 m/s and
    from t = 20 s speed up at 2.5 m/s² to 80 m/s. Starting places and headings are random, so
    a path may pass near the radar or leave the clutter's square (up to 16 km out)."""
    rng = np.random.default_rng(seed)
    targets = []
    for i in range(8):
        landing = i < 4
        rho, bearing, heading = (
            rng.uniform(4e3, 9e3),
            rng.uniform(0, 2 * math.pi),
            rng.uniform(0, 2 * math.pi),
        )
        speed = 80.0 if landing else 10.0
        manoeuvre = Manoeuvre(40.0, 35.0, 0.0, -2.0) if landing else Manoeuvre(20.0, 28.0, 0.0, 2.5)
        name = "landing" if landing else "take-off"
        targets.append(_speed_changer(name, rho, bearing, speed, heading, manoeuvre))
    return ScriptedScenario(tuple(targets), (_airfield_radar(period),), 116.0, seed=seed)


def _speed_changer(
    name: str, rho: float, bearing: float, speed: float, heading: float, manoeuvre: Manoeuvre
) -> ScriptedTarget:
    """A target at range ``rho`` and ``bearing`` from the origin, at ``speed`` along
    ``heading``, with one ``manoeuvre``."""
    position = (rho * math.cos(bearing), rho * math.sin(bearing))
    velocity = (speed * math.cos(heading), speed * math.sin(heading))
    return ScriptedTarget(name, (*position, *velocity), (manoeuvre,))


def _airfield_radar(period: float) -> PolarRadar:
    """A radar at the origin, 20 false alarms a scan over 20 km x 20 km."""
    return PolarRadar(
        "radar-1", period=period, clutter_mean=20.0, clutter_area=((-1e4, 1e4), (-1e4, 1e4))
    )


#: The speed (m/s) of a scripted target "at rest": 1 mm/s, which gives it the heading it
#: sets off along (it moves 4 cm in 40 s).
AT_REST_SPEED = 1e-3


def apron_scenario(period: float = 4.0, seed: int = 0) -> ScriptedScenario:
    """Targets at rest 1-3 km from a radar (range noise 50 m, bearing noise 1 mrad, so
    1-3 m across the beam; ``period`` seconds, P_D 0.9, 20 false alarms a scan over
    20 km x 20 km) that set off across the line of sight (within 17° of it) at a random time
    from 30 to 50 s, 140 s in all: four ``"take-off roll"`` aircraft speeding up at 2.5 m/s²
    for 28 s (to 70 m/s) and four ``"vehicle"`` ones at 2 m/s² for 7.5 s (to 15 m/s). A
    stopped track's gate is a few metres wide across the beam, and the target is 20-40 m
    out of it a scan after it sets off."""
    rng = np.random.default_rng(seed)
    targets = []
    for i in range(8):
        aircraft = i < 4
        rho, bearing = rng.uniform(1e3, 3e3), rng.uniform(0, 2 * math.pi)
        heading = bearing + math.copysign(math.pi / 2, rng.uniform(-1, 1)) + rng.uniform(-0.3, 0.3)
        start = rng.uniform(30.0, 50.0)
        accel, duration = (2.5, 28.0) if aircraft else (2.0, 7.5)
        name = "take-off roll" if aircraft else "vehicle"
        manoeuvre = Manoeuvre(start, duration, 0.0, accel)
        targets.append(_speed_changer(name, rho, bearing, AT_REST_SPEED, heading, manoeuvre))
    return ScriptedScenario(tuple(targets), (_airfield_radar(period),), 140.0, seed=seed)
