"""Reproducible multi-target scenarios: truth trajectories, detections and clutter.

Shared by the tests, the benchmarks and the demo publisher. Everything is drawn from one
``numpy.random.Generator`` seeded with ``ScenarioConfig.seed``, so a config always gives the
same scans. Computation is vectorised over targets.

Truth
-----
States are ``[x, y, vx, vy]`` (m, m/s). At the first scan time ``n_targets`` targets (ids
``0..n_targets−1``) start uniformly in ``init_area`` with velocities ``N(0, init_velocity_std²)``
per axis, unless ``initial_states`` fixes them. Between consecutive scan times (of all sensors,
so every sensor sees the same truth) each target moves by the exact discretisation of the
nearly constant velocity (NCV) model over the interval ``T``: ``x' = F x + w``,
``w ~ N(0, Q)``, ``Q = q [[T³/3, T²/2], [T²/2, T]]`` per axis (see
:func:`trackers.evaluation.crb.cv_matrices`).

If ``turn_rate_std > 0`` each target also has a turn rate ω (rad/s) and its deterministic
motion is the exact coordinated turn at ω; the NCV noise ``w`` is still added. ω is redrawn
at the switching times of a Poisson process of rate ``1/TURN_SEGMENT_MEAN`` (mean segment
length 15 s), evaluated per propagation interval (a switch takes effect at the start of the
interval in which it falls). A drawn ω is 0 (straight flight) with probability 1/2 and
``N(0, turn_rate_std²)`` otherwise; the initial ω is drawn the same way.

If ``birth_death`` is true, targets die and are born at the scan times. With
``L = BIRTH_DEATH_LIFETIME_FRACTION · n_scans · dt`` (half the scenario duration), over an
interval ``T`` each target dies with probability ``1 − exp(−T/L)`` and
``Poisson(n_targets · T / L)`` targets are born (uniform in ``init_area``, velocity as at the
start) with fresh increasing ids, so the expected number alive stays ``n_targets``.

Detections
----------
Each sensor scans every ``dt`` starting at its ``time_offset``; scans are returned in time
order, ties in sensor order. In a scan, each live target is detected with probability ``pd``
at ``z = [x, y] + N(0, σ² I)`` (``R = σ² I``); ``Poisson(clutter_mean)`` false alarms are
uniform over ``area`` (clutter density ``clutter_mean / |area|`` per m²). Detections are
shuffled so their order carries no information; ``target_of_detection`` gives each
detection's target id (−1 for clutter). Detection ids are ``"s{i}-d{j}"`` with ``i`` the
scan's index in the returned list (unique across sensors) and ``j`` its index in the scan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trackers.types import Scan

__all__ = [
    "BIRTH_DEATH_LIFETIME_FRACTION",
    "TURN_SEGMENT_MEAN",
    "Area",
    "ScenarioConfig",
    "SensorSpec",
    "SimulatedScan",
    "crossing_scenario",
    "draw_turn_rates",
    "move_targets",
    "ncv_noise",
    "reference_scenario",
    "scale_scenario",
    "simulate",
]

Area = tuple[tuple[float, float], tuple[float, float]]
"""``((x_min, x_max), (y_min, y_max))`` in metres."""

TURN_SEGMENT_MEAN = 15.0
"""Mean time (s) between turn-rate switches when ``turn_rate_std > 0``."""

BIRTH_DEATH_LIFETIME_FRACTION = 0.5
"""Mean target lifetime, as a fraction of the scenario duration ``n_scans · dt``."""


def _finite(name: str, value: float, lower: float, strict: bool) -> None:
    ok = isinstance(value, int | float) and math.isfinite(value)
    ok = ok and (value > lower if strict else value >= lower)
    if not ok:
        raise ValueError(f"{name}: must be a finite number {'>' if strict else '>='} {lower}")


def _area(name: str, value: Any) -> Area:
    try:
        (x0, x1), (y0, y1) = value
        area = ((float(x0), float(x1)), (float(y0), float(y1)))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: must be ((x_min, x_max), (y_min, y_max))") from exc
    if not all(math.isfinite(v) for pair in area for v in pair):
        raise ValueError(f"{name}: bounds must be finite")
    if not (area[0][0] < area[0][1] and area[1][0] < area[1][1]):
        raise ValueError(f"{name}: each minimum must be below its maximum, got {area}")
    return area


@dataclass(frozen=True)
class SensorSpec:
    """One simulated sensor: detection probability, noise std (m), mean false alarms per scan,
    time offset of its scans (s) and its position (m, passed along in the batches)."""

    sensor_id: str = "radar-1"
    pd: float = 0.9
    sigma: float = 5.0
    clutter_mean: float = 10.0
    time_offset: float = 0.0
    position: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if not (isinstance(self.pd, int | float) and 0 <= self.pd <= 1):
            raise ValueError(f"pd: must be in [0, 1], got {self.pd!r}")
        _finite("sigma", self.sigma, 0.0, strict=True)
        _finite("clutter_mean", self.clutter_mean, 0.0, strict=False)
        _finite("time_offset", self.time_offset, -math.inf, strict=True)
        x, y = self.position
        object.__setattr__(self, "position", (float(x), float(y)))


@dataclass(frozen=True)
class ScenarioConfig:
    """A scenario; see the module docstring for the truth and detection models.

    ``q`` is the NCV white-noise acceleration PSD (m²/s³), ``turn_rate_std`` (rad/s) enables
    piecewise coordinated turns, ``birth_death`` random births and deaths.
    ``initial_states`` (an addition to the basic contract, used by
    :func:`crossing_scenario`) fixes the ``n_targets`` initial ``[x, y, vx, vy]`` instead of
    drawing them.
    """

    n_targets: int = 50
    n_scans: int = 100
    dt: float = 1.0
    area: Area = ((-1000.0, 1000.0), (-1000.0, 1000.0))
    init_area: Area = ((-600.0, 600.0), (-600.0, 600.0))
    init_velocity_std: float = 5.0
    q: float = 0.05
    sensors: tuple[SensorSpec, ...] = (SensorSpec(),)
    turn_rate_std: float = 0.0
    birth_death: bool = False
    seed: int = 0
    initial_states: tuple[tuple[float, float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        for name in ("n_targets", "n_scans", "seed"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{name}: must be an integer >= 0, got {value!r}")
        _finite("dt", self.dt, 0.0, strict=True)
        _finite("init_velocity_std", self.init_velocity_std, 0.0, strict=False)
        _finite("q", self.q, 0.0, strict=False)
        _finite("turn_rate_std", self.turn_rate_std, 0.0, strict=False)
        object.__setattr__(self, "area", _area("area", self.area))
        object.__setattr__(self, "init_area", _area("init_area", self.init_area))
        sensors = tuple(self.sensors)
        if not sensors or not all(isinstance(s, SensorSpec) for s in sensors):
            raise ValueError("sensors: must be a non-empty tuple of SensorSpec")
        if len({s.sensor_id for s in sensors}) != len(sensors):
            raise ValueError("sensors: sensor ids must be unique")
        object.__setattr__(self, "sensors", sensors)
        if self.initial_states is not None:
            states = tuple(tuple(float(v) for v in s) for s in self.initial_states)
            if len(states) != self.n_targets or any(len(s) != 4 for s in states):
                raise ValueError("initial_states: must hold n_targets states [x, y, vx, vy]")
            object.__setattr__(self, "initial_states", states)


@dataclass(frozen=True, eq=False)
class SimulatedScan:
    """One simulated sensor scan with its ground truth. Arrays are read-only.

    ``truth_ids`` ``(k,)`` and ``truth_states`` ``(k, 4)`` are the live targets at ``time``
    (ascending ids); ``z`` ``(n, 2)``, ``R`` ``(n, 2, 2)``, ``target_of_detection`` ``(n,)``
    (−1 = clutter) and ``detection_ids`` describe the detections. ``sensor_position`` (an
    addition to the basic contract) is the sensor's position, needed by :meth:`to_batch`.
    """

    time: float
    sensor_id: str
    truth_ids: np.ndarray
    truth_states: np.ndarray
    z: np.ndarray
    R: np.ndarray
    target_of_detection: np.ndarray
    detection_ids: tuple[str, ...]
    pd: float
    clutter_density: float
    sensor_position: tuple[float, float] = field(default=(0.0, 0.0))

    def to_scan(self) -> Scan:
        """The scan as a :class:`trackers.types.Scan` (own copies of the arrays)."""
        return Scan(
            sensor_id=self.sensor_id,
            time=float(self.time),
            z=self.z.copy(),
            R=self.R.copy(),
            detection_ids=tuple(self.detection_ids),
            pd=float(self.pd),
            clutter_density=self._clutter_density(),
            sensor_position=np.asarray(self.sensor_position, dtype=float),
        )

    def to_batch(self) -> dict[str, Any]:
        """The detection batch of the service contract, with plain Python values only::

        {"sensor_id": str, "time": float,
         "detections": [{"x": float, "y": float, "cov": [[..], [..]], "id": str}, ...],
         "pd": float, "clutter_density": float, "sensor_position": [x, y]}

        ``clutter_density`` is left out when the sensor has no clutter.
        """
        detections = [
            {"x": float(x), "y": float(y), "cov": cov, "id": str(det_id)}
            for (x, y), cov, det_id in zip(
                self.z.tolist(), self.R.tolist(), self.detection_ids, strict=True
            )
        ]
        batch: dict[str, Any] = {
            "sensor_id": str(self.sensor_id),
            "time": float(self.time),
            "detections": detections,
            "pd": float(self.pd),
            "sensor_position": [float(v) for v in self.sensor_position],
        }
        if self._clutter_density() is not None:
            batch["clutter_density"] = float(self.clutter_density)
        return batch

    def _clutter_density(self) -> float | None:
        """The contract wants λ_fa > 0: a sensor simulated without clutter states none, and
        the tracker's configured density applies."""
        return float(self.clutter_density) if self.clutter_density > 0 else None


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def _uniform(rng: np.random.Generator, area: Area, count: int) -> np.ndarray:
    """``(count, 2)`` points uniform over ``area``."""
    (x0, x1), (y0, y1) = area
    return rng.uniform((x0, y0), (x1, y1), size=(count, 2))


def _draw_targets(rng: np.random.Generator, config: ScenarioConfig, count: int) -> np.ndarray:
    """``(count, 4)`` states uniform in ``init_area`` with N(0, init_velocity_std²) velocities."""
    position = _uniform(rng, config.init_area, count)
    velocity = config.init_velocity_std * rng.standard_normal((count, 2))
    return np.hstack([position, velocity])


def draw_turn_rates(rng: np.random.Generator, std: float, count: int) -> np.ndarray:
    """``count`` turn rates: 0 with probability 1/2, else N(0, std²)."""
    straight = rng.random(count) < 0.5
    return np.where(straight, 0.0, std * rng.standard_normal(count))


def ncv_noise(rng: np.random.Generator, q: float, T: float, count: int) -> np.ndarray:
    """``(count, 4)`` samples of ``N(0, Q)``, Q the NCV noise over ``T``.

    Per axis ``Q = q [[T³/3, T²/2], [T²/2, T]] = L Lᵀ`` with the Cholesky factor
    ``L = √q [[√(T³/3), 0], [√(3T)/2, √T/2]]`` (valid for q = 0 too).
    """
    n = rng.standard_normal((2, count, 2))  # (component, target, axis)
    s = math.sqrt(q)
    position = s * math.sqrt(T**3 / 3.0) * n[0]
    velocity = s * (math.sqrt(3.0 * T) / 2.0 * n[0] + math.sqrt(T) / 2.0 * n[1])
    return np.hstack([position, velocity])


def move_targets(states: np.ndarray, omega: np.ndarray | None, T: float) -> np.ndarray:
    """Deterministic motion over ``T``: constant velocity, or exact coordinated turn at ω.

    With ``a = ωT``: ``p' = p + T [[sinc a, −(1−cos a)/a], [(1−cos a)/a, sinc a]] v`` and
    ``v' = [[cos a, −sin a], [sin a, cos a]] v``, using ``sin a / a = sinc`` and
    ``(1 − cos a)/a = (a/2) sinc²(a/2)`` (no division, exact at ω = 0).
    """
    x, y, vx, vy = states.T
    if omega is None:
        return np.column_stack([x + T * vx, y + T * vy, vx, vy])
    a = omega * T
    s1 = T * np.sinc(a / np.pi)
    c1 = T * (a / 2.0) * np.sinc(a / (2.0 * np.pi)) ** 2
    cos_a, sin_a = np.cos(a), np.sin(a)
    return np.column_stack(
        [
            x + s1 * vx - c1 * vy,
            y + c1 * vx + s1 * vy,
            cos_a * vx - sin_a * vy,
            sin_a * vx + cos_a * vy,
        ]
    )


def simulate(config: ScenarioConfig) -> list[SimulatedScan]:
    """All scans of ``config``, in time order (ties in sensor order); reproducible by seed."""
    rng = np.random.default_rng(config.seed)
    sensors = config.sensors
    k = np.arange(config.n_scans, dtype=float)
    times = np.concatenate([s.time_offset + k * config.dt for s in sensors])
    which = np.repeat(np.arange(len(sensors)), config.n_scans)
    order = np.lexsort((which, times))
    if order.size == 0:
        return []

    turning = config.turn_rate_std > 0
    lifetime = BIRTH_DEATH_LIFETIME_FRACTION * config.n_scans * config.dt
    if config.initial_states is not None:
        states = np.array(config.initial_states, dtype=float).reshape(-1, 4)
    else:
        states = _draw_targets(rng, config, config.n_targets)
    ids = np.arange(states.shape[0])
    next_id = states.shape[0]
    omega = draw_turn_rates(rng, config.turn_rate_std, ids.size) if turning else None

    area = config.area
    area_size = (area[0][1] - area[0][0]) * (area[1][1] - area[1][0])
    now = float(times[order[0]])
    scans: list[SimulatedScan] = []
    for index, slot in enumerate(order):
        t = float(times[slot])
        T = t - now
        if T > 0:
            if config.birth_death:
                alive = rng.random(ids.size) >= -math.expm1(-T / lifetime)
                states, ids = states[alive], ids[alive]
                omega = None if omega is None else omega[alive]
            if omega is not None:
                switch = rng.random(ids.size) < -math.expm1(-T / TURN_SEGMENT_MEAN)
                new = draw_turn_rates(rng, config.turn_rate_std, ids.size)
                omega = np.where(switch, new, omega)
            states = move_targets(states, omega, T) + ncv_noise(rng, config.q, T, ids.size)
            if config.birth_death:
                born = int(rng.poisson(config.n_targets * T / lifetime))
                if born:
                    states = np.vstack([states, _draw_targets(rng, config, born)])
                    ids = np.concatenate([ids, np.arange(next_id, next_id + born)])
                    next_id += born
                    if omega is not None:
                        rates = draw_turn_rates(rng, config.turn_rate_std, born)
                        omega = np.concatenate([omega, rates])
            now = t

        sensor = sensors[which[slot]]
        detected = rng.random(ids.size) < sensor.pd
        n_hit = int(np.count_nonzero(detected))
        z_hit = states[detected, :2] + sensor.sigma * rng.standard_normal((n_hit, 2))
        n_clutter = int(rng.poisson(sensor.clutter_mean))
        z = np.vstack([z_hit, _uniform(rng, area, n_clutter)])
        owner = np.concatenate([ids[detected], np.full(n_clutter, -1)]).astype(np.int64)
        perm = rng.permutation(z.shape[0])
        z, owner = z[perm], owner[perm]
        n = z.shape[0]
        R = np.broadcast_to(sensor.sigma**2 * np.eye(2), (n, 2, 2)).copy()
        scans.append(
            SimulatedScan(
                time=t,
                sensor_id=sensor.sensor_id,
                truth_ids=_readonly(ids.astype(np.int64)),
                truth_states=_readonly(states.copy()),
                z=_readonly(z),
                R=_readonly(R),
                target_of_detection=_readonly(owner),
                detection_ids=tuple(f"s{index}-d{j}" for j in range(n)),
                pd=float(sensor.pd),
                clutter_density=float(sensor.clutter_mean / area_size),
                sensor_position=sensor.position,
            )
        )
    return scans


def reference_scenario(seed: int = 0) -> ScenarioConfig:
    """The reference scenario: 50 targets, 100 scans at T = 1 s, clutter area ±1000 m,
    starts in ±600 m, velocities N(0, 5²) m/s, q = 0.05 m²/s³, one sensor with Pd 0.9,
    σ = 5 m and 10 false alarms per scan."""
    return ScenarioConfig(seed=seed)


def scale_scenario(
    n_targets: int = 1000, clutter_mean: float = 1000.0, n_scans: int = 30, seed: int = 0
) -> ScenarioConfig:
    """A load scenario: ``n_targets`` in a 20 km x 20 km area (±10000 m), starts in ±8000 m,
    velocities N(0, 10²) m/s, ``clutter_mean`` false alarms per scan, otherwise as the
    reference (T = 1 s, q = 0.05, Pd 0.9, σ = 5 m)."""
    return ScenarioConfig(
        n_targets=n_targets,
        n_scans=n_scans,
        area=((-10000.0, 10000.0), (-10000.0, 10000.0)),
        init_area=((-8000.0, 8000.0), (-8000.0, 8000.0)),
        init_velocity_std=10.0,
        sensors=(SensorSpec(clutter_mean=clutter_mean),),
        seed=seed,
    )


def crossing_scenario(
    n_targets: int = 4,
    speed: float = 10.0,
    radius: float = 500.0,
    spread: float = math.pi / 2,
    n_scans: int = 100,
    clutter_mean: float = 10.0,
    q: float = 0.01,
    seed: int = 0,
) -> ScenarioConfig:
    """Targets converging on one point, for association tests.

    Target ``i`` of ``n`` flies at ``speed`` (m/s) along heading
    ``θ_i = −spread/2 + i · spread/(n − 1)`` (θ = 0 for a single target), starting at
    ``−radius · (cos θ_i, sin θ_i)``; without process noise all of them pass through the
    origin together at ``t = radius / speed`` (50 s by default, mid-run), adjacent paths
    crossing at ``spread/(n − 1)`` (30° by default). The small default ``q`` keeps the
    crossing tight (position std ≈ 20 m at 50 s). The rest is the reference scenario
    (T = 1 s, area ±1000 m, Pd 0.9, σ = 5 m).
    """
    if n_targets < 1:
        raise ValueError("n_targets: must be >= 1")
    theta = np.linspace(-spread / 2, spread / 2, n_targets) if n_targets > 1 else np.zeros(1)
    heading = np.column_stack([np.cos(theta), np.sin(theta)])
    states = np.hstack([-radius * heading, speed * heading])
    return ScenarioConfig(
        n_targets=n_targets,
        n_scans=n_scans,
        q=q,
        sensors=(SensorSpec(clutter_mean=clutter_mean),),
        seed=seed,
        initial_states=tuple((float(a), float(b), float(c), float(d)) for a, b, c, d in states),
    )
