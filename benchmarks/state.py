"""What saving the tracker's state costs: per save, on the worker, and on disk.

    python -m benchmarks.state [--dir DIR] [--repeat 20]

Two states of the scale scenario (20 km x 20 km, 1,000 targets, 15 scans): without clutter
(about 1,000 tracks, all confirmed) and with 1,000 false alarms a scan (1,000 confirmed and
thousands of tentative tracks and two-point candidates, the worst case of the benchmarks).
For each: the size of the file, the worker's cost (a checkpoint after each batch), the saver
thread's export to plain data, encoding to bytes, atomic write with fsync (in ``DIR``, by
default a temporary folder of the system's), and decoding and checking at start. Then the
engine's per-batch tracker time on the scale scenario with clutter, with saves every 0.1 s
on the saver thread against no state file (the cost of sharing the interpreter).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson

from clients.scenarios.multitarget import scale_scenario, simulate
from service.engine import Engine
from service.files import atomic_write
from service.state_store import StateStore
from trackers.pipeline import TrackingPipeline
from trackers.state import decode_state, encode_state


def _median_ms(f: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times), out


def bench_save(clutter: float, folder: Path, repeat: int) -> None:
    scans = simulate(scale_scenario(n_targets=1000, clutter_mean=clutter, n_scans=15, seed=1))
    pipeline = TrackingPipeline()
    for s in scans:
        pipeline.process(s.to_scan())
    tracks = pipeline.point.tracks  # type: ignore[attr-defined]
    n_cand = len(pipeline.point.candidates)  # type: ignore[attr-defined]
    checkpoint_ms, cp = _median_ms(pipeline.checkpoint, repeat * 50)
    export_ms, state = _median_ms(cp.export, repeat)
    encode_ms, data = _median_ms(lambda: encode_state(state, {"seq": 15}), repeat)
    path = folder / "state.npz"
    write_ms, _ = _median_ms(lambda: atomic_write(path, data), repeat)
    decode_ms, (loaded, _) = _median_ms(lambda: decode_state(path.read_bytes()), repeat)
    restore_ms, _ = _median_ms(lambda: TrackingPipeline().import_state(loaded), repeat)
    print(
        f"| {clutter:,.0f} | {len(tracks):,} ({int(tracks.confirmed.sum()):,}) | {n_cand:,} "
        f"| {len(data) / 1e6:.2f} MB | {1e3 * checkpoint_ms:.1f} µs | {export_ms:.1f} "
        f"| {encode_ms:.1f} | {write_ms:.1f} | {decode_ms:.1f} + {restore_ms:.1f} |"
    )


class _CountingStore(StateStore):
    saves = 0

    def save(self, checkpoint: Any) -> Any:
        out = super().save(checkpoint)
        self.saves += out is not None
        return out


def _engine_times(payloads: list[bytes], store: _CountingStore | None) -> tuple[float, ...]:
    """Median and p99 tracker time per batch (ms), wall time of the run (s), saves made."""
    engine = Engine(state_store=store)
    engine.start()
    try:
        t0 = time.perf_counter()
        futures = [engine.submit(p, "radar-1", "bench") for p in payloads]
        for f in futures:
            f.result(timeout=300)
        wall = time.perf_counter() - t0
        pct = engine.stats.percentiles()
    finally:
        engine.stop()
    return float(pct["p50"]), float(pct["p99"]), wall, 0 if store is None else store.saves


def bench_worker(folder: Path) -> None:
    scans = simulate(scale_scenario(n_targets=1000, clutter_mean=1000.0, n_scans=40, seed=2))
    payloads = [orjson.dumps(s.to_batch()) for s in scans]
    print(f"\n== the engine on {len(payloads)} batches of the scale scenario with clutter")
    print("| state file | tracker p50 ms/batch | p99 | whole run, s | saves |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for label, store in (
        ("none", None),
        ("saved every 0.1 s", _CountingStore(folder / "w.npz", max_age=60, save_interval=0.1)),
    ):
        p50, p99, wall, saves = _engine_times(payloads, store)
        print(f"| {label} | {p50:.1f} | {p99:.1f} | {wall:.2f} | {saves:.0f} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.state", description=__doc__)
    parser.add_argument("--dir", type=Path, default=None, help="where to write (default: temp)")
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        folder = Path(tmp)
        print("== a save of the scale scenario's state (1,000 targets, 15 scans), median ms")
        print(
            "| clutter/scan | tracks (confirmed) | candidates | file | worker: checkpoint "
            "| export | encode | write + fsync | decode + check at start |"
        )
        print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        bench_save(0.0, folder, args.repeat)
        bench_save(1000.0, folder, args.repeat)
        bench_worker(folder)
    return 0


if __name__ == "__main__":
    sys.exit(main())
