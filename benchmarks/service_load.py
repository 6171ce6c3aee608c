"""The service under load: detection batches over Zenoh from another process, REST reads
alongside.

    python -m benchmarks.service_load [--rate 200] [--seconds 15] [--rounds 1] [--no-viewer]
                                      [--viewer-first]

Starts ``tracker-service`` as a subprocess on free loopback ports, then runs the scenario
publisher (``clients.publish``, reliable, ``CongestionControl.BLOCK``) as a second process:
first paced at ``--rate`` batches per second, then as fast as the service takes them
(``--rounds`` times, a new publisher process each time). Each
batch is one scan of the reference scenario (50 targets at Pd 0.9 plus 10 clutter: about 55
detections). During each phase this process reads ``GET /api/v1/tracks`` about 100 times a
second and records the latency. Printed per phase: batches published, processed, rejected
and dropped (from ``/api/v1/stats``), the processing rate, the tracker's time per batch and
the REST latency percentiles, against the targets (≥ 200 batches/s, nothing lost, p99 < 20 ms);
then the service's resident memory after each phase. The paced and the (last) max-rate phase
each have a twin with a live viewer connected (a thread reading ``GET /api/v1/stream`` as a
browser would), run right after it (before it with ``--viewer-first``: compare the two orders
to tell the viewer's cost from the phase order's), printing the frames the viewer got and those
dropped for it (unless ``--no-viewer``), and what one frame costs to build, timed in process.
Each phase also prints the service process's CPU time (all threads) per processed batch, read
from ``/proc``. Exits 1 when a target is missed.
"""

from __future__ import annotations

import argparse
import math
import re
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

import httpx
import numpy as np

from benchmarks.service_process import ROOT, cpu_seconds, rss_mb, running_service

#: Seconds of scenario time between one phase's last batch and the next phase's first: within
#: the service's time-jump allowance (``ingest.max_time_jump``, 10 s) whatever the wall time
#: between the phases.
PHASE_GAP = 2.0


@dataclass
class Phase:
    name: str
    target_rate: float | None
    published: int
    processed: int
    rejected: int
    dropped: int
    rate: float
    tracker_p50: float
    tracker_p99: float
    get_ms: np.ndarray
    cpu_ms_per_batch: float = float("nan")  # the service process's CPU time (all threads)
    frames: int | None = None  # live view frames read, when a viewer was connected
    frames_dropped: int | None = None


def sample_latency(client: httpx.Client, stop: threading.Event, out: list[float]) -> None:
    while not stop.is_set():
        t0 = time.perf_counter()
        r = client.get("/api/v1/tracks")
        out.append(1e3 * (time.perf_counter() - t0))
        if r.status_code != 200:
            raise RuntimeError(f"GET /api/v1/tracks answered {r.status_code}")
        stop.wait(0.01)


def read_stream(base_url: str, stop: threading.Event, frames: list[int]) -> None:
    """A live viewer: read ``GET /api/v1/stream`` until ``stop`` is set, counting report
    events (a keep-alive comment comes every 10 s when no report does)."""
    with (
        httpx.Client(base_url=base_url, timeout=httpx.Timeout(5.0, read=30.0)) as http,
        http.stream("GET", "/api/v1/stream") as r,
    ):
        for line in r.iter_lines():
            if line.startswith("event: report"):
                frames[0] += 1
            if stop.is_set():
                return


def run_phase(
    name: str,
    client: httpx.Client,
    endpoint: str,
    scans: int,
    rate: float | None,
    offset: float,
    viewer: bool = False,
    pid: int | None = None,
) -> Phase:
    frames = [0]
    stop_viewer = threading.Event()
    reader = None
    if viewer:
        reader = threading.Thread(
            target=read_stream, args=(str(client.base_url), stop_viewer, frames), daemon=True
        )
        reader.start()
        deadline = time.monotonic() + 5
        while client.get("/api/v1/stats").json()["viewers"] < 1:
            if time.monotonic() > deadline:
                raise RuntimeError("the viewer did not connect")
            time.sleep(0.05)
    s0 = client.get("/api/v1/stats").json()
    cpu0 = cpu_seconds(pid) if pid else float("nan")
    cmd = [
        sys.executable,
        "-m",
        "clients.publish",
        "--scenario",
        "reference",
        "--scans",
        str(scans),
        "-e",
        endpoint,
        "-q",
        "--time-offset",
        str(offset),
    ]
    cmd += ["--rate", "realtime", "--speed", str(rate)] if rate else ["--rate", "max"]
    latencies: list[float] = []
    stop = threading.Event()
    sampler = threading.Thread(target=sample_latency, args=(client, stop, latencies), daemon=True)
    sampler.start()
    pub = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600, check=False)
    stop.set()
    if pub.returncode != 0:
        raise RuntimeError(f"publisher failed ({pub.returncode}): {pub.stderr.strip()}")
    # "published N batches in X s (...)": from its first put to the service's last answer
    m = re.search(r"published (\d+) batches in ([\d.]+) s", pub.stdout)
    if m is None:
        raise RuntimeError(f"unexpected publisher output: {pub.stdout!r}")
    elapsed_pub = float(m.group(2))
    s1 = client.get("/api/v1/stats").json()
    cpu1 = cpu_seconds(pid) if pid else float("nan")
    processed = s1["batches_processed"] - s0["batches_processed"]
    sampler.join(1.0)
    if reader is not None:
        stop_viewer.set()
        reader.join(15.0)
        if reader.is_alive():
            raise RuntimeError("the viewer did not stop")
    return Phase(
        name=name,
        target_rate=rate,
        published=scans,
        processed=processed,
        rejected=s1["batches_rejected"] - s0["batches_rejected"],
        dropped=s1["batches_dropped"] - s0["batches_dropped"],
        rate=processed / elapsed_pub,
        tracker_p50=s1["processing_ms"]["p50"],
        tracker_p99=s1["processing_ms"]["p99"],
        get_ms=np.asarray(latencies),
        cpu_ms_per_batch=1e3 * (cpu1 - cpu0) / max(processed, 1),
        frames=frames[0] if viewer else None,
        frames_dropped=(s1["view_frames_dropped"] - s0["view_frames_dropped"] if viewer else None),
    )


def frame_cost(repeats: int = 200) -> tuple[float, int, int]:
    """Median milliseconds to build one live-view frame in process (what the service does at
    most 10 times a second while a viewer is connected, off the tracker's worker), from the
    reference scenario's tracker state after 50 scans; and its track and detection counts."""
    from clients.scenarios.multitarget import reference_scenario, simulate
    from service.convert import report_dict, track_to_dict
    from service.reports import ReportState
    from service.viewers import Frame
    from trackers.config import TrackerConfig
    from trackers.pipeline import TrackingPipeline

    pipeline = TrackingPipeline(TrackerConfig())
    scans = simulate(reference_scenario(0))[:50]
    for scan in scans:
        result = pipeline.process(scan.to_scan())
    confirmed = [track_to_dict(t) for t in result.confirmed()]
    state = ReportState.of(report_dict(1, result, 1.0, confirmed), result)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        Frame(state, scans[-1].z).data  # noqa: B018 - building the bytes is what is timed
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times)), len(result.tracks), len(scans[-1].z)


def ingest_cost(repeats: int = 2000) -> tuple[float, int]:
    """Median milliseconds to check (cost bounds, decoding, validation, duplicate keys) and
    convert one reference batch (JSON bytes to tracker arrays), as the engine does for each
    batch; and the batch's detection count."""
    import orjson

    from clients.scenarios.multitarget import reference_scenario, simulate
    from service.convert import batch_to_scan
    from service.ingest import check_batch
    from service.schemas import IngestConfig

    scan = simulate(reference_scenario(0))[50]
    payload = orjson.dumps(scan.to_batch())
    ingest = IngestConfig()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        batch_to_scan(check_batch(payload, scan.sensor_id, ingest), 5.0)
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times[repeats // 10 :])), len(scan.z)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.service_load",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--rate", type=float, default=200.0, help="paced phase, batches/s")
    parser.add_argument("--seconds", type=float, default=15.0, help="length of each phase")
    parser.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="max-rate phases one after another (a soak: watch the service's memory)",
    )
    parser.add_argument(
        "--no-viewer", action="store_true", help="skip the phases with a live viewer connected"
    )
    parser.add_argument(
        "--viewer-first",
        action="store_true",
        help="run each phase with a viewer before its twin without one (the default is after)",
    )
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error("--rounds: at least 1")

    with (
        running_service() as service,
        httpx.Client(base_url=service.url, timeout=5.0) as client,
    ):
        endpoint = service.endpoint
        scans = int(args.rate * args.seconds)
        rss = [("started", rss_mb(service.pid))]
        phases: list[Phase] = []
        offset = 0.0

        def run(name: str, rate: float | None, viewer: bool) -> None:
            nonlocal offset
            phases.append(
                run_phase(
                    name, client, endpoint, scans, rate, offset, viewer=viewer, pid=service.pid
                )
            )
            rss.append((name, rss_mb(service.pid)))
            offset += float(scans) + PHASE_GAP

        # each viewer phase right after (or, with --viewer-first, right before) its twin
        # without one, so that the service's state and the machine are alike for both
        twins = (
            [False] if args.no_viewer else ([True, False] if args.viewer_first else [False, True])
        )
        for viewer in twins:
            run(f"paced {args.rate:.0f}/s" + ("+viewer" if viewer else ""), args.rate, viewer)
        for k in range(1, args.rounds + 1):
            name = "max rate" if args.rounds == 1 else f"max rate {k}"
            for viewer in twins if k == args.rounds else [False]:
                run(name + ("+viewer" if viewer else ""), None, viewer)

    decode_ms, n_det = ingest_cost()
    print(
        f"== ingest: decode, validate and convert a {n_det}-detection batch: "
        f"median {decode_ms:.3f} ms (in the engine's worker, before the tracker)"
    )
    print("== the service under load: ~55-detection batches over Zenoh from another process,")
    print("   GET /api/v1/tracks ~100/s from a third; service, publisher and reader share 2 cores")
    print(
        f"   {'phase':<20}{'published':>10}{'processed':>10}{'rejected':>9}{'dropped':>8}"
        f"{'batches/s':>10}{'tracker p50/p99 ms':>20}{'CPU ms/batch':>13}"
        f"{'GET p50/p99/max ms':>22}"
    )
    for p in phases:
        g = p.get_ms
        print(
            f"   {p.name:<20}{p.published:>10}{p.processed:>10}{p.rejected:>9}{p.dropped:>8}"
            f"{p.rate:>10.1f}{p.tracker_p50:>11.2f}/{p.tracker_p99:<8.2f}"
            f"{p.cpu_ms_per_batch:>13.2f}"
            f"{np.percentile(g, 50):>9.2f}/{np.percentile(g, 99):.2f}/{g.max():.1f}"
        )
    if not args.no_viewer:
        frame_ms, n_tracks, n_det = frame_cost()
        print(
            f"   a live-view frame ({n_tracks} tracks, {n_det} detections) costs {frame_ms:.3f} ms "
            f"to build, once for every viewer, off the tracker's worker: at 10 frames/s "
            f"{100 * frame_ms * 10 / 1000:.3f} % of one core"
        )
    for p in phases:
        if p.frames is not None:
            print(
                f"   {p.name}: the viewer read {p.frames} frames; {p.frames_dropped} dropped "
                "for it (replaced by newer ones; at most 10 frames/s are sent)"
            )
    print(
        "   service resident memory: "
        + ", ".join(f"{name} {mb:.0f} MB" for name, mb in rss if not math.isnan(mb))
    )
    paced = [p for p in phases if p.target_rate]
    ok_rate = min(p.rate for p in phases if not p.target_rate) >= 200 and all(
        p.rate >= 0.97 * args.rate for p in paced
    )
    lost = any(p.processed != p.published or p.dropped or p.rejected for p in phases)
    p99 = max(float(np.percentile(p.get_ms, 99)) for p in phases)
    print(
        f"   targets: ≥ 200 batches/s ({'met' if ok_rate else 'NOT met'}), nothing lost "
        f"({'met' if not lost else 'NOT met'}), "
        f"GET p99 < 20 ms ({'met' if p99 < 20 else 'NOT met'}: {p99:.1f} ms)"
    )
    return 0 if ok_rate and not lost and p99 < 20 else 1


if __name__ == "__main__":
    sys.exit(main())
