"""Extended objects and groups (paper 002): the hybrid tracker against the individual-only
tracker on the same detections.

    python -m benchmarks.extended [--seeds 3]

Runs the convoy and harbour scenarios of :mod:`clients.scenarios.extended` through the
pipeline with every track kind (``TrackingPipeline.all_kinds``, the service's) and through the
individual tracker alone, and prints side by side, per scenario and averaged over seeds:

- false confirmed individual tracks per scan (more than 50 m from every true target);
- convoy: the extended tracks that held the convoy before its split (the nearest to its
  true centroid each scan), that centroid's RMSE, and the first scan after the split at which
  each sub-convoy has an extended track within 150 m of its centroid;
- convoy: the track breaks of the overtaking vehicle (scans at which the individual track
  nearest to it, within 50 m, is another than at its previous scan, or there is none);
- harbour: the extended tracks that held the backwash (within 150 m of its centre) after the
  first 20 scans;
- median milliseconds per scan, and one extended-track update with 20 detections.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import timeit

import numpy as np

from clients.scenarios.extended import convoy_scenario, harbour_scenario
from trackers.extended.random_matrix import ExtendedEstimate, update
from trackers.pipeline import TrackingPipeline


def _run(run, pipeline, convoy: bool) -> dict[str, float]:
    times, false, scans = [], 0, 0
    held, errors, split_found = set(), [], {}
    backwash: set[str] = set()
    prev_ovt, breaks, ovt_scans = None, 0, 0
    centre = None if run.scans[0].clutter_region is None else run.scans[0].clutter_region.mean(0)
    for k, ts in enumerate(run.scans):
        sim = ts.scan
        start = time.perf_counter()
        result = pipeline.process(sim.to_scan())
        times.append(1e3 * (time.perf_counter() - start))
        conf = result.confirmed()
        X = sim.truth_states[:, :2]
        ext = [t for t in conf if t.kind == "extended"]
        ind = [t for t in conf if t.kind == "individual"]
        false += sum(float(np.min(np.hypot(*(X - t.position).T))) > 50 for t in ind)
        scans += 1
        if convoy:
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
            ids = list(sim.truth_ids)
            if 9 in ids:
                x9 = X[ids.index(9)]
                near = [(float(np.hypot(*(np.array(t.position) - x9))), t.id) for t in ind]
                near = [n for n in near if n[0] < 50]
                now = min(near)[1] if near else None
                if prev_ovt is not None:
                    ovt_scans += 1
                    breaks += now != prev_ovt
                prev_ovt = now if now is not None else prev_ovt
        elif centre is not None and k >= 20:
            backwash |= {t.id for t in ext if np.hypot(*(np.array(t.position) - centre)) < 150}
    out = {"false": false / scans, "ms": statistics.median(times)}
    if convoy:
        out["held"] = len(held)
        out["rmse"] = float(np.sqrt(np.mean(np.square(errors)))) if errors else float("nan")
        out["split"] = max(split_found.get(1, np.inf), split_found.get(2, np.inf))
        out["breaks"] = breaks
    else:
        out["backwash"] = len(backwash)
    return out


def update_cost() -> float:
    """Median microseconds of one random-matrix update with 20 detections."""
    rng = np.random.default_rng(0)
    est = ExtendedEstimate(
        x=np.array([0.0, 0.0, 5.0, 0.0]), P=np.eye(4) * 25, X=np.diag([400.0, 100.0]), alpha=10
    )
    Z = rng.normal(0, 10, (20, 2))
    R = np.eye(2) * 100.0
    runs = timeit.repeat(lambda: update(est, Z, R), number=200, repeat=7)
    return 1e6 * min(runs) / 200


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.extended", description=__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    print(f"== one extended-track update with 20 detections: {update_cost():.0f} µs")
    for name, make, convoy in (
        ("convoy", convoy_scenario, True),
        ("harbour", harbour_scenario, False),
    ):
        rows = {"hybrid": [], "individual only": []}
        for seed in range(args.seeds):
            run = make(seed)
            rows["hybrid"].append(_run(run, TrackingPipeline.all_kinds(), convoy))
            rows["individual only"].append(_run(run, TrackingPipeline(), convoy))
        print(f"== {name}, {args.seeds} seeds")
        for label, results in rows.items():
            mean = {k: float(np.mean([r[k] for r in results])) for k in results[0]}
            text = f"   {label:<16} false individual tracks/scan {mean['false']:.3f}"
            text += f", median {mean['ms']:.1f} ms/scan"
            if convoy and label == "hybrid":
                text += (
                    f", tracks holding the convoy {mean['held']:.1f}, centroid RMSE "
                    f"{mean['rmse']:.1f} m, both groups held {mean['split']:.1f} scans after "
                    f"the split, overtaker breaks {mean['breaks']:.1f}"
                )
            elif convoy:
                text += f", overtaker breaks {mean['breaks']:.1f}"
            elif label == "hybrid":
                text += f", extended tracks on the backwash {mean['backwash']:.1f}"
            print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
