"""Targets of every speed with the default configuration, beside the tracker's old defaults.

    python -m benchmarks.speeds [--seeds 3]

Runs the scenarios of :mod:`clients.scenarios.airspace` (mixed speeds with one radar at
T = 4 s, T = 1 s and T = 10 s, the last over its first 16 scans, the scenario's 160 s;
paper 003's formations seen by three unsynchronized radars; a 450 m/s
target pulling 4 g at T = 2 s; aircraft braking and speeding up on a runway at T = 4 s;
aircraft and vehicles setting off from rest near the radar at T = 4 s; a 40 m/s drone weaving
at 20°/s at T = 1 s) through the tracker with its default configuration and with the
defaults it had before two-point initiation (single-point starts with a 15 m/s velocity
prior; the same IMM, without the turn mode's noise along the velocity and without agile
turns; a manoeuvre search for turns alone), on the same detections.
Prints, after the first 8 scans, the effective tracking rate (target-scans held by a
confirmed track within 150 m that is the same track as at the previous scan) overall and per
target class, the false confirmed tracks per scan, and the median tracker time per scan.

A scan is one revisit of the radars: with three unsynchronized radars the first 8 scans are
the first 8 periods (24 batches), and every batch after them is counted. For those the rate
after the first 8 batches is printed too. The false tracks per scan (confirmed tracks more
than 150 m from every target that has no other track) are split into *displaced* ones, a
target's own track more than 150 m off (within 1 km; typically coasting through a missed
detection in a turn), and *spurious* ones, which follow no target
(:mod:`trackers.evaluation.effective_rate`). For one radar, the *floor* line gives the part of
the displaced tracks that the manoeuvres between two detections cause by themselves
(:func:`coasting_floor`).
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.tracking import reference_overrides, run_ours
from clients.scenarios.airspace import (
    ScriptedScenario,
    apron_scenario,
    formation_scenario,
    manoeuvre_scenario,
    mixed_speed_scenario,
    runway_scenario,
    simulate_scripted,
    turn_rate_at,
    weaving_scenario,
)
from clients.scenarios.multitarget import move_targets, reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.evaluation.effective_rate import EffectiveRate, EffectiveRateCounter
from trackers.pipeline import TrackingPipeline

#: The defaults before targets of every speed (issue "Tracks for targets of every speed").
OLD_DEFAULTS = {
    "initiation": {"method": "single_point", "velocity_std": 15.0, "turn_rate_std": 0.05},
    "motion": {
        "q_cv": 0.5,
        "q_ct": 2.0,
        "q_turn_rate": 1e-4,
        "q_ct_along": 0.0,
        "sojourn_times": [30.0, 10.0],
        "agile_acceleration": 0.0,
    },
    "gating": {"manoeuvre_speed_change": 0.0},
}


WARMUP_SCANS = 8


def warmup_batches(scenario: ScriptedScenario, scans: int = WARMUP_SCANS) -> int:
    """The number of batches in the first ``scans`` revisit periods of the slowest radar:
    each radar's reports at ``offset + k · period`` before that end."""
    end = min(r.time_offset for r in scenario.radars) + scans * max(
        r.period for r in scenario.radars
    )
    return sum(max(0, math.ceil((end - r.time_offset) / r.period)) for r in scenario.radars)


def run(
    scenario: ScriptedScenario, config: TrackerConfig
) -> tuple[EffectiveRate, float, EffectiveRate]:
    """Effective rate of ``config`` on ``scenario`` after the first 8 scans, the median ms
    per scan, and the rate after the first 8 batches."""
    pipeline = TrackingPipeline(config)
    counter = EffectiveRateCounter(gate=150.0, warmup=warmup_batches(scenario))
    by_batch = EffectiveRateCounter(gate=150.0, warmup=WARMUP_SCANS)
    times = []
    for sim in simulate_scripted(scenario):
        scan = sim.to_scan()
        start = time.perf_counter()
        result = pipeline.process(scan)
        times.append(1e3 * (time.perf_counter() - start))
        confirmed = result.confirmed()
        est = np.array([t.position for t in confirmed]).reshape(-1, 2)
        ids = [t.id for t in confirmed]
        counter.add(sim.truth_ids, sim.truth_states[:, :2], ids, est)
        by_batch.add(sim.truth_ids, sim.truth_states[:, :2], ids, est)
    classes = scenario.classes
    return counter.result(classes), statistics.median(times), by_batch.result(classes)


def _pooled(results: list[EffectiveRate]) -> tuple[float, dict[str, float], float, float]:
    rate = float(np.mean([r.rate for r in results]))
    classes = sorted({c for r in results for c in r.rate_by_class})
    by_class = {c: float(np.mean([r.rate_by_class[c] for r in results])) for c in classes}
    false = float(np.mean([r.false_per_scan for r in results]))
    displaced = float(np.mean([r.displaced_per_scan for r in results]))
    return rate, by_class, false, displaced


def coasting_floor(scenario: ScriptedScenario, gate: float = 150.0) -> tuple[float, float]:
    """Displaced tracks a scan that no tracker could avoid, on a single-radar scenario.

    At each scan after the first 8, a missed target counts if its true position is more than
    ``gate`` from its true state at its last detection extrapolated (a) with its true turn
    rate then, and (b) in a straight line. Returns the two counts per scan: the part of the
    displaced tracks due to the manoeuvres between detections rather than to estimation.
    """
    last: dict[int, tuple[float, np.ndarray, float]] = {}
    counts = np.zeros(2)
    scans = 0
    for k, sim in enumerate(simulate_scripted(scenario)):
        scored = k >= WARMUP_SCANS
        scans += scored
        detected = set(sim.target_of_detection.tolist())
        for tid, state in zip(sim.truth_ids.tolist(), sim.truth_states, strict=True):
            target = scenario.targets[tid]
            if tid in detected:
                last[tid] = (sim.time, state, turn_rate_at(target, sim.time))
            elif scored and tid in last:
                t0, s0, omega = last[tid]
                pred = move_targets(np.stack([s0, s0]), np.array([omega, 0.0]), sim.time - t0)
                counts += np.hypot(*(pred[:, :2] - state[:2]).T) > gate
    return float(counts[0] / scans), float(counts[1] / scans)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.speeds", description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of the reference")
    args = parser.parse_args(argv)
    configs = {
        "defaults": TrackerConfig(),
        "old defaults": TrackerConfig().merged(OLD_DEFAULTS),
    }
    scenarios = {
        "mixed speeds, T = 4 s": lambda s: mixed_speed_scenario(period=4.0, seed=s),
        "mixed speeds, T = 1 s": lambda s: mixed_speed_scenario(period=1.0, seed=s),
        "mixed speeds, T = 10 s (16 scans, 8 counted)": lambda s: mixed_speed_scenario(
            period=10.0, seed=s
        ),
        "paper 003 formations, 3 radars": lambda s: formation_scenario(seed=s),
        "450 m/s, 4 g turn, T = 2 s": lambda s: manoeuvre_scenario(seed=s),
        "runway: braking 2 m/s², speeding up 2.5 m/s², T = 4 s": lambda s: runway_scenario(seed=s),
        "apron: setting off from rest 1-3 km out, T = 4 s": lambda s: apron_scenario(seed=s),
        "weaving drone: 40 m/s, 3 s turns at 20°/s, T = 1 s": lambda s: weaving_scenario(seed=s),
    }
    print("effective tracking rate after 8 scans (150 m, same track as the scan before);")
    print("false confirmed tracks per scan (displaced: a target's own track > 150 m off;")
    print(f"spurious: the rest); median tracker ms per scan; {args.seeds} seeds")
    for title, make in scenarios.items():
        one_radar = len(make(0).radars) == 1
        print(f"== {title}")
        for name, config in configs.items():
            runs = [run(make(seed), config) for seed in range(args.seeds)]
            rate, by_class, false, displaced = _pooled([r for r, _, _ in runs])
            ms = statistics.median([m for _, m, _ in runs])
            classes = "  ".join(f"{c} {v:.3f}" for c, v in by_class.items())
            print(
                f"   {name:<13} rate {rate:.3f}  false/scan {false:.3f} (displaced "
                f"{displaced:.3f}, spurious {false - displaced:.3f})  {ms:.2f} ms  | {classes}"
            )
            if not one_radar:
                first_batches = _pooled([b for _, _, b in runs])[0]
                print(f"   {'':<13} rate after the first 8 batches instead: {first_batches:.3f}")
        if one_radar:
            floors = np.mean([coasting_floor(make(seed)) for seed in range(args.seeds)], axis=0)
            print(
                f"   {'floor':<13} a target missed > 150 m from its true state at its last"
                f" detection extrapolated: {floors[0]:.3f}/scan with its true turn rate,"
                f" {floors[1]:.3f} in a straight line"
            )
    print("targets (defaults): rate ≥ 0.97 overall, ≥ 0.9 per class, ≤ 0.05 false tracks/scan")
    bench_reference(configs, args.seeds, args.repeats)
    return 0


#: The last commit before targets of every speed: "the tracker of today" of that issue.
BASELINE_COMMIT = "3e3592c670b53417e5b7e4023f97c228e00fb504"

#: Run in a tree (the baseline commit's copy, or this one): its median ms a scan on reference
#: seeds with its defaults.
_BASELINE_SCRIPT = """
import json, statistics, sys, time
from clients.scenarios.multitarget import reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline
out = []
for seed in range(int(sys.argv[1])):
    scans = [s.to_scan() for s in simulate(reference_scenario(seed))]
    pipeline, times = TrackingPipeline(TrackerConfig()), []
    for scan in scans:
        start = time.perf_counter()
        pipeline.process(scan)
        times.append(1e3 * (time.perf_counter() - start))
    out.append(statistics.median(times))
print(json.dumps(out))
"""


def _baseline_ms(tree: Path, seeds: int) -> list[float]:
    """The median ms a scan on reference seeds ``0..seeds−1`` of the tracker in ``tree`` (a
    copy of :data:`BASELINE_COMMIT`, or this project), run by a child interpreter."""
    done = subprocess.run(
        [sys.executable, "-c", _BASELINE_SCRIPT, str(seeds)],
        cwd=tree,
        env={**os.environ, "PYTHONPATH": str(tree)},
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout)


def bench_baseline(seeds: int, repeats: int) -> None:
    """Time per scan of the reference scenario with the defaults against the tracker of
    :data:`BASELINE_COMMIT` with its own defaults, interleaved runs (needs the git history).
    Both trees are timed alike: the same script (:data:`_BASELINE_SCRIPT`) in a child
    interpreter, which times ``process`` alone, one scan after another (timed in this
    process, our scans would sit between the scoring's snapshots and distances, whose
    garbage the collector then clears during ``process``)."""
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "archive", BASELINE_COMMIT],
            cwd=Path(__file__).resolve().parent.parent,
            capture_output=True,
        )
        if archive.returncode != 0:
            print(f"   (the tracker before the issue: commit {BASELINE_COMMIT[:7]} not available)")
            return
        with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
            safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}
            tar.extractall(tmp, **safe)  # type: ignore[arg-type]
        ours: list[list[float]] = []
        theirs: list[list[float]] = []
        for _ in range(repeats):
            theirs.append(_baseline_ms(Path(tmp), seeds))
            ours.append(_baseline_ms(Path(__file__).resolve().parent.parent, seeds))
    new = statistics.median(statistics.median(r) for r in zip(*ours, strict=True))
    old = statistics.median(statistics.median(r) for r in zip(*theirs, strict=True))
    print(
        f"   defaults {new:.2f} ms against the tracker before the issue (commit "
        f"{BASELINE_COMMIT[:7]}, its defaults) {old:.2f} ms  | time ratio {new / old:.2f}"
    )


def bench_reference(configs: dict[str, TrackerConfig], seeds: int, repeats: int) -> None:
    """The reference scenario (the Stone Soup comparison) with each of ``configs`` as it is
    and given Stone Soup's model (:func:`benchmarks.tracking.reference_overrides`): median ms
    a scan (the median of ``repeats`` interleaved runs, then over seeds), mean GOSPA, and the
    ratio of the first config's time to the second's."""
    print("== reference scenario (Stone Soup comparison): median ms per scan, mean GOSPA m")
    for params in ("as configured", "Stone Soup's model"):
        ms: dict[str, list[float]] = {name: [] for name in configs}
        gospa: dict[str, list[float]] = {name: [] for name in configs}
        for seed in range(seeds):
            scenario = reference_scenario(seed)
            scans = simulate(scenario)
            runs: dict[str, list[float]] = {name: [] for name in configs}
            for _ in range(repeats):
                for name, config in configs.items():
                    if params != "as configured":
                        config = config.merged(reference_overrides(scenario))
                    result = run_ours(scans, config, name)
                    runs[name].append(result.median_ms)
                    if len(runs[name]) == 1:  # the same detections give the same tracks
                        gospa[name].append(result.mean_gospa)
            for name in configs:
                ms[name].append(statistics.median(runs[name]))
        row = "  ".join(
            f"{name} {statistics.median(ms[name]):.2f} ms, GOSPA {np.mean(gospa[name]):.2f}"
            for name in configs
        )
        first, second = (statistics.median(ms[name]) for name in list(configs)[:2])
        print(f"   {params:<19} {row}  | time ratio {first / second:.2f}")
    bench_baseline(seeds, repeats)
    print(
        "targets: time ≤ 1.20 x the tracker before the issue; GOSPA of the defaults no worse"
        " than the old defaults'"
    )


if __name__ == "__main__":
    sys.exit(main())
