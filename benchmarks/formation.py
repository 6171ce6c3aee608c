"""Formation tracking (paper 003) against the individual tracker alone, on the same detections.

    python -m benchmarks.formation [--seeds 2]

Environment 1 (two formations of four, no clutter), environment 2 at every clutter level of
the paper's Table I, and environment 3 (a formation turning by 120° at 4°/s, radars not
synchronized) from :mod:`clients.scenarios.formation`, each run through the pipeline with
formations switched on (``formation.enabled``) and through the individual tracker alone.
Prints, like Table II, the effective tracking rate (target-scans after the first 5 s held by
the same confirmed track within 3σ of the measurement noise), false confirmed tracks per batch,
RMS position and velocity errors (all held target-scans, and from t = 50 s on), id changes,
and the formation peer's median time per batch and formation.
"""

from __future__ import annotations

import argparse
import statistics
import sys

import numpy as np

from clients.scenarios.formation import (
    CLUTTER_LEVELS,
    FormationFigures,
    FormationScenario,
    environment_1,
    environment_2,
    environment_3,
    run_figures,
)
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline

#: The paper's MSFT-TM effective tracking rates and times (ms) at each clutter level (Table II).
PAPER_RATE = (1.0, 0.9875, 0.9523, 0.9034, 0.8923, 0.7534)
PAPER_MS = (0.0234, 0.0783, 0.1534, 0.1946, 0.2578, 0.3208)


def _steady(series: tuple[tuple[float, float], ...], after: float = 50.0) -> float:
    vals = [v for t, v in series if t >= after]
    return float(np.sqrt(np.mean(np.square(vals)))) if vals else float("nan")


def _both(make: object, seeds: int) -> tuple[list[FormationFigures], list[FormationFigures]]:
    on = TrackerConfig().merged({"formation": {"enabled": True}})
    formation, individual = [], []
    for seed in range(seeds):
        scenario: FormationScenario = make(seed)  # type: ignore[operator]
        formation.append(run_figures(scenario, TrackingPipeline.all_kinds(on)))
        individual.append(run_figures(scenario, TrackingPipeline(TrackerConfig())))
    return formation, individual


def _mean(figs: list[FormationFigures], name: str) -> float:
    return float(np.mean([getattr(f, name) for f in figs]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2, help="Monte Carlo runs per scenario")
    args = parser.parse_args(argv)
    print(f"paper 003 environments, {args.seeds} seed(s) each; formation = pipeline with")
    print("formations on, individual = the individual tracker alone, same detections\n")

    form, ind = _both(lambda s: environment_1(seed=s), args.seeds)
    print("Environment 1 (no clutter)")
    for name, figs in (("formation", form), ("individual", ind)):
        steady_p = np.mean([_steady(f.rms_position_by_time) for f in figs])
        steady_v = np.mean([_steady(f.rms_velocity_by_time) for f in figs])
        print(
            f"  {name:10s} rate {_mean(figs, 'rate'):.4f}  RMS position "
            f"{_mean(figs, 'rms_position'):5.1f} m (t>=50 s: {steady_p:5.1f} m)  RMS velocity "
            f"{_mean(figs, 'rms_velocity'):5.2f} m/s (t>=50 s: {steady_v:5.2f} m/s)"
        )

    print("\nEnvironment 2 (Table II): effective tracking rate, false tracks/batch, ms")
    print(
        f"  {'(l1, l2)':9s} {'formation':>9s} {'individual':>10s} {'paper':>6s}  "
        f"{'false f/i':>11s}  {'ms/formation':>12s} {'paper ms':>8s}"
    )
    for level, (l1, l2) in enumerate(CLUTTER_LEVELS):
        form, ind = _both(lambda s, a=l1, b=l2: environment_2(a, b, seed=s), args.seeds)
        ms = [f.formation_ms for f in form if f.formation_ms is not None]
        print(
            f"  ({l1}, {l2:2d})  {_mean(form, 'rate'):9.4f} {_mean(ind, 'rate'):10.4f} "
            f"{PAPER_RATE[level]:6.4f}  {_mean(form, 'false_per_batch'):5.3f}/"
            f"{_mean(ind, 'false_per_batch'):5.3f}  "
            f"{statistics.median(ms) if ms else float('nan'):12.3f} {PAPER_MS[level]:8.4f}"
        )

    form, ind = _both(lambda s: environment_3(seed=s), args.seeds)
    print("\nEnvironment 3 (turn of 120 deg at 4 deg/s, radars not synchronized)")
    for name, figs in (("formation", form), ("individual", ind)):
        print(
            f"  {name:10s} rate {_mean(figs, 'rate'):.4f}  id changes "
            f"{[f.id_changes for f in figs]}  RMS position {_mean(figs, 'rms_position'):5.1f} m"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
