"""``tracker-publish``: simulate a scenario and publish its detection batches over Zenoh.

Examples::

    tracker-publish                                  # reference scenario, real time
    tracker-publish --rate max --scans 100           # as fast as the service takes them
    tracker-publish --scenario scale --targets 500 --clutter 200 --rate max
    tracker-publish --record run.jsonl               # also write the batches, one per line

Batches go to ``{prefix}/detections/{sensor_id}`` through reliable publishers with
``CongestionControl.BLOCK``. Before the first put of each sensor the publisher waits for the
service's subscriber to match. The service answers every batch with a Track report
(``{prefix}/tracks``) or an Error report (``{prefix}/errors/{sensor_id}``, printed to
stderr); the publisher keeps at most ``--max-in-flight`` batches unanswered and waits for
every answer before it exits, so a fast publisher neither piles megabytes into the network
buffers nor loses the batches still in flight when its session closes.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import IO, Any, TypeVar

import orjson
import zenoh

from clients.scenarios.airspace import (
    ScriptedScenario,
    formation_scenario,
    manoeuvre_scenario,
    mixed_speed_scenario,
    simulate_scripted,
)
from clients.scenarios.multitarget import (
    ScenarioConfig,
    SimulatedScan,
    crossing_scenario,
    reference_scenario,
    scale_scenario,
    simulate,
)
from clients.zenoh_session import (
    BatchPublisher,
    ReportCounter,
    add_zenoh_arguments,
    session_from_args,
)

__all__ = [
    "UnansweredError",
    "add_flow_arguments",
    "add_pacing_arguments",
    "build_parser",
    "check_pacing",
    "main",
    "pace",
    "paced",
    "publish_batches",
    "run_publisher",
    "scenario_config",
    "simulated_scans",
]

T = TypeVar("T")


_SCENARIOS: dict[str, Callable[..., ScenarioConfig]] = {
    "scale": scale_scenario,
    "crossing": crossing_scenario,
}


#: Scripted scenarios with range-bearing radars (clients.scenarios.airspace): targets of every
#: speed. --targets, --scans and --clutter do not apply to them.
_SCRIPTED: dict[str, Callable[[int], ScriptedScenario]] = {
    "mixed-speeds": lambda seed: mixed_speed_scenario(period=4.0, seed=seed),
    "formations": lambda seed: formation_scenario(seed=seed),
    "manoeuvre": lambda seed: manoeuvre_scenario(seed=seed),
}


def simulated_scans(args: argparse.Namespace) -> list[SimulatedScan]:
    """The scans of the scenario the flags describe. Raises ``ValueError`` for a flag that
    does not apply to it."""
    make = _SCRIPTED.get(args.scenario)
    if make is None:
        return simulate(scenario_config(args))
    given = [f"--{n}" for n in ("targets", "scans", "clutter") if getattr(args, n) is not None]
    if given:
        raise ValueError(f"{', '.join(given)}: not for the scripted scenario {args.scenario}")
    return simulate_scripted(make(args.seed))


def scenario_config(args: argparse.Namespace) -> ScenarioConfig:
    """The scenario the flags describe."""
    changes: dict[str, Any] = {}
    if args.targets is not None:
        changes["n_targets"] = args.targets
    if args.scans is not None:
        changes["n_scans"] = args.scans
    make = _SCENARIOS.get(args.scenario)
    if make is None:  # reference: --clutter does not apply
        config = reference_scenario(args.seed)
        return replace(config, **changes) if changes else config
    if args.clutter is not None:
        changes["clutter_mean"] = args.clutter
    return make(seed=args.seed, **changes)


def pace(
    items: Iterable[tuple[float, T]],
    *,
    realtime: bool,
    speed: float = 1.0,
    stop: threading.Event | None = None,
) -> Iterable[T]:
    """Yield each ``(time, item)``'s item; in real time, not before ``(time - first) / speed``
    seconds of wall time have passed since the first."""
    start_wall: float | None = None
    first = 0.0
    for t, item in items:
        if realtime:
            if start_wall is None:
                start_wall, first = time.monotonic(), t
            delay = start_wall + (t - first) / speed - time.monotonic()
            if delay > 0:
                if stop is not None:
                    if stop.wait(delay):
                        return
                else:
                    time.sleep(delay)
        if stop is not None and stop.is_set():
            return
        yield item


class UnansweredError(Exception):
    """The service stopped answering (no Track or Error report for our batches)."""


def publish_batches(
    publisher: BatchPublisher,
    counter: ReportCounter,
    items: Iterable[tuple[str, bytes]],
    *,
    max_in_flight: int,
    answer_timeout: float,
    on_sent: Callable[[str, bytes], None] | None = None,
) -> None:
    """Put each ``(sensor_id, payload)``, keeping at most ``max_in_flight`` batches
    unanswered; then wait for every answer. Raises :class:`UnansweredError` after
    ``answer_timeout`` seconds without progress, and ``LookupError`` when no subscriber
    matches a sensor's key."""
    for sensor, payload in items:
        publisher.publisher(sensor)
        if sensor in publisher.unmatched:
            raise LookupError(sensor)
        if not counter.wait_in_flight(publisher.published, max_in_flight, answer_timeout):
            raise UnansweredError(
                f"{publisher.published - counter.answered} batches unanswered for "
                f"{answer_timeout} s"
            )
        publisher.put(payload, sensor)
        if on_sent is not None:
            on_sent(sensor, payload)
    if not counter.wait_answered(publisher.published, answer_timeout):
        raise UnansweredError(
            f"{publisher.published - counter.answered} of {publisher.published} batches "
            f"unanswered after {answer_timeout} s"
        )


def print_error(key: str, text: str) -> None:
    print(f"error report on {key}: {text}", file=sys.stderr, flush=True)


def add_flow_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--max-in-flight",
        type=int,
        default=64,
        metavar="N",
        help="batches sent but not yet answered by a report, at most (0: no limit; default 64)",
    )
    parser.add_argument(
        "--answer-timeout",
        type=float,
        default=30.0,
        metavar="S",
        help="seconds to wait for the service's reports before giving up (default 30)",
    )
    parser.add_argument(
        "--wait-matching",
        type=float,
        default=10.0,
        metavar="S",
        help="seconds to wait for the service's subscriber (0: do not wait; default 10)",
    )


def add_pacing_arguments(parser: argparse.ArgumentParser) -> None:
    """``--rate``, ``--speed`` and ``--time-offset`` (see :func:`paced`)."""
    parser.add_argument(
        "--rate",
        choices=("realtime", "max"),
        default="realtime",
        help="realtime: batch times pace the puts; max: as fast as the service takes them",
    )
    parser.add_argument("--speed", type=float, default=1.0, help="real-time speed-up factor")
    parser.add_argument(
        "--time-offset", type=float, default=0.0, help="seconds added to every batch time"
    )


def check_pacing(prog: str, args: argparse.Namespace) -> bool:
    """False, after saying why on stderr, when the pacing flags cannot be used."""
    if args.speed <= 0:
        print(f"{prog}: --speed must be > 0", file=sys.stderr)
        return False
    return True


def paced(args: argparse.Namespace, items: Iterable[tuple[float, T]]) -> Iterable[T]:
    """:func:`pace` as the flags of :func:`add_pacing_arguments` ask."""
    return pace(items, realtime=args.rate == "realtime", speed=args.speed)


def run_publisher(
    prog: str,
    args: argparse.Namespace,
    items: Iterable[tuple[str, bytes]],
    headline: Callable[[int, float], str],
    *,
    record: Path | None = None,
) -> int:
    """Open a session from the flags, :func:`publish_batches` ``items`` (already paced) and
    print a summary, ``headline(published, elapsed)`` followed by the answer counts. Errors
    are printed as ``{prog}: ...``; returns the exit code. ``record`` also gets every
    payload sent, one per line."""
    try:
        session = session_from_args(args)
    except zenoh.ZError as exc:
        print(f"{prog}: cannot open a Zenoh session: {exc}", file=sys.stderr)
        return 1
    out: IO[bytes] | None = None
    counter: ReportCounter | None = None
    publisher = BatchPublisher(session, args.prefix, wait_matching=args.wait_matching)
    realtime = args.rate == "realtime"

    def sent(sensor: str, payload: bytes) -> None:
        if out is not None:
            out.write(payload + b"\n")
        if not args.quiet and realtime:
            print(f"{sensor}: {len(payload)} bytes", flush=True)

    try:
        counter = ReportCounter(session, args.prefix, publisher.sensors, print_error)
        if record is not None:
            out = record.open("wb")
        t0 = time.monotonic()
        publish_batches(
            publisher,
            counter,
            items,
            max_in_flight=args.max_in_flight,
            answer_timeout=args.answer_timeout,
            on_sent=sent,
        )
        elapsed = time.monotonic() - t0
        print(
            f"{headline(publisher.published, elapsed)}; "
            f"{counter.answered} answered, {counter.errors} error reports",
            flush=True,
        )
        return 0
    except LookupError as exc:
        print(
            f"{prog}: no subscriber on {publisher.key(str(exc.args[0]))} after "
            f"{args.wait_matching} s: is the service running?",
            file=sys.stderr,
        )
        return 1
    except UnansweredError as exc:
        print(f"{prog}: the service did not answer: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        if out is not None:
            out.close()
        publisher.close()
        if counter is not None:
            counter.close()
        session.close()


PROG = "tracker-publish"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Simulate a scenario and publish its detection batches over Zenoh.",
    )
    parser.add_argument(
        "--scenario",
        choices=("reference", "scale", "crossing", *_SCRIPTED),
        default="reference",
        help=(
            "which simulated scenario (default reference: 50 targets, 100 scans at 1 s; "
            "mixed-speeds: parked cars to 680 m/s jets, one radar at 4 s; formations: paper "
            "003's two formations, three radars; manoeuvre: 450 m/s pulling 4 g)"
        ),
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--scans", type=int, help="number of scans per sensor")
    parser.add_argument("--targets", type=int, help="number of targets")
    parser.add_argument("--clutter", type=float, help="mean false alarms per scan (scale)")
    add_pacing_arguments(parser)
    parser.add_argument("--record", type=Path, metavar="FILE", help="also write JSON lines")
    add_flow_arguments(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="print only the summary")
    add_zenoh_arguments(parser)
    return parser


def _headline(published: int, elapsed: float) -> str:
    rate = published / elapsed if elapsed > 0 else float("inf")
    return f"published {published} batches in {elapsed:.2f} s ({rate:.0f} batches/s)"


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not check_pacing(PROG, args):
        return 2
    try:
        scans = simulated_scans(args)
    except ValueError as exc:
        print(f"{PROG}: {exc}", file=sys.stderr)
        return 2

    def items() -> Iterator[tuple[str, bytes]]:
        batches = ((s.time + args.time_offset, s) for s in scans)
        for scan in paced(args, batches):
            batch = scan.to_batch()
            batch["time"] = scan.time + args.time_offset
            yield scan.sensor_id, orjson.dumps(batch)

    return run_publisher(PROG, args, items(), _headline, record=args.record)


if __name__ == "__main__":
    sys.exit(main())
