"""Hostile senders against the service: huge batches over Zenoh and REST while another sensor
publishes normal batches.

    python -m benchmarks.hostile [--sizes 1000000 2500000] [--repeat 2] [--rate 20]

Starts ``tracker-service`` as a subprocess with its default limits on free loopback ports.
This process is the other sensor (``radar-ok``: the reference scenario's ~55-detection
batches at ``--rate`` per second over Zenoh, reliable and blocking) and times each of its
batches from the put to its Track report; and it asks ``GET /health`` every 10 ms. Then, one
case at a time, a hostile sender (``hostile-1``) sends ``--repeat`` batches of each of
``--sizes`` detections (``{"x":1.5,"y":2.5}`` each: 18 bytes a detection), over Zenoh and
then over REST; and, within the limits, the costliest batches the limits let through: 10,000
detections with every field whose last one is invalid (validated to the end), and 4 MB of
220,000 small detections (refused from the count of its bytes).

Printed per case: what the service answered the hostile sender, the service's peak resident
memory during the case (the kernel's high-water mark, reset before each case), its resident
memory a second after, the other sensor's worst and median wait (put to Track report), and
the worst ``/health`` latency. Exits 1 when a target is missed: peak under 300 MB, the other
sensor's worst wait under 100 ms more than with no hostile sender, ``/health`` under 100 ms,
every hostile batch refused with one Error report, and the counters agreeing at the end.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import orjson
import zenoh

from benchmarks.service_process import proc_status_mb, rss_mb, running_service
from clients.scenarios.multitarget import reference_scenario, simulate
from service.keys import Keys, make_config

OTHER = "radar-ok"
HOSTILE = "hostile-1"
KEYS = Keys()
PEAK_TARGET_MB = 300.0
WAIT_TARGET_MS = 100.0
HEALTH_TARGET_MS = 100.0


def reset_peak(pid: int) -> bool:
    """Reset the kernel's peak resident memory of ``pid`` (VmHWM); False if not allowed."""
    try:
        Path(f"/proc/{pid}/clear_refs").write_text("5")
    except OSError:
        return False
    return True


class MemorySampler(threading.Thread):
    """The peak of VmRSS sampled every 2 ms (when VmHWM cannot be reset)."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid = pid
        self.peak = 0.0
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.wait(0.002):
            self.peak = max(self.peak, rss_mb(self.pid))


class OtherSensor(threading.Thread):
    """Publishes normal batches at ``rate`` per second; records (put time, wait) for each."""

    def __init__(self, session: zenoh.Session, rate: float) -> None:
        super().__init__(daemon=True)
        self.session = session
        self.period = 1.0 / rate
        self.scans = simulate(reference_scenario(0))
        self.pending: dict[float, float] = {}
        self.waits: list[tuple[float, float]] = []
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.errors: list[dict[str, Any]] = []

    def on_report(self, report: dict[str, Any]) -> None:
        if report.get("sensor_id") != OTHER:
            return
        now = time.monotonic()
        with self.lock:
            put = self.pending.pop(report["time"], None)
            if put is not None:
                self.waits.append((put, now - put))

    def run(self) -> None:
        pub = self.session.declare_publisher(
            KEYS.detections(OTHER),
            encoding=zenoh.Encoding.APPLICATION_JSON,
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        while not pub.matching_status.matching:
            time.sleep(0.01)
        k = 0
        next_put = time.monotonic()
        while not self.stop.is_set():
            scan = self.scans[k % len(self.scans)]
            t = float(k)  # a second of sensor time per batch, ever increasing
            payload = orjson.dumps({**scan.to_batch(), "sensor_id": OTHER, "time": t})
            with self.lock:
                self.pending[t] = time.monotonic()
            pub.put(payload)
            k += 1
            next_put += self.period
            self.stop.wait(max(0.0, next_put - time.monotonic()))
        pub.undeclare()

    def between(self, start: float, end: float) -> np.ndarray:
        with self.lock:
            return np.array([w for put, w in self.waits if start <= put <= end]) * 1e3


class HealthProbe(threading.Thread):
    """``GET /health`` every 10 ms; records (time, latency)."""

    def __init__(self, url: str) -> None:
        super().__init__(daemon=True)
        self.url = url
        self.samples: list[tuple[float, float]] = []
        self.stop = threading.Event()

    def run(self) -> None:
        with httpx.Client(base_url=self.url, timeout=30) as http:
            while not self.stop.is_set():
                t0 = time.monotonic()
                ok = http.get("/health").status_code == 200
                self.samples.append((t0, (time.monotonic() - t0) if ok else float("inf")))
                self.stop.wait(0.01)

    def between(self, start: float, end: float) -> np.ndarray:
        return np.array([lat for t, lat in list(self.samples) if start <= t <= end]) * 1e3


@dataclass
class Case:
    name: str
    outcomes: list[str] = field(default_factory=list)
    answer_s: float = 0.0
    peak_mb: float = 0.0
    after_mb: float = 0.0
    waits_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    health_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))


def small_detections(n: int, t: float) -> bytes:
    """A batch of ``n`` detections of 18 bytes each."""
    head = b'{"sensor_id":"%s","time":%r,"detections":[' % (HOSTILE.encode(), t)
    return head + b",".join([b'{"x":1.5,"y":2.5}'] * n) + b"]}"


def full_detections(n: int, t: float) -> bytes:
    """``n`` detections with every field; the last one's covariance is not positive
    definite, so the whole batch is validated and then refused."""
    dets = [
        {
            "x": -123456.78901234567 + i,
            "y": 98765.432109876543 - i,
            "cov": [[25.123456789012345, 0.5], [0.5, 25.98765432109876]],
            "vr": -123.45678901234567,
            "amplitude": 12.345678901234567,
            "id": f"hostile-detection-{i:012d}",
        }
        for i in range(n)
    ]
    dets[-1]["cov"] = [[1.0, 2.0], [2.0, 1.0]]
    return orjson.dumps(
        {"sensor_id": HOSTILE, "time": t, "detections": dets, "sensor_position": [0.0, 0.0]}
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.hostile",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--sizes", type=int, nargs="+", default=[1_000_000, 2_500_000], help="detections"
    )
    parser.add_argument("--repeat", type=int, default=2, help="hostile batches per case")
    parser.add_argument("--rate", type=float, default=20.0, help="other sensor, batches/s")
    parser.add_argument(
        "--only", default="", help="run only the cases whose name holds this text (and the base)"
    )
    args = parser.parse_args(argv)

    cases: list[Case] = []
    hostile_errors: list[dict[str, Any]] = []
    errors_seen = threading.Condition()
    with running_service() as service, httpx.Client(base_url=service.url, timeout=120) as http:
        endpoint, url, pid = service.endpoint, service.url, service.pid
        session = zenoh.open(make_config("peer", [], [endpoint]))
        hostile_session = zenoh.open(make_config("peer", [], [endpoint]))
        try:
            other = OtherSensor(session, args.rate)

            def on_tracks(sample: zenoh.Sample) -> None:
                other.on_report(orjson.loads(sample.payload.to_bytes()))

            def on_error(sample: zenoh.Sample) -> None:
                report = orjson.loads(sample.payload.to_bytes())
                with errors_seen:
                    if report["sensor_id"] == OTHER:
                        other.errors.append(report)
                    else:
                        hostile_errors.append(report)
                    errors_seen.notify_all()

            subs = [
                session.declare_subscriber(KEYS.tracks, on_tracks),
                session.declare_subscriber(KEYS.all_errors, on_error),
            ]
            hostile_pub = hostile_session.declare_publisher(
                KEYS.detections(HOSTILE),
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
            while not hostile_pub.matching_status.matching:
                time.sleep(0.01)
            health = HealthProbe(url)
            other.start()
            health.start()
            time.sleep(3.0)  # the other sensor's tracks start

            def run_case(name: str, send: Callable[[int], str | None]) -> None:
                if cases and args.only not in name:
                    return
                case = Case(name)
                time.sleep(1.0)
                hwm = reset_peak(pid)
                sampler = MemorySampler(pid)
                sampler.start()
                start = time.monotonic()
                for i in range(args.repeat):
                    answer = send(i)
                    if answer is not None:
                        case.outcomes.append(answer)
                case.answer_s = time.monotonic() - start
                end = time.monotonic()
                time.sleep(1.0)  # the reports of the batches put during the case
                sampler.stop.set()
                sampler.join()
                case.peak_mb = proc_status_mb(pid, "VmHWM") if hwm else sampler.peak
                case.after_mb = rss_mb(pid)
                case.waits_ms = other.between(start, end + 0.2)
                case.health_ms = health.between(start, end + 0.2)
                cases.append(case)
                print(f"   ... {name}: {case.outcomes}", file=sys.stderr, flush=True)

            def over_zenoh(payload_of: Callable[[int], bytes]) -> Callable[[int], str]:
                def send(i: int) -> str:
                    payload = payload_of(i)
                    with errors_seen:
                        n = len(hostile_errors)
                    hostile_pub.put(payload)
                    with errors_seen:
                        if not errors_seen.wait_for(lambda: len(hostile_errors) > n, 120):
                            return "no answer"
                        return str(hostile_errors[n]["error"])

                return send

            def over_rest(payload_of: Callable[[int], bytes]) -> Callable[[int], str]:
                def send(i: int) -> str:
                    try:
                        r = http.post("/api/v1/detections", content=payload_of(i))
                    except httpx.HTTPError as exc:
                        return f"{type(exc).__name__}"
                    return f"{r.status_code} {r.json().get('error', '')}".strip()

                return send

            run_case("no hostile sender", lambda i: None)
            for n in args.sizes:
                payload = small_detections(n, 1.0)
                mb = len(payload) / 1e6
                run_case(f"Zenoh {n:,} ({mb:.0f} MB)", over_zenoh(lambda i, p=payload: p))
                run_case(f"REST  {n:,} ({mb:.0f} MB)", over_rest(lambda i, p=payload: p))
                del payload
            limit = 10_000
            full = [full_detections(limit, 1.0 + i) for i in range(args.repeat)]
            mb = len(full[0]) / 1e6
            run_case(
                f"Zenoh {limit:,} full, last bad ({mb:.1f} MB)",
                over_zenoh(lambda i: full[i]),
            )
            run_case(
                f"REST  {limit:,} full, last bad ({mb:.1f} MB)",
                over_rest(lambda i: full[i]),
            )
            many = small_detections(220_000, 1.0)
            mb = len(many) / 1e6
            run_case(f"Zenoh 220,000 small ({mb:.1f} MB)", over_zenoh(lambda i: many))
            run_case(f"REST  220,000 small ({mb:.1f} MB)", over_rest(lambda i: many))

            other.stop.set()
            health.stop.set()
            other.join(5)
            health.join(5)
            time.sleep(0.5)
            for sub in subs:
                sub.undeclare()
            hostile_pub.undeclare()
        finally:
            session.close()
            hostile_session.close()
        stats = http.get("/api/v1/stats").json()

    print("== hostile senders: the service with its default limits (max_batch_bytes 4 MiB,")
    print(f"   10,000 detections a batch); another sensor publishes {args.rate:g} batches/s of")
    print("   ~55 detections over Zenoh meanwhile; GET /health every 10 ms; all on 2 cores")
    print(
        f"   {'case':<38}{'answer':<28}{'peak MB':>8}{'after MB':>9}"
        f"{'other wait max/p50 ms':>23}{'health max ms':>14}"
    )
    base = cases[0]
    base_wait = float(base.waits_ms.max()) if base.waits_ms.size else 0.0
    ok = True
    for case in cases:
        answers = sorted(set(case.outcomes)) or ["-"]
        wait = case.waits_ms
        wmax = float(wait.max()) if wait.size else float("nan")
        wp50 = float(np.median(wait)) if wait.size else float("nan")
        hmax = float(case.health_ms.max()) if case.health_ms.size else float("nan")
        print(
            f"   {case.name:<38}{', '.join(answers):<28}{case.peak_mb:>8.0f}"
            f"{case.after_mb:>9.0f}{wmax:>14.1f}/{wp50:<8.1f}{hmax:>14.1f}"
        )
        if case is not base:
            refused = len(case.outcomes) == args.repeat and all(
                a != "no answer" and not a.startswith("202") for a in case.outcomes
            )
            ok &= refused
            ok &= case.peak_mb < PEAK_TARGET_MB
            ok &= not (wmax > base_wait + WAIT_TARGET_MS)
            ok &= not (hmax > HEALTH_TARGET_MS)
    counted = stats["batches_processed"] + stats["batches_rejected"] + stats["batches_dropped"]
    agree = stats["batches_received"] == counted
    ok &= agree
    print(
        f"   counters: received {stats['batches_received']}, processed "
        f"{stats['batches_processed']}, rejected {stats['batches_rejected']} "
        f"{stats['rejected_by_reason']}, dropped {stats['batches_dropped']} "
        f"({'agree' if agree else 'DISAGREE'})"
    )
    print(
        f"   targets: peak < {PEAK_TARGET_MB:.0f} MB, other sensor's worst wait < "
        f"{WAIT_TARGET_MS:.0f} ms over its {base_wait:.1f} ms with no hostile sender, "
        f"/health < {HEALTH_TARGET_MS:.0f} ms, each hostile batch refused: "
        f"{'met' if ok else 'NOT met'}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
