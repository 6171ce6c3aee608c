"""``python -m clients.demo``: a sensor and a reader in one, so a newcomer sees tracks at once.

Examples::

    python -m clients.demo                         # against a service on tcp/127.0.0.1:7447
    python -m clients.demo -e tcp/10.0.0.5:7447 --summary-interval 2

Publishes a scenario's batches over Zenoh in real time, as a sensor would, its times
starting after the service's latest report so they never go out of sequence: by default the
continuous scenario (:mod:`clients.scenarios.continuous`: targets born at random times, each
living a random while, so tracks end and start one by one as in life; one radar at 1 s,
Pd 0.9, clutter), or with ``--scenario reference`` the 100 s reference scenario in a loop,
or with ``--scenario convoy`` / ``--scenario harbour`` one of the extended-object scenarios of
:mod:`clients.scenarios.extended` in a loop (a convoy in traffic, 600 s at 5 s scans; a boat
entering a harbour, 300 s at 2 s scans). A loop's times follow on from the previous loop's.
Every ``--summary-interval`` seconds it asks the service's
queryable ``{prefix}/state/tracks`` for the latest Track report and logs a one-line summary
of the confirmed tracks. ``tracker-service --demo [SCENARIO]`` starts it as a child process
connected to the service and stops it on shutdown. Runs until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

import orjson
import zenoh

from clients.scenarios.continuous import ContinuousScenario
from clients.scenarios.multitarget import SimulatedScan, reference_scenario, simulate
from clients.zenoh_session import (
    DEFAULT_ENDPOINT,
    BatchPublisher,
    add_zenoh_arguments,
    session_from_args,
)
from service.keys import Keys

__all__ = [
    "SCENARIOS",
    "Demo",
    "build_parser",
    "latest_report",
    "looped_scans",
    "main",
    "summary_line",
]

log = logging.getLogger("clients.demo")


def summary_line(report: dict[str, Any], limit: int = 5) -> str:
    """``seq 42 t=41.0 s: 48 confirmed tracks: T3 (120, -40) 5.1 m/s, ...``"""
    tracks = report.get("tracks", [])
    parts = []
    for t in tracks[:limit]:
        (x, y), (vx, vy) = t["position"], t["velocity"]
        parts.append(f"{t['id']} ({x:.0f}, {y:.0f}) {math.hypot(vx, vy):.1f} m/s")
    more = f", +{len(tracks) - limit} more" if len(tracks) > limit else ""
    when = "-" if report.get("time") is None else f"{report['time']:.1f}"
    return f"seq {report.get('seq', 0)} t={when} s: {len(tracks)} confirmed tracks" + (
        ": " + ", ".join(parts) + more if parts else ""
    )


def latest_report(session: zenoh.Session, keys: Keys, timeout: float) -> dict[str, Any] | None:
    """The service's latest Track report from its queryable; ``None`` when none answers."""
    found: dict[str, Any] | None = None
    for reply in session.get(keys.state, timeout=timeout):
        if reply.ok is not None and found is None:
            found = orjson.loads(reply.ok.payload.to_bytes())
    return found


#: ``continuous``: targets come and go forever (:mod:`clients.scenarios.continuous`);
#: ``reference``: the 100 s reference scenario replayed in a loop; ``convoy`` and
#: ``harbour``: the extended-object scenarios (:mod:`clients.scenarios.extended`) in a loop;
#: ``formation``: paper 003's two formations seen by three radars, with clutter around them
#: (environment 2 at (λ1, λ2) = (2, 4), :mod:`clients.scenarios.formation`), in a loop.
SCENARIOS = ("continuous", "reference", "convoy", "harbour", "formation")


def looped_scans(scenario: str, seed: int = 0) -> list[SimulatedScan]:
    """The scans a looping scenario replays (every one but ``continuous``), in time order."""
    if scenario == "reference":
        return simulate(reference_scenario(seed))
    if scenario in ("convoy", "harbour"):
        from clients.scenarios import extended

        run = (
            extended.convoy_scenario(seed)
            if scenario == "convoy"
            else extended.harbour_scenario(seed)
        )
        return [truth.scan for truth in run.scans]
    if scenario == "formation":
        from clients.scenarios.formation import environment_2, simulate_formations

        return simulate_formations(environment_2(2.0, 4.0, seed=seed))
    raise ValueError(f"scenario: one of {', '.join(SCENARIOS[1:])}, got {scenario!r}")


class Demo:
    """Publishes a scenario in real time until ``stop`` is set (or, with ``parent``, until
    the process ``parent`` is no longer this process's parent)."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        *,
        stop: threading.Event,
        seed: int = 0,
        speed: float = 1.0,
        summary_interval: float = 5.0,
        wait_matching: float = 5.0,
        query_timeout: float = 2.0,
        parent: int | None = None,
        scenario: str = "continuous",
        sensor_id: str = "radar-1",
        centre: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        if scenario not in SCENARIOS:
            raise ValueError(f"scenario: one of {', '.join(SCENARIOS)}, got {scenario!r}")
        self.scenario = scenario
        #: the continuous scenario's radar: its id, and where it stands (its area around it)
        self.sensor_id = sensor_id
        self.centre = centre
        self.session = session
        self.keys = keys
        self.publisher = BatchPublisher(session, keys.prefix, wait_matching=wait_matching)
        self.seed = seed
        self.speed = speed
        self.summary_interval = summary_interval
        self.query_timeout = query_timeout
        self.parent = parent
        self._stop = stop
        self._next_summary = 0.0  # wall time of the next one-line summary

    @property
    def published(self) -> int:
        return self.publisher.published

    def run(self) -> None:
        if self.scenario == "continuous":
            self._run_continuous()
        else:
            self._run_loop(looped_scans(self.scenario, self.seed))

    def _run_continuous(self) -> None:
        """The continuous scenario, forever, its times shifted to after the service's latest."""
        cx, cy = self.centre
        (x0, x1), (y0, y1) = ContinuousScenario.area
        scenario = ContinuousScenario(
            seed=self.seed,
            sensor_id=self.sensor_id,
            sensor_position=self.centre,
            area=((x0 + cx, x1 + cx), (y0 + cy, y1 + cy)),
        )
        report = latest_report(self.session, self.keys, self.query_timeout)
        last = None if report is None else report.get("time")
        offset = 0.0 if last is None else float(last) + scenario.dt
        start_wall = time.monotonic()
        self._next_summary = start_wall + self.summary_interval
        for scan in scenario.scans():
            if self._pace(start_wall + scan.time / self.speed):
                return
            batch = scan.to_batch()
            batch["time"] = scan.time + offset
            self.publisher.put(batch)

    def _run_loop(self, scans: Sequence[SimulatedScan]) -> None:
        """``scans`` in a loop, each loop's times after the previous one's (and after the
        service's latest report)."""
        if not scans:
            return
        first = scans[0].time
        duration = scans[-1].time - first
        dt = scans[1].time - scans[0].time if len(scans) > 1 else 1.0
        self._next_summary = time.monotonic() + self.summary_interval
        loop = 0
        while not self._stopped():
            offset = loop * (duration + dt)
            report = latest_report(self.session, self.keys, self.query_timeout)
            last = None if report is None else report.get("time")
            if last is not None and first + offset <= last:
                offset = last + dt - first
            start_wall = time.monotonic()
            for scan in scans:
                if self._pace(start_wall + (scan.time - first) / self.speed):
                    return
                batch = scan.to_batch()
                batch["time"] = scan.time + offset
                self.publisher.put(batch)
            loop += 1

    def close(self) -> None:
        self.publisher.close()

    def _log_summary(self) -> None:
        report = latest_report(self.session, self.keys, self.query_timeout)
        if report is None:
            log.info("demo: no answer from %s", self.keys.state)
        else:
            log.info("demo: %s", summary_line(report))

    def _stopped(self) -> bool:
        if self.parent is not None and os.getppid() != self.parent:
            self._stop.set()  # the service that started us is gone
        return self._stop.is_set()

    def _pace(self, due: float) -> bool:
        """Wait until the wall time ``due``, logging the summaries that fall due meanwhile;
        True to stop."""
        while True:
            now = time.monotonic()
            if now >= self._next_summary:
                self._log_summary()
                self._next_summary = time.monotonic() + self.summary_interval
                continue
            if now >= due:
                return self._stopped()
            if self._wait(min(due, self._next_summary) - now):
                return True

    def _wait(self, seconds: float) -> bool:
        """Wait up to ``seconds`` (half a second at most, to watch the parent); True to stop."""
        self._stop.wait(max(0.0, min(seconds, 0.5)))
        return self._stopped()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m clients.demo",
        description=(
            "Publish a simulated scenario to the tracking service in real time and log a "
            "summary of its confirmed tracks every few seconds."
        ),
    )
    add_zenoh_arguments(parser)
    parser.add_argument(
        "--scenario",
        choices=SCENARIOS,
        default="continuous",
        help=(
            "continuous (default): targets born at random times, living a random while, "
            "leaving or no longer seen; reference: the 100 s reference scenario in a loop; "
            "convoy, harbour: the extended-object scenarios (a convoy in traffic, a boat "
            "entering a harbour) in a loop"
        ),
    )
    parser.add_argument("--seed", type=int, default=0, help="scenario seed (default 0)")
    parser.add_argument(
        "--sensor-id",
        default="radar-1",
        help="the continuous scenario's radar id, the last chunk of its key (default radar-1)",
    )
    parser.add_argument(
        "--centre",
        type=_point,
        default=(0.0, 0.0),
        metavar="X,Y",
        help=(
            "where the continuous scenario's radar stands, metres; its 20 km square area "
            "is around it (default 0,0; write --centre=-15000,0 for a negative x)"
        ),
    )
    parser.add_argument(
        "--speed", type=float, default=1.0, help="times real time (default 1: real time)"
    )
    parser.add_argument(
        "--summary-interval",
        type=float,
        default=5.0,
        help="seconds between the one-line track summaries (default 5)",
    )
    parser.add_argument(
        "--wait-matching",
        type=float,
        default=5.0,
        help="seconds to wait for the service's subscriber before the first batch (default 5)",
    )
    parser.add_argument(
        "--log-level",
        choices=("critical", "error", "warning", "info", "debug"),
        default="info",
    )
    parser.add_argument(
        "--exit-with-parent",
        action="store_true",
        help="stop when the process that started this one is gone (as under tracker-service)",
    )
    return parser


def _point(text: str) -> tuple[float, float]:
    """``"x,y"`` -> ``(x, y)``, finite metres."""
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in metres, got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected finite X,Y, got {text!r}")
    return x, y


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.summary_interval > 0:
        parser.error("--summary-interval: must be > 0")
    if not args.speed > 0:
        parser.error("--speed: must be > 0")
    if not re.fullmatch(r"[A-Za-z0-9_.\-]{1,64}", args.sensor_id):
        parser.error("--sensor-id: 1 to 64 of A-Z a-z 0-9 _ . -")
    logging.basicConfig(
        level=args.log_level.upper(),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    stop = threading.Event()
    parent = os.getppid() if args.exit_with_parent else None
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, frame: stop.set())
    try:
        session = session_from_args(args)
    except zenoh.ZError as exc:
        print(f"python -m clients.demo: cannot open a Zenoh session: {exc}", file=sys.stderr)
        return 1
    demo = Demo(
        session,
        Keys(args.prefix),
        stop=stop,
        seed=args.seed,
        speed=args.speed,
        summary_interval=args.summary_interval,
        wait_matching=args.wait_matching,
        parent=parent,
        scenario=args.scenario,
        sensor_id=args.sensor_id,
        centre=args.centre,
    )
    try:
        log.info(
            "demo: publishing the %s scenario to %s",
            args.scenario,
            args.connect or [DEFAULT_ENDPOINT],
        )
        demo.run()
    finally:
        demo.close()
        session.close()
    log.info("demo: stopped after %d batches", demo.published)
    return 0


if __name__ == "__main__":
    sys.exit(main())
