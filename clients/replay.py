"""``tracker-replay FILE``: publish a JSON-lines file of detection batches over Zenoh.

Each non-blank line is one Detection batch (as ``tracker-publish --record`` writes them); it
goes to ``{prefix}/detections/{its sensor_id}`` exactly as recorded (unless
``--time-offset`` shifts the times). ``--rate realtime`` paces the puts by the batch times
(``--speed`` scales time), ``--rate max`` sends them as fast as the service takes them.
Publishers are reliable with ``CongestionControl.BLOCK``. Lines that are not JSON objects
with a string ``sensor_id`` cannot be routed and are skipped with a message.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import orjson
import zenoh

from clients.publish import UnansweredError, add_flow_arguments, pace, print_error, publish_batches
from clients.zenoh_session import (
    BatchPublisher,
    ReportCounter,
    add_zenoh_arguments,
    session_from_args,
)

__all__ = ["build_parser", "main", "read_batches"]


def read_batches(
    path: Path, time_offset: float = 0.0, warn: bool = True
) -> Iterator[tuple[float, tuple[str, bytes]]]:
    """``(time, (sensor_id, payload))`` for each routable line of ``path``."""
    last_time = -math.inf
    with path.open("rb") as fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.strip()
            if not line:
                continue
            try:
                obj = orjson.loads(line)
            except orjson.JSONDecodeError:
                obj = None
            sensor = obj.get("sensor_id") if isinstance(obj, dict) else None
            if not isinstance(sensor, str) or not sensor or "/" in sensor:
                if warn:
                    print(f"{path}:{lineno}: no usable sensor_id; skipped", file=sys.stderr)
                continue
            assert isinstance(obj, dict)
            t = obj.get("time")
            t_pace = last_time
            if isinstance(t, int | float) and not isinstance(t, bool):
                if time_offset:
                    obj["time"] = t + time_offset
                    line = orjson.dumps(obj)
                t_pace = float(obj["time"])
            if math.isfinite(t_pace):
                last_time = t_pace
            yield (last_time if math.isfinite(last_time) else 0.0), (sensor, line)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tracker-replay",
        description="Replay a JSON-lines file of detection batches over Zenoh.",
    )
    parser.add_argument("file", type=Path, help="JSON lines, one Detection batch per line")
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
    add_flow_arguments(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="print only the summary")
    add_zenoh_arguments(parser)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.speed <= 0:
        print("tracker-replay: --speed must be > 0", file=sys.stderr)
        return 2
    if not args.file.is_file():
        print(f"tracker-replay: {args.file}: no such file", file=sys.stderr)
        return 2
    try:
        session = session_from_args(args)
    except zenoh.ZError as exc:
        print(f"tracker-replay: cannot open a Zenoh session: {exc}", file=sys.stderr)
        return 1
    publisher = BatchPublisher(session, args.prefix, wait_matching=args.wait_matching)
    counter: ReportCounter | None = None
    realtime = args.rate == "realtime"

    def sent(sensor: str, payload: bytes) -> None:
        if not args.quiet and realtime:
            print(f"{sensor}: {len(payload)} bytes", flush=True)

    try:
        counter = ReportCounter(session, args.prefix, publisher.sensors, print_error)
        t0 = time.monotonic()
        items = read_batches(args.file, args.time_offset)
        publish_batches(
            publisher,
            counter,
            pace(items, realtime=realtime, speed=args.speed),
            max_in_flight=args.max_in_flight,
            answer_timeout=args.answer_timeout,
            on_sent=sent,
        )
        elapsed = time.monotonic() - t0
        print(
            f"replayed {publisher.published} batches in {elapsed:.2f} s; "
            f"{counter.answered} answered, {counter.errors} error reports",
            flush=True,
        )
        return 0
    except LookupError as exc:
        print(
            f"tracker-replay: no subscriber on {publisher.key(str(exc.args[0]))} after "
            f"{args.wait_matching} s: is the service running?",
            file=sys.stderr,
        )
        return 1
    except UnansweredError as exc:
        print(f"tracker-replay: the service did not answer: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    finally:
        publisher.close()
        if counter is not None:
            counter.close()
        session.close()


if __name__ == "__main__":
    sys.exit(main())
