"""``tracker-router``: a Zenoh router in a Python process, for machines with no ``zenohd``.

Sensors, tracker instances and readers join it as clients (or peers) and their samples,
queries and liveliness tokens are routed through it, as through the official router
(``zenohd``, e.g. the ``eclipse/zenoh`` image, which reads the same configuration file:
``deploy/zenoh-router.json5``). Examples::

    tracker-router                                        # listens on tcp/0.0.0.0:7447
    tracker-router --listen tcp/127.0.0.1:7447            # this machine only
    tracker-router --connect tcp/10.0.0.2:7447            # ... and joins another router
    tracker-router --config deploy/zenoh-router.json5     # a Zenoh JSON5 configuration

``--listen`` and ``--connect`` override the configuration file's endpoints; without a file,
multicast scouting is off, as everywhere in this project. Runs until SIGINT or SIGTERM, then
closes its session and exits with status 0; a configuration that cannot be used (a port in
use, a bad file) is one line on stderr and exit status 1 (2 for bad flags).
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import zenoh

from service.settings import split_endpoints

__all__ = ["DEFAULT_LISTEN", "build_parser", "main", "router_config"]

log = logging.getLogger("service.router")

PROG = "tracker-router"
#: Where the router listens without ``--listen`` or a configuration file: every interface,
#: as ``zenohd`` does, since sensors and trackers on other machines join it.
DEFAULT_LISTEN = "tcp/0.0.0.0:7447"


def router_config(
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
    config_file: Path | None = None,
) -> zenoh.Config:
    """A Zenoh config in router mode: ``config_file`` (JSON5) as the starting point when
    given, else multicast scouting off and listening on :data:`DEFAULT_LISTEN`; ``listen``
    and ``connect``, when given, replace the file's endpoints. Raises ``zenoh.ZError`` for a
    file Zenoh cannot read, ``ValueError`` for a file that sets another mode."""
    if config_file is not None:
        conf = zenoh.Config.from_file(str(config_file))
        mode = json.loads(conf.get_json("mode"))
        if mode not in (None, "router"):
            raise ValueError(f"{config_file}: mode is {mode!r}; a router needs mode 'router'")
    else:
        conf = zenoh.Config()
        conf.insert_json5("scouting/multicast/enabled", "false")
        listen = listen or [DEFAULT_LISTEN]
    conf.insert_json5("mode", '"router"')
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return conf


def _endpoints(value: str) -> list[str]:
    """An argparse type: comma-separated endpoints, each like ``tcp/HOST:PORT``."""
    try:
        return split_endpoints(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description=(
            "A Zenoh router in a Python process: sensors, tracker instances and readers "
            "connect to it and are routed through it. Runs until SIGINT or SIGTERM."
        ),
    )
    parser.add_argument(
        "-l",
        "--listen",
        action="append",
        type=_endpoints,
        metavar="ENDPOINTS",
        help=(
            "endpoint(s) to listen on, comma-separated or repeated "
            f"(default: the config file's, else {DEFAULT_LISTEN})"
        ),
    )
    parser.add_argument(
        "-e",
        "--connect",
        action="append",
        type=_endpoints,
        metavar="ENDPOINTS",
        help="other router(s) to connect to, comma-separated or repeated (default: none)",
    )
    parser.add_argument(
        "-c",
        "--config",
        type=Path,
        metavar="FILE",
        help="a Zenoh JSON5 configuration to start from (e.g. deploy/zenoh-router.json5)",
    )
    parser.add_argument(
        "--log-level",
        choices=("critical", "error", "warning", "info", "debug"),
        default="info",
    )
    return parser


def _flat(groups: list[list[str]] | None) -> list[str]:
    return [endpoint for group in groups or [] for endpoint in group]


def _shown(conf: zenoh.Config, key: str) -> str:
    """The endpoints under ``key`` (a list, or Zenoh's per-mode table), for the log."""
    value = json.loads(conf.get_json(key))
    if isinstance(value, dict):
        value = value.get("router", [])
    return ", ".join(value) if value else "nothing"


def main(argv: Sequence[str] | None = None) -> int:
    """``tracker-router``: run a Zenoh router until SIGINT or SIGTERM."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    listen, connect = _flat(args.listen), _flat(args.connect)
    stop = threading.Event()

    def _stop(signum: int, frame: Any) -> None:
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stop)
    try:
        conf = router_config(listen, connect, args.config)
        session = zenoh.open(conf)
    except (zenoh.ZError, ValueError) as exc:
        where = f" ({args.config})" if args.config is not None else ""
        print(f"{PROG}: cannot start the Zenoh router{where}: {exc}", file=sys.stderr)
        return 1
    try:
        log.info(
            "zenoh router %s: listening on %s, connecting to %s",
            session.zid(),
            _shown(conf, "listen/endpoints"),
            _shown(conf, "connect/endpoints"),
        )
        while not stop.wait(0.2):
            pass
    finally:
        session.close()
    log.info("zenoh router stopped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
