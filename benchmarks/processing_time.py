"""The tracker's time per batch inside the service against the same step in this process.

    python -m benchmarks.processing_time [--speed 20] [--seeds 2]

The reference scenario (50 targets, 100 scans at 1 s) is tracked three ways with the default
configuration:

- in this process, scan after scan with nothing in between (what ``benchmarks.tracking``
  measures);
- in this process, idling between scans as the service does when batches come at the given
  real-time ``--speed`` (1/speed seconds apart);
- by ``tracker-service`` in a subprocess, fed over Zenoh by ``tracker-publish`` at that speed;
  its own ``processing_ms`` percentiles come from ``/api/v1/stats``.

Printed: median and 90th percentile ms per batch for each, and the ratios service/in-process.
The service measures only ``pipeline.process`` (decoding and reports are not in it), so any
difference is threads, the GIL, thread pools or what idling costs the CPU's caches.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

import httpx
import numpy as np

from benchmarks.service_process import ROOT, running_service
from clients.scenarios.multitarget import reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline


def in_process(seed: int, gap: float) -> list[float]:
    """ms per scan of the pipeline (confirmed tracks built too), sleeping ``gap`` s between."""
    scans = [s.to_scan() for s in simulate(reference_scenario(seed))]
    pipeline = TrackingPipeline(TrackerConfig())
    times = []
    for scan in scans:
        if gap:
            time.sleep(gap)
        t0 = time.perf_counter()
        pipeline.process(scan).confirmed()
        times.append(1e3 * (time.perf_counter() - t0))
    return times


def in_service(seed: int, speed: float) -> dict[str, float]:
    """The service's processing-time percentiles for the scenario published at ``speed``."""
    with running_service() as service:
        subprocess.run(
            [
                *(sys.executable, "-m", "clients.publish", "--scenario", "reference"),
                *("--seed", str(seed), "--rate", "realtime", "--speed", str(speed)),
                *("-q", "-e", service.endpoint),
            ],
            cwd=ROOT,
            check=True,
            stdout=subprocess.DEVNULL,
        )
        stats = httpx.get(f"{service.url}/api/v1/stats", timeout=5).json()
    return dict(stats["processing_ms"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=20.0, help="real-time speed-up")
    parser.add_argument("--seeds", type=int, default=2)
    args = parser.parse_args(argv)
    gap = 1.0 / args.speed
    rows: dict[str, tuple[list[float], list[float]]] = {}
    back_to_back = [in_process(s, 0.0) for s in range(args.seeds)]
    idling = [in_process(s, gap) for s in range(args.seeds)]
    service = [in_service(s, args.speed) for s in range(args.seeds)]
    rows["in process, back to back"] = (
        [statistics.median(t) for t in back_to_back],
        [float(np.percentile(t, 90)) for t in back_to_back],
    )
    rows[f"in process, idle {1e3 * gap:.0f} ms between"] = (
        [statistics.median(t) for t in idling],
        [float(np.percentile(t, 90)) for t in idling],
    )
    rows[f"service, {args.speed:g}x real time"] = (
        [p["p50"] for p in service],
        [p["p90"] for p in service],
    )
    print(f"reference scenario, default configuration, {args.seeds} seeds: ms per batch")
    print(f"{'':40s} {'p50':>7s} {'p90':>7s}")
    for name, (p50, p90) in rows.items():
        print(f"{name:40s} {np.mean(p50):7.2f} {np.mean(p90):7.2f}")
    base = np.mean(rows["in process, back to back"][0])
    idle = np.mean(rows[f"in process, idle {1e3 * gap:.0f} ms between"][0])
    svc = np.mean(rows[f"service, {args.speed:g}x real time"][0])
    print(f"service / in process back to back: {svc / base:.2f}; / idling alike: {svc / idle:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
