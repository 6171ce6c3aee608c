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
from collections.abc import Iterator, Sequence
from pathlib import Path

import orjson

from clients.publish import (
    add_flow_arguments,
    add_pacing_arguments,
    check_pacing,
    paced,
    run_publisher,
)
from clients.zenoh_session import add_zenoh_arguments

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


PROG = "tracker-replay"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Replay a JSON-lines file of detection batches over Zenoh.",
    )
    parser.add_argument("file", type=Path, help="JSON lines, one Detection batch per line")
    add_pacing_arguments(parser)
    add_flow_arguments(parser)
    parser.add_argument("-q", "--quiet", action="store_true", help="print only the summary")
    add_zenoh_arguments(parser)
    return parser


def _headline(published: int, elapsed: float) -> str:
    return f"replayed {published} batches in {elapsed:.2f} s"


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if not check_pacing(PROG, args):
        return 2
    if not args.file.is_file():
        print(f"{PROG}: {args.file}: no such file", file=sys.stderr)
        return 2
    items = paced(args, read_batches(args.file, args.time_offset))
    return run_publisher(PROG, args, items, _headline)


if __name__ == "__main__":
    sys.exit(main())
