"""``tracker-follow``: print the service's tracks, once or as they change.

Examples::

    tracker-follow --rest http://127.0.0.1:8000            # the latest report, once
    tracker-follow --rest http://127.0.0.1:8000 --follow   # every new report (polling)
    tracker-follow --zenoh tcp/127.0.0.1:7447 --follow     # subscribe to {prefix}/tracks
    tracker-follow --zenoh tcp/127.0.0.1:7447 --query      # ask {prefix}/state/tracks
    tracker-follow ... --json                               # one report per line, JSON

Output is a compact table per report, or JSON lines with ``--json``. ``--status all`` adds
tentative tracks (REST and ``--query``); ``--kind`` keeps some kinds only.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import queue
import sys
import time
import urllib.parse
import urllib.request
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any, TextIO

import orjson
import zenoh

from clients.zenoh_session import open_session
from service.keys import DEFAULT_PREFIX, Keys

__all__ = ["build_parser", "format_table", "main", "rest_reports", "zenoh_reports"]


def format_table(report: dict[str, Any]) -> str:
    """A report as a header line and one row per track."""
    tracks = report.get("tracks", [])
    when = "-" if report.get("time") is None else f"{report['time']:.2f}"
    head = (
        f"seq {report.get('seq', 0)}  t={when} s  sensor {report.get('sensor_id') or '-'}  "
        f"{len(tracks)} tracks  ({report.get('processing_ms', 0.0):.2f} ms)"
    )
    if report.get("deleted"):
        head += f"  deleted {', '.join(report['deleted'])}"
    lines = [head]
    if tracks:
        lines.append(
            f"{'id':<8} {'kind':<10} {'status':<9} {'x':>10} {'y':>10} {'vx':>7} {'vy':>7} "
            f"{'speed':>6} {'score':>7} {'hits':>5}"
        )
        for t in tracks:
            (x, y), (vx, vy) = t["position"], t["velocity"]
            lines.append(
                f"{t['id']:<8} {t['kind']:<10} {t['status']:<9} {x:>10.1f} {y:>10.1f} "
                f"{vx:>7.2f} {vy:>7.2f} {math.hypot(vx, vy):>6.2f} {t['score']:>7.1f} "
                f"{t['hits']:>5}"
            )
    return "\n".join(lines)


def _filter(report: dict[str, Any], kinds: set[str] | None) -> dict[str, Any]:
    if not kinds:
        return report
    return {**report, "tracks": [t for t in report.get("tracks", []) if t["kind"] in kinds]}


def _poll(
    fetch: Callable[[], Iterable[dict[str, Any]]], *, follow: bool, interval: float
) -> Iterator[dict[str, Any]]:
    """The reports of one ``fetch()``; while following, those with a new ``seq`` of a
    ``fetch()`` every ``interval`` s."""
    last_seq: int | None = None
    while True:
        for report in fetch():
            if not follow or report.get("seq") != last_seq:
                last_seq = report.get("seq")
                yield report
        if not follow:
            return
        time.sleep(interval)


def rest_reports(
    url: str,
    *,
    status: str,
    kind: str | None,
    follow: bool,
    interval: float,
    timeout: float,
) -> Iterator[dict[str, Any]]:
    """Reports from ``GET {url}/api/v1/tracks``: once, or each new ``seq`` while following."""
    params = {"status": status}
    if kind:
        params["kind"] = kind
    full = url.rstrip("/") + "/api/v1/tracks?" + urllib.parse.urlencode(params)

    def fetch() -> Iterator[dict[str, Any]]:
        with urllib.request.urlopen(full, timeout=timeout) as resp:
            report = orjson.loads(resp.read())
        yield report

    return _poll(fetch, follow=follow, interval=interval)


def zenoh_reports(
    session: zenoh.Session,
    prefix: str,
    *,
    query: bool,
    status: str,
    kind: str | None,
    follow: bool,
    interval: float,
    timeout: float,
) -> Iterator[dict[str, Any]]:
    """Reports over Zenoh: published ones (subscriber on ``{prefix}/tracks``) or answers of
    the queryable ``{prefix}/state/tracks`` (polled every ``interval`` s while following)."""
    kinds = {k for k in (kind or "").split(",") if k} or None
    keys = Keys(prefix)
    if query:
        selector = keys.state
        params = [f"status={status}"] + ([f"kind={kind}"] if kind else [])
        selector += "?" + ";".join(params)

        def fetch() -> Iterator[dict[str, Any]]:
            got = False
            for reply in session.get(selector, timeout=timeout):
                if reply.ok is None:
                    continue
                got = True
                yield orjson.loads(reply.ok.payload.to_bytes())
            if not got and not follow:
                raise TimeoutError(f"no answer from {keys.state} in {timeout} s")

        yield from _poll(fetch, follow=follow, interval=interval)
        return
    inbox: queue.Queue[bytes] = queue.Queue(maxsize=1000)

    def on_sample(sample: zenoh.Sample) -> None:
        with contextlib.suppress(queue.Full):
            inbox.put_nowait(sample.payload.to_bytes())

    sub = session.declare_subscriber(keys.tracks, on_sample)
    try:
        first = True
        while True:
            try:
                data = inbox.get(timeout=timeout if first else None)
            except queue.Empty:
                raise TimeoutError(f"no report on {keys.tracks} in {timeout} s") from None
            first = False
            yield _filter(orjson.loads(data), kinds)
            if not follow:
                return
    finally:
        sub.undeclare()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tracker-follow", description="Print the tracking service's tracks."
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--rest", metavar="URL", help="service URL (default)")
    source.add_argument("--zenoh", metavar="ENDPOINT", help="Zenoh endpoint to connect to")
    parser.add_argument(
        "--query", action="store_true", help="with --zenoh: ask the queryable, do not subscribe"
    )
    parser.add_argument("-f", "--follow", action="store_true", help="keep printing new reports")
    parser.add_argument("--json", action="store_true", help="JSON lines instead of a table")
    parser.add_argument(
        "--status",
        choices=("confirmed", "tentative", "all"),
        default="confirmed",
        help="which tracks (REST and --query; published reports hold confirmed ones)",
    )
    parser.add_argument("--kind", help="keep these kinds (comma-separated)")
    parser.add_argument(
        "--interval", type=float, default=1.0, help="polling interval, s (REST, --query)"
    )
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for an answer")
    parser.add_argument("--count", type=int, help="stop after this many reports")
    parser.add_argument("--mode", choices=("peer", "client"), default="peer")
    parser.add_argument(
        "--prefix", default=DEFAULT_PREFIX, help=f"key prefix (default {DEFAULT_PREFIX})"
    )
    return parser


def _print_reports(
    reports: Iterator[dict[str, Any]], as_json: bool, count: int | None, out: TextIO
) -> int:
    n = 0
    for report in reports:
        if as_json:
            out.write(orjson.dumps(report).decode() + "\n")
        else:
            out.write(format_table(report) + "\n\n")
        out.flush()
        n += 1
        if count is not None and n >= count:
            break
    return n


def main(argv: Sequence[str] | None = None, out: TextIO | None = None) -> int:
    args = build_parser().parse_args(argv)
    out = out or sys.stdout
    options: dict[str, Any] = {
        "status": args.status,
        "kind": args.kind,
        "follow": args.follow,
        "interval": args.interval,
        "timeout": args.timeout,
    }
    session: zenoh.Session | None = None
    if args.zenoh:
        try:
            session = open_session(args.mode, [args.zenoh])
        except zenoh.ZError as exc:
            print(f"tracker-follow: cannot open a Zenoh session: {exc}", file=sys.stderr)
            return 1
        reports = zenoh_reports(session, args.prefix, query=args.query, **options)
    else:
        reports = rest_reports(args.rest or "http://127.0.0.1:8000", **options)
    try:
        try:
            _print_reports(reports, args.json, args.count, out)
        finally:
            if session is not None:
                session.close()
    except KeyboardInterrupt:
        return 130
    except OSError as exc:  # TimeoutError, urllib.error.URLError, ...
        print(f"tracker-follow: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
