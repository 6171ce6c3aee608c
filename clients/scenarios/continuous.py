"""A scenario that never ends, for the demo: targets come and go as in life.

At the start ``mean_targets`` targets are already in the area. From then on targets are born
at random times (a Poisson process of rate ``mean_targets / mean_lifetime`` per second, so
about ``mean_targets`` would be alive at any time; some leave the area sooner, so
about 80 % of that are), each at a uniform place in the area with a
heading uniform in [0, 2π) and a speed of its class: people walking (1-2 m/s), cars
(8-30 m/s), helicopters (30-70 m/s) or airliners (120-250 m/s). Each lives for an
exponential while (mean ``mean_lifetime`` s) and then stops being seen, or leaves the area
before that; so tracks end and start one by one, never all at once. Targets fly nearly
constant velocity (NCV noise ``q``) with a turn rate redrawn now and then (0 half the time).

One radar at ``sensor_position`` scans every ``dt`` s: each live target is detected with
probability ``pd`` at ``σ = sigma`` m, and ``Poisson(clutter_mean)`` false alarms fall
uniformly over the area. Everything is drawn from one generator seeded with ``seed``: the
same seed gives the same scans. :meth:`ContinuousScenario.scans` yields them forever.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from clients.scenarios.multitarget import (
    Area,
    SimulatedScan,
    draw_turn_rates,
    move_targets,
    ncv_noise,
)

__all__ = ["SPEED_CLASSES", "ContinuousScenario"]

#: (name, lowest speed, highest speed m/s, share of the births)
SPEED_CLASSES: tuple[tuple[str, float, float, float], ...] = (
    ("walker", 1.0, 2.0, 0.15),
    ("car", 8.0, 30.0, 0.45),
    ("helicopter", 30.0, 70.0, 0.2),
    ("airliner", 120.0, 250.0, 0.2),
)

#: Mean seconds between redraws of a target's turn rate.
TURN_SEGMENT_MEAN = 20.0


@dataclass(frozen=True)
class ContinuousScenario:
    """See the module docstring."""

    seed: int = 0
    mean_targets: int = 60
    mean_lifetime: float = 120.0
    dt: float = 1.0
    area: Area = ((-10_000.0, 10_000.0), (-10_000.0, 10_000.0))
    pd: float = 0.9
    sigma: float = 10.0
    clutter_mean: float = 20.0
    q: float = 0.05
    turn_rate_std: float = 0.02
    sensor_id: str = "radar-1"
    sensor_position: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if self.mean_targets < 0 or self.seed < 0:
            raise ValueError("mean_targets and seed must be >= 0")
        for name in ("mean_lifetime", "dt", "sigma"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be finite and > 0, got {value!r}")
        if not 0 <= self.pd <= 1:
            raise ValueError(f"pd: must be in [0, 1], got {self.pd!r}")
        if not (math.isfinite(self.clutter_mean) and self.clutter_mean >= 0):
            raise ValueError("clutter_mean: must be finite and >= 0")

    @property
    def clutter_density(self) -> float:
        (x0, x1), (y0, y1) = self.area
        return self.clutter_mean / ((x1 - x0) * (y1 - y0))

    def scans(self) -> Iterator[SimulatedScan]:
        """The scans at times 0, dt, 2 dt, ... forever (truth ids never reused)."""
        rng = np.random.default_rng(self.seed)
        (x0, x1), (y0, y1) = self.area
        n0 = self.mean_targets
        states = self._births(rng, n0)
        ids = np.arange(n0, dtype=np.int64)
        next_id = n0
        ends = rng.exponential(self.mean_lifetime, n0)  # memoryless: as if born earlier
        omega = self._turn_rates(rng, n0)
        birth_rate = self.mean_targets / self.mean_lifetime
        t = 0.0
        k = 0
        while True:
            if k > 0:
                T = self.dt
                states = move_targets(states, omega, T) + ncv_noise(rng, self.q, T, len(ids))
                switch = rng.random(len(ids)) < 1.0 - math.exp(-T / TURN_SEGMENT_MEAN)
                omega = np.where(switch, self._turn_rates(rng, len(ids)), omega)
                x, y = states[:, 0], states[:, 1]
                inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
                keep = inside & (ends > t)
                states, ids, ends, omega = states[keep], ids[keep], ends[keep], omega[keep]
                born = int(rng.poisson(birth_rate * T))
                if born:
                    states = np.vstack([states, self._births(rng, born)])
                    ids = np.concatenate([ids, np.arange(next_id, next_id + born)])
                    next_id += born
                    ends = np.concatenate([ends, t + rng.exponential(self.mean_lifetime, born)])
                    omega = np.concatenate([omega, self._turn_rates(rng, born)])
            yield self._scan(rng, k, t, ids, states)
            k += 1
            t = k * self.dt

    def _births(self, rng: np.random.Generator, count: int) -> np.ndarray:
        (x0, x1), (y0, y1) = self.area
        position = np.column_stack([rng.uniform(x0, x1, count), rng.uniform(y0, y1, count)])
        shares = np.array([c[3] for c in SPEED_CLASSES])
        kind = rng.choice(len(SPEED_CLASSES), size=count, p=shares / shares.sum())
        low = np.array([c[1] for c in SPEED_CLASSES])[kind]
        high = np.array([c[2] for c in SPEED_CLASSES])[kind]
        speed = rng.uniform(low, high)
        heading = rng.uniform(0.0, 2.0 * math.pi, count)
        velocity = np.column_stack([speed * np.cos(heading), speed * np.sin(heading)])
        return np.hstack([position, velocity])

    def _turn_rates(self, rng: np.random.Generator, count: int) -> np.ndarray:
        return draw_turn_rates(rng, self.turn_rate_std, count)

    def _scan(
        self, rng: np.random.Generator, k: int, t: float, ids: np.ndarray, states: np.ndarray
    ) -> SimulatedScan:
        (x0, x1), (y0, y1) = self.area
        seen = rng.random(len(ids)) < self.pd
        z_true = states[seen, :2] + self.sigma * rng.standard_normal((int(seen.sum()), 2))
        n_fa = int(rng.poisson(self.clutter_mean))
        z_fa = np.column_stack([rng.uniform(x0, x1, n_fa), rng.uniform(y0, y1, n_fa)])
        z = np.vstack([z_true, z_fa])
        owner = np.concatenate([ids[seen], np.full(n_fa, -1, dtype=np.int64)])
        order = rng.permutation(len(z))
        z, owner = z[order], owner[order]
        R = np.broadcast_to(self.sigma**2 * np.eye(2), (len(z), 2, 2)).copy()
        for a in (ids, states, z, R, owner):
            a.setflags(write=False)
        return SimulatedScan(
            time=t,
            sensor_id=self.sensor_id,
            truth_ids=ids,
            truth_states=states,
            z=z,
            R=R,
            target_of_detection=owner,
            detection_ids=tuple(f"s{k}-d{j}" for j in range(len(z))),
            pd=self.pd,
            clutter_density=self.clutter_density,
            sensor_position=self.sensor_position,
        )
