"""Targets of every speed with the default configuration, beside the tracker's old defaults.

    python -m benchmarks.speeds [--seeds 3]

Runs the scenarios of :mod:`clients.scenarios.airspace` (mixed speeds with one radar at
T = 4 s and T = 1 s; paper 003's formations seen by three unsynchronized radars; a 450 m/s
target pulling 4 g at T = 2 s) through the tracker with its default configuration and with
the defaults it had before two-point initiation (single-point starts with a 15 m/s velocity
prior, q_ct 2, q_turn_rate 1e-4), on the same detections. Prints, after the first 8 scans,
the effective tracking rate (target-scans held by a confirmed track within 150 m that is the
same track as at the previous scan) overall and per target class, the false confirmed tracks
per scan, and the median tracker time per scan.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from clients.scenarios.airspace import (
    ScriptedScenario,
    formation_scenario,
    manoeuvre_scenario,
    mixed_speed_scenario,
    simulate_scripted,
)
from trackers.config import TrackerConfig
from trackers.evaluation.effective_rate import EffectiveRate, EffectiveRateCounter
from trackers.pipeline import TrackingPipeline

#: The defaults before targets of every speed (issue "Tracks for targets of every speed").
OLD_DEFAULTS = {
    "initiation": {"method": "single_point", "velocity_std": 15.0, "turn_rate_std": 0.05},
    "motion": {"q_cv": 0.5, "q_ct": 2.0, "q_turn_rate": 1e-4, "sojourn_times": [30.0, 10.0]},
}


def run(scenario: ScriptedScenario, config: TrackerConfig) -> tuple[EffectiveRate, float]:
    """Effective rate of ``config`` on ``scenario`` and the median ms per scan."""
    pipeline = TrackingPipeline(config)
    counter = EffectiveRateCounter(gate=150.0, warmup=8)
    times = []
    for sim in simulate_scripted(scenario):
        scan = sim.to_scan()
        start = time.perf_counter()
        result = pipeline.process(scan)
        times.append(1e3 * (time.perf_counter() - start))
        confirmed = result.confirmed()
        est = np.array([t.position for t in confirmed]).reshape(-1, 2)
        counter.add(sim.truth_ids, sim.truth_states[:, :2], [t.id for t in confirmed], est)
    return counter.result(scenario.classes), statistics.median(times)


def _pooled(results: list[EffectiveRate]) -> tuple[float, dict[str, float], float]:
    rate = float(np.mean([r.rate for r in results]))
    classes = sorted({c for r in results for c in r.rate_by_class})
    by_class = {c: float(np.mean([r.rate_by_class[c] for r in results])) for c in classes}
    false = float(np.mean([r.false_per_scan for r in results]))
    return rate, by_class, false


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.speeds", description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    configs = {
        "defaults": TrackerConfig(),
        "old defaults": TrackerConfig().merged(OLD_DEFAULTS),
    }
    scenarios = {
        "mixed speeds, T = 4 s": lambda s: mixed_speed_scenario(period=4.0, seed=s),
        "mixed speeds, T = 1 s": lambda s: mixed_speed_scenario(period=1.0, seed=s),
        "paper 003 formations, 3 radars": lambda s: formation_scenario(seed=s),
        "450 m/s, 4 g turn, T = 2 s": lambda s: manoeuvre_scenario(seed=s),
    }
    print("effective tracking rate after 8 scans (150 m, same track as the scan before);")
    print(f"false confirmed tracks per scan; median tracker ms per scan; {args.seeds} seeds")
    for title, make in scenarios.items():
        print(f"== {title}")
        for name, config in configs.items():
            runs = [run(make(seed), config) for seed in range(args.seeds)]
            rate, by_class, false = _pooled([r for r, _ in runs])
            ms = statistics.median([m for _, m in runs])
            classes = "  ".join(f"{c} {v:.3f}" for c, v in by_class.items())
            print(
                f"   {name:<13} rate {rate:.3f}  false/scan {false:.3f}  {ms:.2f} ms  | {classes}"
            )
    print("targets (defaults): rate ≥ 0.97 overall, ≥ 0.9 per class, ≤ 0.05 false tracks/scan")
    return 0


if __name__ == "__main__":
    sys.exit(main())
