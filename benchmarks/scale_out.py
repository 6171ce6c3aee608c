"""Scale-out over Zenoh: does a second service instance add throughput?

    python -m benchmarks.scale_out [--targets 500] [--scans 200] [--clutter 30] [--seed 1]
                                   [--quick]

Two sectors side by side (``sector-a``: x in [-100 km, 0], ``sector-b``: x in [0, 100 km],
y in [-50 km, 50 km]), each seen by its own sensor scanning every second (``sector-b`` half
a second after ``sector-a``) with ``--targets`` constant-velocity targets (10 to 50 m/s,
detected with Pd 0.9 and 40 m noise) and about ``--clutter`` uniform false alarms per scan.
Every batch is encoded to JSON once, before anything is timed, and written to a temporary
file. Then two configurations run, each on fresh processes:

- **1 instance**: a Zenoh router (``python -m service.router``) and one service instance
  connected to it, taking every sensor's batches (the default detection keys);
- **2 instances**: the router and two instances started with ``--scale-out``, ``a`` taking
  ``tracking/detections/sector-a`` and ``b`` taking ``tracking/detections/sector-b``.

In both, the same publisher, a separate process (this module's hidden ``publish``
sub-command), joins the router as a Zenoh client and puts the same batches in time order
(the sectors interleaved), reliable and with ``CongestionControl.BLOCK``, as fast as the
service takes them. It waits until a subscriber matches each sensor's key, puts a few
warm-up scans (not counted; the tracks start there), and once the instances have processed
them puts the rest. This process only reads each instance's ``GET /api/v1/stats`` (a few
times a second, more often near the end; it does not subscribe to the track reports) until
the instances together have processed every batch.

How to read the table: ``batches/s`` is the batches processed after the warm-up divided by
the time from the first of them published to the last processed (as seen by the polling),
summed over the instances; ``detections/s`` the same for the detections in them. ``ratio``
is the 2-instance figure over the 1-instance one: 2.0 would be perfect scaling of the same
work; on a 2-core machine the router, the publisher and the REST polling share the cores
with the instances, so the target is 1.5. It can exceed 2: the work is not the same, since
a single instance's Track report after each batch holds the confirmed tracks of both
sectors, which are converted and encoded every time, while each of two instances reports
only its own sector's. ``lost`` must be 0 (published minus processed, plus the batches every
instance rejected or dropped), and the confirmed tracks per instance at the end should be
about ``--targets`` per sector (about twice that for the single instance, which holds both
sectors). The CPU lines show each process's CPU time (all its threads) over the timed
interval as a share of one core (``other``: whatever else ran on the machine meanwhile,
which should be near 0), and the whole machine's busy share: a process near 100 % is the
bottleneck (an instance's tracker runs on one thread), a machine near 100 % means the cores
are the limit. Exits 1 when something was lost or, except with ``--quick``, the
ratio is below 1.5.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import queue
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
import orjson

from benchmarks.service_process import ROOT, cpu_seconds, free_port, running_service

__all__ = [
    "SECTORS",
    "TARGET_RATIO",
    "RunResult",
    "generate_batches",
    "main",
    "run_benchmark",
]

#: Sensor id and x range (m) of each sector; y is in [-50 km, 50 km] for both.
SECTORS: tuple[tuple[str, float, float], ...] = (
    ("sector-a", -100_000.0, 0.0),
    ("sector-b", 0.0, 100_000.0),
)
Y_RANGE = (-50_000.0, 50_000.0)
#: Seconds between two scans of a sensor; ``sector-b`` scans ``SCAN_PERIOD / 2`` later.
SCAN_PERIOD = 1.0
PD = 0.9
NOISE_STD = 40.0  # m, per axis
SPEED_RANGE = (10.0, 50.0)  # m/s
#: The 2-instance throughput over the 1-instance one that the benchmark asks for.
TARGET_RATIO = 1.5
#: Shortest and longest wait, seconds, between two reads of the instances' ``/api/v1/stats``.
#: A read is not free for an instance holding many tracks (it counts the tentative ones by
#: building every track's snapshot, on the instance's event loop), so the polling waits half
#: the expected time left, within these bounds: a few reads a second, and fine steps near the
#: end, where the time of the last batch is read.
POLL_MIN_S = 0.01
POLL_MAX_S = 0.5
#: Seconds without progress after which a configuration is given up.
STALL_S = 60.0
#: Scans of each sensor put before the timed ones (not counted).
WARMUP_SCANS = 10
QUICK = {"targets": 50, "scans": 20}

_LEN = struct.Struct("<I")


# -- the scenario ---------------------------------------------------------------------------


def generate_batches(
    targets: int, scans: int, clutter: float, seed: int
) -> list[tuple[str, bytes]]:
    """``(key expression, JSON payload)`` of every detection batch of both sectors, in time
    order: ``sector-a`` at ``k * SCAN_PERIOD``, ``sector-b`` half a period later."""
    rng = np.random.default_rng(seed)
    y0, y1 = Y_RANGE
    sectors = []
    for sensor, x0, x1 in SECTORS:
        pos = np.column_stack([rng.uniform(x0, x1, targets), rng.uniform(y0, y1, targets)])
        speed = rng.uniform(*SPEED_RANGE, targets)
        heading = rng.uniform(0.0, 2 * np.pi, targets)
        vel = np.column_stack([speed * np.cos(heading), speed * np.sin(heading)])
        density = clutter / ((x1 - x0) * (y1 - y0))
        sectors.append((sensor, x0, x1, pos, vel, density))
    out = []
    for k in range(scans):
        for j, (sensor, x0, x1, pos, vel, density) in enumerate(sectors):
            t = k * SCAN_PERIOD + j * SCAN_PERIOD / 2
            truth = pos + vel * t
            seen = truth[rng.random(targets) < PD]
            z = seen + rng.normal(0.0, NOISE_STD, seen.shape)
            n_false = int(rng.poisson(clutter))
            false = np.column_stack([rng.uniform(x0, x1, n_false), rng.uniform(y0, y1, n_false)])
            z = np.round(np.concatenate([z, false]), 1)
            rng.shuffle(z)
            batch = {
                "sensor_id": sensor,
                "time": t,
                "cov": [[NOISE_STD**2, 0.0], [0.0, NOISE_STD**2]],
                "pd": PD,
                "clutter_density": density,
                "detections": [{"x": float(x), "y": float(y)} for x, y in z],
            }
            out.append((f"tracking/detections/{sensor}", orjson.dumps(batch)))
    return out


def write_batches(path: Path, batches: Sequence[tuple[str, bytes]]) -> None:
    """Each batch as its key and payload, each length-prefixed (little-endian u32)."""
    with open(path, "wb") as f:
        for key, payload in batches:
            raw = key.encode()
            f.write(_LEN.pack(len(raw)) + raw + _LEN.pack(len(payload)) + payload)


def read_batches(path: Path) -> list[tuple[str, bytes]]:
    """The batches :func:`write_batches` wrote."""
    data = Path(path).read_bytes()
    out, i = [], 0
    while i < len(data):
        (n,) = _LEN.unpack_from(data, i)
        key = data[i + 4 : i + 4 + n].decode()
        i += 4 + n
        (n,) = _LEN.unpack_from(data, i)
        out.append((key, data[i + 4 : i + 4 + n]))
        i += 4 + n
    return out


# -- the publisher process ------------------------------------------------------------------


def publish_main(argv: Sequence[str]) -> int:
    """The hidden ``publish`` sub-command: the publisher process of one configuration.

    Talks with the benchmark over stdin/stdout, one line each: prints ``ready`` once a
    subscriber matches every key, ``warm`` after putting the first ``--warmup`` batches,
    then waits for ``go``, prints ``start <wall time>`` and puts the rest, prints
    ``published <count>``, and waits for ``exit`` (or end of input) before closing its
    session, so that no put still in flight is lost."""
    import zenoh

    from clients.zenoh_session import open_session, wait_for_matching

    parser = argparse.ArgumentParser(prog="python -m benchmarks.scale_out publish")
    parser.add_argument("batches", type=Path, help="a file written by write_batches")
    parser.add_argument("--connect", required=True, help="the router's endpoint")
    parser.add_argument("--warmup", type=int, default=0, help="batches put before 'go'")
    parser.add_argument("--mode", choices=("client", "peer"), default="client")
    args = parser.parse_args(argv)

    batches = read_batches(args.batches)

    def say(line: str) -> None:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()

    with open_session(args.mode, [args.connect]) as session:
        publishers: dict[str, zenoh.Publisher] = {}
        for key, _ in batches:
            if key not in publishers:
                publishers[key] = session.declare_publisher(
                    key,
                    encoding=zenoh.Encoding.APPLICATION_JSON,
                    congestion_control=zenoh.CongestionControl.BLOCK,
                    reliability=zenoh.Reliability.RELIABLE,
                )
        for key, pub in publishers.items():
            if not wait_for_matching(pub, 30.0):
                sys.stderr.write(f"no subscriber matched {key}\n")
                return 1
        say("ready")
        for key, payload in batches[: args.warmup]:
            publishers[key].put(payload)
        say("warm")
        if sys.stdin.readline().strip() != "go":
            return 1
        say(f"start {time.time():.6f}")
        for key, payload in batches[args.warmup :]:
            publishers[key].put(payload)
        say(f"published {len(batches) - args.warmup}")
        sys.stdin.readline()  # "exit", or the end of input
        for pub in publishers.values():
            pub.undeclare()
    return 0


class _Lines:
    """A child's stdout read line by line on a thread, each line awaited with a timeout."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.process = process
        self._lines: queue.Queue[str | None] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self._lines.put(line.strip())
        self._lines.put(None)

    def expect(self, word: str, timeout: float) -> str:
        """The next line, which must start with ``word``; the rest of it."""
        try:
            line = self._lines.get(timeout=timeout)
        except queue.Empty:
            raise RuntimeError(f"the publisher did not say {word!r} in {timeout:.0f} s") from None
        if line is None or not line.startswith(word):
            raise RuntimeError(f"the publisher said {line!r}, expected {word!r}")
        return line[len(word) :].strip()

    def send(self, line: str) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()


# -- processes ------------------------------------------------------------------------------


def _stop(process: subprocess.Popen[str] | subprocess.Popen[bytes], grace: float = 10.0) -> None:
    """SIGTERM, then SIGKILL after ``grace`` seconds."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(grace)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


@contextmanager
def _running_router() -> Iterator[tuple[subprocess.Popen[bytes], str]]:
    """A ``service.router`` on a free loopback port, accepting connections; its endpoint.
    Its log goes to a temporary file, shown when it fails to start."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with tempfile.TemporaryFile() as log:
        process = subprocess.Popen(
            [
                *(sys.executable, "-m", "service.router"),
                *("--listen", endpoint, "--log-level", "warning"),
            ],
            cwd=ROOT,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=log,
        )
        try:
            deadline = time.monotonic() + 30
            while True:
                with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
                    break
                if process.poll() is not None or time.monotonic() > deadline:
                    _stop(process)
                    log.seek(0)
                    err = log.read().decode(errors="replace").strip()
                    raise RuntimeError(f"the router did not start:\n{err}")
                time.sleep(0.05)
            yield process, endpoint
        finally:
            _stop(process)


@contextmanager
def _running_publisher(
    batches_file: Path, router: str, warmup: int
) -> Iterator[tuple[subprocess.Popen[str], _Lines]]:
    """The publisher process (:func:`publish_main`) of ``batches_file``, talking over its
    stdin and stdout; at the end its input is closed (it closes its session and exits),
    and it is stopped if it has not within 10 s."""
    process = subprocess.Popen(
        [
            *(sys.executable, "-m", "benchmarks.scale_out", "publish", str(batches_file)),
            *("--connect", router, "--warmup", str(warmup)),
        ],
        cwd=ROOT,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        yield process, _Lines(process)
    finally:
        if process.stdin is not None:
            with contextlib.suppress(OSError):
                process.stdin.close()  # the end of input: it closes its session and exits
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            _stop(process)


# -- one configuration ----------------------------------------------------------------------


@dataclass
class RunResult:
    """What one configuration did in the timed interval (after the warm-up)."""

    name: str
    instances: list[str]
    published: int
    processed: int
    detections: int
    seconds: float
    rejected: int
    dropped: int
    confirmed: dict[str, int]  # confirmed tracks per instance at the end
    tracker_p50_ms: dict[str, float]  # per instance, over its latest batches
    cpu_share: dict[str, float] = field(default_factory=dict)  # per process, of one core
    machine_busy: float = float("nan")  # share of all cores busy

    @property
    def batches_per_s(self) -> float:
        return self.processed / self.seconds

    @property
    def detections_per_s(self) -> float:
        return self.detections / self.seconds

    @property
    def lost(self) -> int:
        return self.published - self.processed + self.rejected + self.dropped


def _machine_times() -> tuple[float, float]:
    """Busy and total jiffies of all cores so far (``/proc/stat``; NaN elsewhere)."""
    try:
        fields = [float(v) for v in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    except OSError:
        return float("nan"), float("nan")
    total = sum(fields[:8])  # user .. steal (guest time is counted in user already)
    idle = sum(fields[3:5])  # idle, iowait
    return total - idle, total


def _all_stats(clients: dict[str, httpx.Client]) -> dict[str, dict]:
    """Each instance's ``/api/v1/stats``."""
    return {name: c.get("/api/v1/stats").raise_for_status().json() for name, c in clients.items()}


def _wait_processed(
    clients: dict[str, httpx.Client], count: int, processes: Sequence[subprocess.Popen]
) -> tuple[dict[str, dict], float]:
    """Poll until the instances together processed (or refused) ``count`` batches; their
    stats and the wall time when the polling saw it. Raises when one of ``processes``
    exits or nothing moves for ``STALL_S`` seconds."""
    last, last_change = -1, time.monotonic()
    first: tuple[float, int] | None = None
    while True:
        stats = _all_stats(clients)
        now = time.time()
        done = sum(s["batches_processed"] for s in stats.values())
        refused = sum(s["batches_rejected"] + s["batches_dropped"] for s in stats.values())
        if done + refused >= count:
            return stats, now
        first = first or (now, done)
        rate = (done - first[1]) / (now - first[0]) if now > first[0] else 0.0
        left = (count - done - refused) / rate if rate > 0 else 10 * POLL_MIN_S
        if done != last:
            last, last_change = done, time.monotonic()
        elif time.monotonic() - last_change > STALL_S:
            raise RuntimeError(f"no progress for {STALL_S:.0f} s: {done} of {count} processed")
        for process in processes:
            if process.poll() is not None:
                raise RuntimeError(f"{process.args!r} exited ({process.returncode}) mid-run")
        time.sleep(min(max(left / 2, POLL_MIN_S), POLL_MAX_S))


def run_configuration(
    name: str,
    instance_args: dict[str, list[str]],
    batches_file: Path,
    n_batches: int,
    warmup: int,
) -> RunResult:
    """Run one configuration: the router, an instance per ``instance_args`` entry (its extra
    command-line arguments), the publisher; timed from the first batch after the ``warmup``
    ones until every batch is processed."""
    with ExitStack() as stack:
        router, endpoint = stack.enter_context(_running_router())
        services = {
            inst: stack.enter_context(running_service("--zenoh-connect", endpoint, *extra))
            for inst, extra in instance_args.items()
        }
        clients = {
            inst: stack.enter_context(httpx.Client(base_url=svc.url, timeout=10.0))
            for inst, svc in services.items()
        }
        publisher, lines = stack.enter_context(_running_publisher(batches_file, endpoint, warmup))
        children = [router, publisher, *(svc.process for svc in services.values())]
        lines.expect("ready", 60)
        lines.expect("warm", 60)
        s0, _ = _wait_processed(clients, warmup, children)
        procs = {"router": router.pid, "publisher": publisher.pid}
        procs.update({f"instance {inst}": svc.pid for inst, svc in services.items()})
        cpu0 = {p: cpu_seconds(pid) for p, pid in procs.items()}
        own0, machine0 = time.process_time(), _machine_times()
        lines.send("go")
        t0 = float(lines.expect("start", 30))
        s1, t1 = _wait_processed(clients, n_batches, children)
        cpu1 = {p: cpu_seconds(pid) for p, pid in procs.items()}
        own1, machine1 = time.process_time(), _machine_times()
        lines.expect("published", 30)
        lines.send("exit")
        confirmed = {
            inst: len(c.get("/api/v1/tracks").raise_for_status().json()["tracks"])
            for inst, c in clients.items()
        }

    def delta(key: str) -> int:
        return sum(s1[i][key] - s0[i][key] for i in s1)

    seconds = max(t1 - t0, 1e-9)
    cpu = {p: (cpu1[p] - cpu0[p]) / seconds for p in procs}
    cpu["benchmark (polling)"] = (own1 - own0) / seconds
    busy = (machine1[0] - machine0[0]) / max(machine1[1] - machine0[1], 1e-9)
    # whatever else ran on the machine meanwhile (another job's processes, the kernel)
    cpu["other"] = max(0.0, busy * (os.cpu_count() or 1) - sum(cpu.values()))
    return RunResult(
        name=name,
        instances=list(instance_args),
        published=n_batches - warmup,
        processed=delta("batches_processed"),
        detections=delta("detections_processed"),
        seconds=seconds,
        rejected=delta("batches_rejected"),
        dropped=delta("batches_dropped"),
        confirmed=confirmed,
        tracker_p50_ms={i: float(s1[i]["processing_ms"]["p50"]) for i in s1},
        cpu_share=cpu,
        machine_busy=busy,
    )


def run_benchmark(
    targets: int = 500,
    scans: int = 200,
    clutter: float = 30.0,
    seed: int = 1,
    warmup_scans: int = WARMUP_SCANS,
    log: bool = True,
) -> list[RunResult]:
    """Both configurations on the same batches: 1 instance, then 2 instances."""
    if scans <= warmup_scans:
        raise ValueError(f"scans ({scans}) must be more than the warm-up's ({warmup_scans})")
    t_gen = time.perf_counter()
    batches = generate_batches(targets, scans, clutter, seed)
    size = sum(len(p) for _, p in batches)
    if log:
        print(
            f"== {len(batches)} batches ({scans} scans x {len(SECTORS)} sectors, {targets} "
            f"targets each, ~{clutter:g} false alarms per scan), {size / 1e6:.1f} MB of JSON, "
            f"generated in {time.perf_counter() - t_gen:.1f} s",
            flush=True,
        )
    one = {"single": []}
    two = {
        sector[-1]: [
            *("--scale-out", "--instance-id", sector[-1]),
            *("--detection-keys", f"tracking/detections/{sector}"),
        ]
        for sector, _, _ in SECTORS
    }
    results = []
    with tempfile.TemporaryDirectory(prefix="tracker-scale-out-") as tmp:
        path = Path(tmp) / "batches.bin"
        write_batches(path, batches)
        for name, instance_args in (("1 instance", one), ("2 instances", two)):
            t_run = time.perf_counter()
            result = run_configuration(
                name, instance_args, path, len(batches), warmup_scans * len(SECTORS)
            )
            results.append(result)
            if log:
                print(
                    f"   {name}: {result.batches_per_s:.1f} batches/s "
                    f"(configuration run in {time.perf_counter() - t_run:.1f} s)",
                    flush=True,
                )
    return results


def print_results(results: Sequence[RunResult]) -> float:
    """The table; returns the ratio of the last configuration's batches/s to the first's."""
    print(
        f"   {'configuration':<14}{'instances':>10}{'published':>10}{'processed':>10}"
        f"{'lost':>6}{'seconds':>9}{'batches/s':>11}{'detections/s':>14}{'ratio':>7}"
    )
    base = results[0].batches_per_s
    for r in results:
        print(
            f"   {r.name:<14}{len(r.instances):>10}{r.published:>10}{r.processed:>10}"
            f"{r.lost:>6}{r.seconds:>9.2f}{r.batches_per_s:>11.1f}{r.detections_per_s:>14.0f}"
            f"{r.batches_per_s / base:>7.2f}"
        )
    for r in results:
        tracks = ", ".join(
            f"{i}: {r.confirmed[i]} confirmed, tracker p50 {r.tracker_p50_ms[i]:.1f} ms"
            for i in r.instances
        )
        print(
            f"   {r.name}: rejected {r.rejected}, dropped {r.dropped}; {tracks}",
        )
        cpu = ", ".join(f"{p} {100 * share:.0f} %" for p, share in r.cpu_share.items())
        print(
            f"      CPU (share of one core): {cpu}; machine {100 * r.machine_busy:.0f} % busy "
            f"({os.cpu_count()} cores)"
        )
    return results[-1].batches_per_s / base


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["publish"]:
        return publish_main(argv[1:])
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.scale_out",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--targets", type=int, default=500, help="targets per sector")
    parser.add_argument(
        "--scans", type=int, default=200, help="scans of each sensor (10 of them a warm-up)"
    )
    parser.add_argument(
        "--clutter", type=float, default=30.0, help="mean false alarms per scan and sector"
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--quick",
        action="store_true",
        help=f"a smoke test: {QUICK['targets']} targets, {QUICK['scans']} scans, no ratio target",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.targets, args.scans = QUICK["targets"], QUICK["scans"]
    warmup = min(WARMUP_SCANS, args.scans // 4)
    if args.targets < 1 or args.scans <= warmup or args.clutter < 0:
        parser.error("--targets must be at least 1, --scans at least 5, --clutter not negative")

    # SIGTERM unwinds as Ctrl-C does: every child process is stopped on the way out
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    t0 = time.perf_counter()
    results = run_benchmark(args.targets, args.scans, args.clutter, args.seed, warmup)
    print(f"== scale-out over Zenoh: {args.targets} targets per sector, {warmup} warm-up scans")
    ratio = print_results(results)
    lost = sum(r.lost for r in results)
    ok_ratio = args.quick or ratio >= TARGET_RATIO
    print(
        f"   targets: nothing lost ({'met' if not lost else f'NOT met: {lost}'}), "
        f"2 instances ≥ {TARGET_RATIO}x 1 instance "
        f"({'not asked (--quick)' if args.quick else 'met' if ok_ratio else 'NOT met'}: "
        f"{ratio:.2f}x); total {time.perf_counter() - t0:.1f} s"
    )
    return 0 if not lost and ok_ratio else 1


if __name__ == "__main__":
    sys.exit(main())
