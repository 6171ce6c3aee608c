"""Paper 003's formation environments, and a turning formation, as detections of 2-D radars.

Shared by the tests and ``python -m benchmarks.formation``.

- :func:`environment_1`: two formations of four in uniform linear motion (section IV.A):
  formation 1 from (5000, 800), (5200, 1000), (5550, 1200), (5700, 1400) m at (−200, 300)
  m/s, formation 2 from (−5000, 8000), (−5200, 8200), (−5550, 8400), (−5700, 8600) m at
  (100, 300) m/s; three radars at (−20, 0), (0, −20) and (20, 0) km, range noise 40 m,
  bearing noise 2 mrad, Pd 0.9, one scan a second each, a third of a second apart (the
  fusion centre updates the formations with each sensor's batch in turn), 100 scans; with
  ``synchronized`` the three report at the same instants, as the paper's ``Z(k)`` gathers
  them (three batches of one time, in radar order).
- :func:`environment_2`: the same with clutter (Table I): per scan and per sensor,
  ``Poisson(λ1)`` false alarms uniform in the box 1 km larger on each side than formation 1,
  ``Poisson(λ2)`` in that of formation 2.
- :func:`environment_3` (ours): one formation of four, flying at 360 m/s, turns by 120° at
  4°/s as a rigid body (its shape turns with its heading, so outer members fly faster),
  seen by three radars whose scans are not synchronized (periods 1.0, 1.3 and 0.8 s, offset),
  with clutter around it.

Truth: each formation is a centre moving as a coordinated turn (straight at ω = 0) with
members at fixed offsets in the formation's frame, ``p_n = c + R(ψ − ψ₀) o_n`` and
``v_n = v_c + ω R(ψ − ψ₀) o_n⊥``. Detections are polar (range, bearing) with Gaussian noise,
reported in Cartesian coordinates with the linearized covariance, as in
:mod:`clients.scenarios.airspace`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from clients.scenarios.airspace import PolarRadar, radar_hits, radar_scan
from clients.scenarios.multitarget import SimulatedScan
from trackers.evaluation.crb import straight_line_velocity_bound
from trackers.evaluation.effective_rate import EffectiveRateCounter

__all__ = [
    "CLUTTER_LEVELS",
    "FormationFigures",
    "FormationScenario",
    "FormationTruth",
    "environment_1",
    "environment_2",
    "environment_3",
    "noise_sigma",
    "run_figures",
    "simulate_formations",
]

#: Table I of paper 003: (λ1, λ2) false alarms per scan and sensor around formations 1 and 2.
CLUTTER_LEVELS = ((1, 2), (2, 4), (3, 6), (4, 8), (5, 10), (6, 12))

_FIRST = ((5000.0, 800.0), (5200.0, 1000.0), (5550.0, 1200.0), (5700.0, 1400.0))
_SECOND = ((-5000.0, 8000.0), (-5200.0, 8200.0), (-5550.0, 8400.0), (-5700.0, 8600.0))
_RADAR_POSITIONS = ((-20e3, 0.0), (0.0, -20e3), (20e3, 0.0))


@dataclass(frozen=True)
class FormationTruth:
    """A formation: member positions at ``t = 0`` (m), the common velocity there (m/s), and
    its turns ``(start, duration, ω)`` (s, s, rad/s)."""

    members: tuple[tuple[float, float], ...]
    velocity: tuple[float, float]
    turns: tuple[tuple[float, float, float], ...] = ()
    clutter_mean: float = 0.0

    def states(self, t: float) -> np.ndarray:
        """Members' ``[x, y, vx, vy]`` at ``t`` (exact rigid-body motion)."""
        p0 = np.asarray(self.members, dtype=float)
        c = p0.mean(axis=0)
        offsets = p0 - c
        v = np.asarray(self.velocity, dtype=float)
        now, turned, omega = 0.0, 0.0, 0.0
        for start, duration, w in [*sorted(self.turns), (math.inf, 0.0, 0.0)]:
            for t1, w1 in ((min(start, t), 0.0), (min(start + duration, t), w)):
                dt = t1 - now
                if dt <= 0:
                    continue
                c, v = _move(c, v, w1, dt)
                turned += w1 * dt
                now = t1
            omega = w if start <= t < start + duration else 0.0
            if now >= t:
                break
        cs, sn = math.cos(turned), math.sin(turned)
        rot = np.array([[cs, -sn], [sn, cs]])
        r = offsets @ rot.T
        pos = c + r
        vel = v + omega * np.column_stack([-r[:, 1], r[:, 0]])
        return np.column_stack([pos, vel])


def _move(c: np.ndarray, v: np.ndarray, w: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    if abs(w) < 1e-12:
        return c + v * dt, v
    s, co = math.sin(w * dt), math.cos(w * dt)
    x = c[0] + (v[0] * s - v[1] * (1 - co)) / w
    y = c[1] + (v[0] * (1 - co) + v[1] * s) / w
    return np.array([x, y]), np.array([v[0] * co - v[1] * s, v[0] * s + v[1] * co])


@dataclass(frozen=True)
class FormationScenario:
    formations: tuple[FormationTruth, ...]
    radars: tuple[PolarRadar, ...]
    duration: float
    clutter_margin: float = 1000.0
    seed: int = 0

    @property
    def groups(self) -> tuple[tuple[int, ...], ...]:
        """Target ids of each formation."""
        out, start = [], 0
        for f in self.formations:
            out.append(tuple(range(start, start + len(f.members))))
            start += len(f.members)
        return tuple(out)

    def truth(self, t: float) -> np.ndarray:
        return np.vstack([f.states(t) for f in self.formations])


def _radars(periods: tuple[float, ...] = (1.0, 1.0, 1.0), offsets=(0.0, 0.0, 0.0)):
    return tuple(
        PolarRadar(
            f"radar-{i + 1}",
            position=pos,
            range_std=40.0,
            bearing_std=2e-3,
            pd=0.9,
            period=period,
            time_offset=offset,
            clutter_mean=0.0,
        )
        for i, (pos, period, offset) in enumerate(
            zip(_RADAR_POSITIONS, periods, offsets, strict=True)
        )
    )


def environment_1(
    seed: int = 0, scans: int = 100, *, synchronized: bool = False
) -> FormationScenario:
    """Paper 003's environment 1 (no clutter)."""
    return environment_2(0.0, 0.0, seed=seed, scans=scans, synchronized=synchronized)


def environment_2(
    lambda_1: float,
    lambda_2: float,
    seed: int = 0,
    scans: int = 100,
    *,
    synchronized: bool = False,
) -> FormationScenario:
    """Paper 003's environment 2: environment 1 with ``Poisson(λ1)`` and ``Poisson(λ2)`` false
    alarms per scan and sensor around formations 1 and 2; the radars a third of a second
    apart, or reporting together with ``synchronized``."""
    return FormationScenario(
        formations=(
            FormationTruth(_FIRST, (-200.0, 300.0), clutter_mean=float(lambda_1)),
            FormationTruth(_SECOND, (100.0, 300.0), clutter_mean=float(lambda_2)),
        ),
        radars=_radars(offsets=(0.0, 0.0, 0.0) if synchronized else (0.0, 1.0 / 3.0, 2.0 / 3.0)),
        duration=float(scans - 1),
        seed=seed,
    )


def environment_3(seed: int = 0, clutter_mean: float = 4.0) -> FormationScenario:
    """A formation of four at 360 m/s turning by 120° at 4°/s (30 s from t = 20 s) as a rigid
    body, 90 s long, seen by radars scanning every 1.0, 1.3 and 0.8 s, unsynchronized."""
    omega = math.radians(4.0)
    return FormationScenario(
        formations=(
            FormationTruth(
                _FIRST,
                (-200.0, 300.0),
                turns=((20.0, math.radians(120.0) / omega, omega),),
                clutter_mean=clutter_mean,
            ),
        ),
        radars=_radars(periods=(1.0, 1.3, 0.8), offsets=(0.0, 0.45, 0.2)),
        duration=90.0,
        seed=seed,
    )


def simulate_formations(scenario: FormationScenario) -> list[SimulatedScan]:
    """Every radar's scans in time order (ties in radar order), reproducible by seed."""
    rng = np.random.default_rng(scenario.seed)
    slots = sorted(
        (r.time_offset + k * r.period, i)
        for i, r in enumerate(scenario.radars)
        for k in range(math.floor((scenario.duration - r.time_offset) / r.period + 1e-9) + 1)
    )
    groups = scenario.groups
    scans: list[SimulatedScan] = []
    for index, (t, ri) in enumerate(slots):
        radar = scenario.radars[ri]
        states = scenario.truth(t)
        hits = radar_hits(rng, radar, states)
        clutter = [np.zeros((0, 2))]
        density = 0.0  # no clutter simulated: the scan states none, the tracker's own applies
        m = scenario.clutter_margin
        for f, group in zip(scenario.formations, groups, strict=True):
            if f.clutter_mean <= 0:
                continue
            pts = states[list(group), :2]
            lo, hi = pts.min(axis=0) - m, pts.max(axis=0) + m
            n = int(rng.poisson(f.clutter_mean))
            clutter.append(rng.uniform(lo, hi, size=(n, 2)))
            density = max(density, f.clutter_mean / float(np.prod(hi - lo)))
        scans.append(radar_scan(rng, radar, t, index, states, hits, np.vstack(clutter), density))
    return scans


# -- figures shared by the benchmark and the tests -------------------------------------------


@dataclass(frozen=True)
class FormationFigures:
    """What one run of a scenario shows: the effective tracking rate (target-scans after the
    first 5 scan times held by the same confirmed track within 3σ of the measurement noise),
    false confirmed tracks per batch, position and velocity RMS errors over the held
    target-scans (m, m/s) and per scan time (for the plots), the id changes of every target,
    the formation peer's median time per batch and formation (ms), and the formation tracks
    seen at the end. ``velocity_bound`` is the RMS over the same target-scans of the
    Cramér-Rao bound of any unbiased estimator of a lone target's velocity from its
    detections so far (straight-line motion, known noise: :func:`velocity_bounds`);
    ``formation_velocity_bound`` that of its formation's common velocity, the members known
    from their first detections."""

    rate: float
    false_per_batch: float
    rms_position: float
    rms_velocity: float
    rms_position_by_time: tuple[tuple[float, float], ...]
    rms_velocity_by_time: tuple[tuple[float, float], ...]
    id_changes: int
    formation_ms: float | None
    formations_at_end: int
    tracks_by_time: tuple[tuple[float, tuple[tuple[str, float, float], ...]], ...]
    velocity_bound: float = math.nan
    formation_velocity_bound: float = math.nan


def velocity_bounds(
    scenario: FormationScenario, sims: list[SimulatedScan], at: list[tuple[int, float]]
) -> tuple[float, float]:
    """The RMS over the target-scans ``at`` ((target id, time) pairs) of the Cramér-Rao
    bounds on the velocity (:func:`~trackers.evaluation.crb.straight_line_velocity_bound`)
    of each target alone and of its formation's common velocity (the targets move in
    straight lines in environments 1 and 2: no process noise), from the detections of the
    target (its formation's) made up to that time; ``nan`` without target-scans."""
    if not at:
        return math.nan, math.nan
    t = np.concatenate([np.full(s.target_of_detection.size, s.time) for s in sims])
    R = np.concatenate([s.R for s in sims])
    owner = np.concatenate([s.target_of_detection for s in sims])
    pairs = np.array(at, dtype=float)
    alone = np.zeros(len(at))
    together = np.zeros(len(at))
    for group in scenario.groups:
        ids = np.array(group)
        for target in group:
            rows = np.flatnonzero(pairs[:, 0] == target)
            mine = owner == target
            alone[rows] = straight_line_velocity_bound(
                t[mine], R[mine], np.zeros(int(mine.sum())), 1, pairs[rows, 1]
            )
        rows = np.flatnonzero(np.isin(pairs[:, 0], ids))
        theirs = np.isin(owner, ids)
        index = {int(target): i for i, target in enumerate(group)}
        member = np.array([index[int(o)] for o in owner[theirs]], dtype=np.intp)
        together[rows] = straight_line_velocity_bound(
            t[theirs], R[theirs], member, ids.size, pairs[rows, 1]
        )
    return float(np.sqrt(np.mean(alone))), float(np.sqrt(np.mean(together)))


def noise_sigma(
    states: np.ndarray, radar_position: tuple[float, float], radar: PolarRadar
) -> float:
    """The RMS over targets of the measurement noise's larger standard deviation (m): range
    noise or bearing noise times range."""
    rho = np.hypot(*(states[:, :2] - np.asarray(radar_position)).T)
    sig = np.maximum(radar.range_std, radar.bearing_std * rho)
    return float(np.sqrt(np.mean(sig**2)))


def run_figures(
    scenario: FormationScenario, pipeline: Any, warmup_time: float = 5.0
) -> FormationFigures:
    """Run ``scenario``'s detections through ``pipeline`` (a
    :class:`trackers.pipeline.TrackingPipeline`) and measure :class:`FormationFigures`."""
    radars = {r.sensor_id: r for r in scenario.radars}
    peer = next((p for p in getattr(pipeline, "peers", ()) if p.kind == "formation"), None)
    costs: list[float] = []
    if peer is not None:
        propose = peer.propose

        def timed(scan: Any, view: Any) -> Any:
            start = time.perf_counter()
            out = propose(scan, view)
            n = len(peer.formations)
            if n:
                costs.append(1e3 * (time.perf_counter() - start) / n)
            return out

        peer.propose = timed
    sims = simulate_formations(scenario)
    warmup = sum(1 for s in sims if s.time < warmup_time)
    counter = EffectiveRateCounter(warmup=warmup)
    previous: dict[int, str] = {}
    changes = 0
    err_p: dict[float, list[float]] = {}
    err_v: dict[float, list[float]] = {}
    held_at: list[tuple[int, float]] = []
    tracks_by_time = []
    formations_at_end = 0
    try:
        for k, sim in enumerate(sims):
            result = pipeline.process(sim.to_scan())
            conf = [t for t in result.confirmed() if t.kind == "individual"]
            formations_at_end = sum(1 for t in result.confirmed() if t.kind == "formation")
            est = {t.id: t for t in conf}
            X = sim.truth_states
            gate = 3.0 * noise_sigma(X, sim.sensor_position, radars[sim.sensor_id])
            pos = np.array([t.position for t in conf], dtype=float).reshape(-1, 2)
            pairs = counter.add(sim.truth_ids, X[:, :2], [t.id for t in conf], pos, gate=gate)
            for i, target in enumerate(sim.truth_ids.tolist()):
                tid = pairs.get(target)
                if tid is None:
                    continue
                if target in previous and previous[target] != tid:
                    changes += 1
                if k >= warmup and previous.get(target) == tid:
                    t = est[tid]
                    err_p.setdefault(sim.time, []).append(
                        float(np.sum((np.asarray(t.position) - X[i, :2]) ** 2))
                    )
                    err_v.setdefault(sim.time, []).append(
                        float(np.sum((np.asarray(t.velocity) - X[i, 2:]) ** 2))
                    )
                    held_at.append((target, sim.time))
            previous = pairs
            tracks_by_time.append(
                (sim.time, tuple((t.id, float(t.position[0]), float(t.position[1])) for t in conf))
            )
    finally:
        if peer is not None:
            del peer.propose
    res = counter.result()
    all_p = [e for v in err_p.values() for e in v]
    all_v = [e for v in err_v.values() for e in v]
    bound, formation_bound = velocity_bounds(scenario, sims, held_at)
    return FormationFigures(
        rate=res.rate,
        false_per_batch=res.false_per_scan,
        rms_position=float(np.sqrt(np.mean(all_p))) if all_p else math.nan,
        rms_velocity=float(np.sqrt(np.mean(all_v))) if all_v else math.nan,
        rms_position_by_time=tuple((t, float(np.sqrt(np.mean(v)))) for t, v in err_p.items()),
        rms_velocity_by_time=tuple((t, float(np.sqrt(np.mean(v)))) for t, v in err_v.items()),
        id_changes=changes,
        formation_ms=float(np.median(costs)) if costs else None,
        formations_at_end=formations_at_end,
        tracks_by_time=tuple(tracks_by_time),
        velocity_bound=bound,
        formation_velocity_bound=formation_bound,
    )
