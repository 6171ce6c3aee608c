"""Paper 000's maneuvering and bending extended target (Dezert, SPIE 1998, section 5).

Shared by the tests and ``python -m benchmarks.bending``. One target whose reference point
(its "centre of mass") moves in the plane, whose attitude ``α`` turns, and whose shape
(the point pattern seen by the sensor) changes; state ``[x, vx, y, vy, α, α̇]`` (m, m/s, m,
m/s, rad, rad/s), as in :mod:`trackers.pattern.bending`.

Truth (noise-free, as in the paper): ``T = 1`` s, scans ``k = 1..30`` at ``t = k``, initial
state ``x(0) = [0, 100, 0, 100, 45°, 0]``. The mode of scan ``k`` is in effect over the
period ``(k − 1, k]``:

- principal: constant velocity for ``k = 1..10``, coordinated turn at −3°/s (clockwise,
  exact) for ``k = 11..20``, constant velocity for ``k = 21..30`` (mode indices 0, 1, 0);
- proper: no rotation (``α̇ = 0``) for ``k = 1..17``, then ``α̇ = 5°/s`` (indices 0, 1);
- shape: a random 5-point pattern for ``k = 1..15``, a random 4-point one from ``k = 16``
  (indices 0, 1). Patterns are uniform in ``[−L, L]²``, ``L = 10`` m, redrawn until every
  two points are at least ``MIN_POINT_SPACING`` apart (so that a point pattern matcher can
  tell them apart at the noise level; our addition).

Detections at scan ``k``: each pattern point ``q`` is detected with probability 0.9 at
``(x, y) + R(α) q + N(0, 0.3² I)``; ``Poisson(λ V)`` false alarms uniform in the square of
side ``3L = 30`` m centred on the true reference point (``λ = 0.005`` per m², ``V = 900``
m², 4.5 a scan on average). Detections are shuffled; ``point_of_detection`` tells, for
each, the pattern point it comes from (−1 for clutter).

Seeds: ``pattern_seed`` draws the patterns (the same for all Monte Carlo runs by default,
as in the paper), ``seed`` draws the detections of a run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trackers.types import Scan

__all__ = [
    "CLUTTER_DENSITY",
    "EXTENT",
    "MIN_POINT_SPACING",
    "NOISE_STD",
    "PD",
    "SCAN_PERIOD",
    "TRUE_INITIAL_STATE",
    "BendingRun",
    "BendingScan",
    "bending_scenario",
    "draw_pattern",
    "initial_covariance",
    "paper_patterns",
    "truth_modes",
]

SCAN_PERIOD = 1.0
N_SCANS = 30
EXTENT = 10.0
"""``L`` (m): patterns are drawn in ``[−L, L]²``; clutter fills a square of side ``3L``."""
PD = 0.9
CLUTTER_DENSITY = 0.005
NOISE_STD = 0.3
MIN_POINT_SPACING = 2.0
TURN_RATE = math.radians(-3.0)
ROTATION_RATE = math.radians(5.0)
TRUE_INITIAL_STATE = (0.0, 100.0, 0.0, 100.0, math.radians(45.0), 0.0)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.setflags(write=False)
    return a


def initial_covariance() -> np.ndarray:
    """Paper 000's ``P(0|0) = diag[(100 m)², (10 m/s)², (100 m)², (10 m/s)², (2°)², (2°/s)²]``."""
    d2r = math.radians(1.0)
    return np.diag([100.0**2, 10.0**2, 100.0**2, 10.0**2, (2 * d2r) ** 2, (2 * d2r) ** 2])


def draw_pattern(
    rng: np.random.Generator,
    points: int,
    extent: float = EXTENT,
    spacing: float = MIN_POINT_SPACING,
) -> np.ndarray:
    """``points`` uniform in ``[−extent, extent]²``, redrawn until pairwise ≥ ``spacing``."""
    while True:
        q = rng.uniform(-extent, extent, size=(points, 2))
        d = np.sqrt(((q[:, None] - q[None]) ** 2).sum(axis=2))
        if points < 2 or d[np.triu_indices(points, 1)].min() >= spacing:
            return q


def paper_patterns(
    pattern_seed: int = 0, counts: tuple[int, ...] = (5, 4)
) -> tuple[np.ndarray, ...]:
    """The shape patterns (default: 5 points, then 4), reproducible by ``pattern_seed``."""
    rng = np.random.default_rng(pattern_seed)
    return tuple(_readonly(draw_pattern(rng, c)) for c in counts)


def truth_modes(k: int) -> tuple[int, int, int]:
    """``(principal, proper, shape)`` mode indices in effect at scan ``k`` (1-based)."""
    return (1 if 11 <= k <= 20 else 0, 1 if k >= 18 else 0, 1 if k >= 16 else 0)


def _move(state: np.ndarray, principal: int, proper: int, T: float) -> np.ndarray:
    x, vx, y, vy, a, _ = state
    if principal == 1:
        w = TURN_RATE
        s, c = math.sin(w * T), math.cos(w * T)
        nx = x + (vx * s - vy * (1 - c)) / w
        ny = y + (vx * (1 - c) + vy * s) / w
        nvx, nvy = vx * c - vy * s, vx * s + vy * c
    else:
        nx, ny, nvx, nvy = x + vx * T, y + vy * T, vx, vy
    rate = ROTATION_RATE if proper == 1 else 0.0
    return np.array([nx, nvx, ny, nvy, a + rate * T, rate])


@dataclass(frozen=True, eq=False)
class BendingScan:
    """One scan: ``time`` (s), ``k`` (1-based), true ``state (6,)``, true ``modes``
    ``(principal, proper, shape)``, ``detections (n, 2)`` and ``point_of_detection (n,)``
    (pattern point index of the true shape, −1 for clutter). Arrays are read-only."""

    k: int
    time: float
    state: np.ndarray
    modes: tuple[int, int, int]
    detections: np.ndarray
    point_of_detection: np.ndarray

    @property
    def target_detections(self) -> np.ndarray:
        """Indices of the detections that come from the target."""
        return np.flatnonzero(self.point_of_detection >= 0)


@dataclass(frozen=True, eq=False)
class BendingRun:
    """A run: ``scans`` in time order, the ``patterns`` (shape index → ``(m, 2)``), the
    initial truth ``initial_state`` and the noise/detection parameters to give a filter."""

    scans: tuple[BendingScan, ...]
    patterns: tuple[np.ndarray, ...]
    initial_state: np.ndarray
    R: np.ndarray
    pd: float
    clutter_density: float
    dt: float

    def to_scan(self, index: int, sensor_id: str = "radar") -> Scan:
        """Scan number ``index`` (0-based) as a :class:`trackers.types.Scan`: every detection
        with the noise ``R``, ids ``k{k}d{i}``, the run's ``pd`` and clutter density."""
        sc = self.scans[index]
        n = len(sc.detections)
        return Scan(
            sensor_id,
            sc.time,
            sc.detections.copy(),
            np.tile(self.R, (n, 1, 1)),
            detection_ids=tuple(f"k{sc.k}d{i}" for i in range(n)),
            pd=self.pd,
            clutter_density=self.clutter_density,
        )


def bending_scenario(
    seed: int = 0,
    *,
    patterns: tuple[np.ndarray, ...] | None = None,
    pattern_seed: int = 0,
    scans: int = N_SCANS,
    pd: float = PD,
    clutter_density: float = CLUTTER_DENSITY,
    noise_std: float = NOISE_STD,
) -> BendingRun:
    """Paper 000's section 5 simulation (module docstring); ``seed`` draws the detections."""
    if patterns is None:
        patterns = paper_patterns(pattern_seed)
    patterns = tuple(_readonly(np.asarray(p, dtype=float)) for p in patterns)
    if len(patterns) < 2:
        raise ValueError("bending_scenario needs two patterns (shape modes 0 and 1)")
    rng = np.random.default_rng(seed)
    state = np.array(TRUE_INITIAL_STATE)
    side = 3.0 * EXTENT
    out: list[BendingScan] = []
    for k in range(1, scans + 1):
        modes = truth_modes(k)
        state = _move(state, modes[0], modes[1], SCAN_PERIOD)
        q = patterns[modes[2]]
        c, s = math.cos(state[4]), math.sin(state[4])
        pts = np.column_stack(
            [state[0] + c * q[:, 0] - s * q[:, 1], state[2] + s * q[:, 0] + c * q[:, 1]]
        )
        seen = rng.random(len(q)) < pd
        target = pts[seen] + rng.normal(0.0, noise_std, size=(int(seen.sum()), 2))
        n_fa = rng.poisson(clutter_density * side * side)
        fa = np.array([state[0], state[2]]) + rng.uniform(-side / 2, side / 2, size=(n_fa, 2))
        z = np.vstack([target, fa])
        who = np.concatenate([np.flatnonzero(seen), np.full(n_fa, -1)])
        order = rng.permutation(len(z))
        out.append(
            BendingScan(
                k=k,
                time=k * SCAN_PERIOD,
                state=_readonly(state),
                modes=modes,
                detections=_readonly(z[order]),
                point_of_detection=_readonly(who[order].astype(np.int64)),
            )
        )
    return BendingRun(
        scans=tuple(out),
        patterns=patterns,
        initial_state=_readonly(np.array(TRUE_INITIAL_STATE)),
        R=_readonly(np.eye(2) * noise_std**2),
        pd=pd,
        clutter_density=clutter_density,
        dt=SCAN_PERIOD,
    )
