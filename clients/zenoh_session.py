"""Zenoh sessions for the clients.

:func:`add_zenoh_arguments` gives every client the same flags (``--connect``, ``--mode``,
``--listen``, ``--prefix``); :func:`open_session` opens a session configured as the service
configures its own (:func:`service.keys.make_config`: multicast scouting off);
:class:`BatchPublisher` puts detection batches on ``{prefix}/detections/{sensor_id}`` with one
declared, reliable, ``CongestionControl.BLOCK`` publisher per sensor, waiting for a
subscriber to match before the first put. Key expressions come from :mod:`service.keys`.

Always close the session (``with open_session(...) as session:``): a process whose session
still has a callback subscriber never exits.
"""

from __future__ import annotations

import argparse
import contextlib
import re
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import orjson
import zenoh

from service.keys import DEFAULT_PREFIX, Keys, make_config

__all__ = [
    "DEFAULT_ENDPOINT",
    "BatchPublisher",
    "ReportCounter",
    "add_zenoh_arguments",
    "open_session",
    "session_from_args",
]

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def open_session(
    mode: str = "peer",
    connect: Sequence[str] = (DEFAULT_ENDPOINT,),
    listen: Sequence[str] = (),
) -> zenoh.Session:
    """A session in ``mode`` connecting to ``connect`` (and listening on ``listen``, unless a
    client), multicast scouting off. Raises ``zenoh.ZError`` when it cannot open."""
    return zenoh.open(make_config(mode, listen, connect))


def add_zenoh_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("zenoh")
    group.add_argument(
        "-e",
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"Zenoh endpoint to connect to (repeatable; default {DEFAULT_ENDPOINT})",
    )
    group.add_argument(
        "--mode",
        choices=("peer", "client"),
        default="peer",
        help="Zenoh session mode (default peer)",
    )
    group.add_argument(
        "--listen", action="append", metavar="ENDPOINT", default=[], help="endpoint to listen on"
    )
    group.add_argument(
        "--prefix", default=DEFAULT_PREFIX, help=f"key prefix (default {DEFAULT_PREFIX})"
    )


def session_from_args(args: argparse.Namespace) -> zenoh.Session:
    connect = args.connect or [DEFAULT_ENDPOINT]
    return open_session(args.mode, connect, args.listen)


class BatchPublisher:
    """Publishes detection batches, one declared publisher per sensor key.

    ``wait_matching`` seconds are spent at most, per new sensor, waiting for a subscriber
    (the service) to match before the first put; 0 skips the wait."""

    def __init__(
        self,
        session: zenoh.Session,
        prefix: str = DEFAULT_PREFIX,
        *,
        wait_matching: float = 5.0,
        congestion_control: zenoh.CongestionControl = zenoh.CongestionControl.BLOCK,
    ) -> None:
        self.session = session
        self.keys = Keys(prefix)
        self.wait_matching = wait_matching
        self._cc = congestion_control
        self._publishers: dict[str, zenoh.Publisher] = {}
        self.published = 0
        self.unmatched: set[str] = set()
        #: the sensor ids published so far (shared with a :class:`ReportCounter`)
        self.sensors: set[str] = set()

    def key(self, sensor_id: str) -> str:
        return self.keys.detections(sensor_id)

    def publisher(self, sensor_id: str) -> zenoh.Publisher:
        pub = self._publishers.get(sensor_id)
        if pub is None:
            pub = self.session.declare_publisher(
                self.key(sensor_id),
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=self._cc,
                reliability=zenoh.Reliability.RELIABLE,
            )
            self._publishers[sensor_id] = pub
            self.sensors.add(sensor_id)
            if self.wait_matching > 0 and not wait_for_matching(pub, self.wait_matching):
                self.unmatched.add(sensor_id)
        return pub

    def put(self, batch: dict[str, Any] | bytes, sensor_id: str | None = None) -> None:
        """Publish one batch (a dict, or its JSON bytes with ``sensor_id`` given)."""
        if isinstance(batch, dict):
            sensor_id = sensor_id or str(batch["sensor_id"])
            data = orjson.dumps(batch)
        else:
            data = batch
            if sensor_id is None:
                raise ValueError("sensor_id is needed with a raw payload")
        self.publisher(sensor_id).put(data)
        self.published += 1

    def close(self) -> None:
        for pub in self._publishers.values():
            with contextlib.suppress(Exception):  # the session may be closed already
                pub.undeclare()
        self._publishers.clear()


def wait_for_matching(pub: zenoh.Publisher, timeout: float) -> bool:
    """Wait up to ``timeout`` s for a subscriber matching ``pub``; True when one does."""
    deadline = time.monotonic() + timeout
    while True:
        if pub.matching_status.matching:  # type: ignore[attr-defined]  # (stub says bool)
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)


_SENSOR_RE = re.compile(rb'"sensor_id":\s*"([^"]*)"')


class ReportCounter:
    """Counts the service's answers to our batches: one Track report (``{prefix}/tracks``) or
    one Error report (``{prefix}/errors/**``) per batch, recognised by sensor id.

    A session closed while its puts are still in flight loses them, and a fast publisher can
    have megabytes in flight; so publishers keep at most ``max_in_flight`` batches
    unanswered (:meth:`wait_in_flight`) and wait for every answer before closing
    (:meth:`wait_answered`). Error reports are passed to ``on_error`` as text."""

    def __init__(
        self,
        session: zenoh.Session,
        prefix: str,
        sensors: set[str],
        on_error: Callable[[str, str], None] | None = None,
    ) -> None:
        self.sensors = sensors
        self.answered = 0
        self.errors = 0
        self._on_error_cb = on_error
        self._cond = threading.Condition()
        keys = Keys(prefix)
        self._subs = [
            session.declare_subscriber(keys.tracks, self._on_tracks),
            session.declare_subscriber(keys.all_errors, self._on_error),
        ]

    @staticmethod
    def _sensor_of(data: bytes) -> str | None:
        m = _SENSOR_RE.search(data, 0, 512)
        if m:
            return m.group(1).decode("utf-8", "replace")
        try:
            obj = orjson.loads(data)
        except orjson.JSONDecodeError:
            return None
        sensor = obj.get("sensor_id") if isinstance(obj, dict) else None
        return sensor if isinstance(sensor, str) else None

    def _count(self, sensor: str | None) -> None:
        if sensor is not None and sensor in self.sensors:
            with self._cond:
                self.answered += 1
                self._cond.notify_all()

    def _on_tracks(self, sample: zenoh.Sample) -> None:
        self._count(self._sensor_of(sample.payload.to_bytes()))

    def _on_error(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        sensor = Keys.last_chunk(str(sample.key_expr))
        if sensor in self.sensors:
            with self._cond:
                self.errors += 1
            if self._on_error_cb is not None:
                self._on_error_cb(str(sample.key_expr), data.decode("utf-8", "replace"))
        self._count(sensor)

    def wait_answered(self, count: int, timeout: float) -> bool:
        """Wait until at least ``count`` batches are answered; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self.answered < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
        return True

    def wait_in_flight(self, published: int, max_in_flight: int, timeout: float) -> bool:
        """Wait until fewer than ``max_in_flight`` of ``published`` batches are unanswered."""
        if max_in_flight <= 0:
            return True
        return self.wait_answered(published - max_in_flight + 1, timeout)

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(Exception):
                sub.undeclare()
