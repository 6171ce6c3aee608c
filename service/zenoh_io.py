"""The service's Zenoh side: one session, the detection subscriber, the report publishers,
the state queryable and the liveliness token.

The subscriber callback runs on a Zenoh thread and only copies the payload and hands it to
the engine (whose bounded queue may block it: back-pressure for BLOCK publishers). A sample on
a key that is not exactly ``{prefix}/detections/{sensor_id}``, or larger than
``max_payload_bytes``, is refused without being copied. The callback must stay short: Zenoh
runs a subscriber's callbacks one at a time, so one that validated a large batch would hold
back every sensor's (measured: a callback of 0.5 s delayed another session's samples by up
to 0.5 s); batches are validated by the engine's worker. Everything is undeclared and the
session closed in :meth:`ZenohIO.close`; a process that keeps a session with a callback
subscriber open never exits.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zenoh

from service.convert import dumps
from service.keys import Keys, make_config
from service.payload import too_large_detail
from service.schemas import parse_kinds

if TYPE_CHECKING:
    from service.scale_out import ScaleOut

__all__ = ["ZenohIO", "parse_selector_filters"]

log = logging.getLogger("service.zenoh")

_JSON = zenoh.Encoding.APPLICATION_JSON


_STATUSES = ("confirmed", "tentative", "all")


def parse_selector_filters(parameters: str) -> tuple[str, set[str] | None]:
    """``status=all;kind=individual,extended`` (Zenoh selector parameters) -> filters, as the
    REST query parameters of ``GET /api/v1/tracks``. Other parameters are ignored; a
    ``status`` other than ``confirmed``, ``tentative`` or ``all``, or an unknown ``kind``
    (:func:`parse_kinds`), raises ``ValueError``."""
    status = "confirmed"
    kinds: set[str] | None = None
    for part in parameters.replace("&", ";").split(";"):
        if "=" not in part:
            continue
        key, value = part.split("=", 1)
        key = key.strip()
        if key == "status":
            if value not in _STATUSES:
                raise ValueError(f"status: one of {', '.join(_STATUSES)}, got {value!r}")
            status = value
        elif key == "kind" and value:
            kinds = parse_kinds(value) or None
    return status, kinds


class ZenohIO:
    """Opens the session and wires it to an engine-like object.

    ``submit(payload, key_sensor_id, source)`` takes each received batch;
    ``report_bytes()`` gives the latest Track report for the queryable and
    ``filtered(status, kinds)`` a filtered one (selector parameters ``status``, ``kind``).
    """

    def __init__(
        self,
        *,
        mode: str,
        listen: list[str],
        connect: list[str],
        key_prefix: str,
        instance_id: str,
        submit: Callable[[bytes, str | None, str], Future[Any]],
        report_bytes: Callable[[], bytes],
        filtered: Callable[[str, set[str] | None], dict[str, Any]] | None = None,
        congestion_control: str = "block",
        config_file: Path | None = None,
        shared_memory: bool = False,
        refuse: Callable[[int, str | None, str, str], Any] | None = None,
        max_payload_bytes: int | None = None,
        max_message_bytes: int | None = None,
        detection_keys: list[str] | None = None,
        scale_out: ScaleOut | None = None,
    ) -> None:
        self.mode = mode
        self.listen = listen
        self.connect = connect
        self.keys = Keys(key_prefix)
        self.instance_id = instance_id
        self._submit = submit
        self._report_bytes = report_bytes
        self._filtered = filtered
        self._cc = (
            zenoh.CongestionControl.BLOCK
            if congestion_control == "block"
            else zenoh.CongestionControl.DROP
        )
        self._config_file = config_file
        self._shared_memory = shared_memory
        #: ``refuse(size, sensor_id, reason, detail)`` counts and reports a payload refused
        #: unread (``sensor_id`` ``None``: the key names no sensor)
        self._refuse = refuse
        self._max_payload_bytes = max_payload_bytes
        self._max_message_bytes = max_message_bytes
        #: the detection keys subscribed to (default: every sensor's)
        self.detection_keys = list(detection_keys or [self.keys.all_detections])
        #: scale-out: reports on the instance's key, its own state queryable, and the rest
        self.scale_out = scale_out
        self.tracks_key = (
            self.keys.instance_tracks(instance_id) if scale_out is not None else self.keys.tracks
        )
        self._subscribers: list[Any] = []
        self._instance_queryable: Any = None
        self._lock = threading.Lock()
        self._closed = True
        self.session: zenoh.Session | None = None
        self._queryable: Any = None
        self._token: Any = None
        self._tracks_pub: zenoh.Publisher | None = None

    # -- lifecycle --------------------------------------------------------------------------

    def build_config(self) -> zenoh.Config:
        """The session's Zenoh configuration; raises ``zenoh.ZError`` when it cannot be made
        (a ``zenoh_config_file`` missing or not JSON5, a value Zenoh refuses)."""
        return make_config(
            self.mode,
            self.listen,
            self.connect,
            config_file=self._config_file,
            shared_memory=self._shared_memory,
            max_message_size=self._max_message_bytes,
        )

    def open(self) -> None:
        """Open the session and declare everything; raises ``zenoh.ZError`` on failure (for
        example when a listen port is taken), leaving nothing open."""
        session = zenoh.open(self.build_config())
        try:
            self._tracks_pub = session.declare_publisher(
                self.tracks_key,
                encoding=_JSON,
                congestion_control=self._cc,
                reliability=zenoh.Reliability.RELIABLE,
            )
            self._queryable = session.declare_queryable(
                self.keys.state, self._answer(self.keys.state)
            )
            if self.scale_out is not None:
                key = self.keys.instance_state(self.instance_id)
                self._instance_queryable = session.declare_queryable(key, self._answer(key))
                self.scale_out.declare(session)
            self._token = session.liveliness().declare_token(self.keys.alive(self.instance_id))
            self._subscribers = [
                session.declare_subscriber(key, self._on_sample) for key in self.detection_keys
            ]
        except BaseException:
            if self.scale_out is not None:
                self.scale_out.undeclare()
            session.close()
            raise
        self.session = session
        self._closed = False
        log.info(
            "zenoh %s session %s: listen %s, connect %s; subscribed to %s",
            self.mode,
            session.zid(),
            self.listen if self.mode != "client" else [],
            self.connect,
            ", ".join(self.detection_keys),
        )

    def stop_intake(self) -> None:
        """Stop taking detection batches (undeclare the subscriber); reports still go out."""
        subs, self._subscribers = self._subscribers, []
        for sub in subs:
            try:
                sub.undeclare()
            except Exception:
                log.debug("undeclare failed", exc_info=True)

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        with self._lock:
            if self._closed or self.session is None:
                return
            self._closed = True
        session = self.session
        if self.scale_out is not None:
            self.scale_out.undeclare()
        entities = (
            *self._subscribers,
            self._queryable,
            self._instance_queryable,
            self._token,
            self._tracks_pub,
        )
        for entity in entities:
            if entity is None:
                continue
            try:
                entity.undeclare()
            except Exception:  # already gone with the session
                log.debug("undeclare failed", exc_info=True)
        try:
            session.close()
        except Exception:
            log.exception("closing the zenoh session failed")
        self._subscribers = []
        self._queryable = self._instance_queryable = self._token = self._tracks_pub = None
        log.info("zenoh session closed")

    @property
    def closed(self) -> bool:
        return self._closed

    def reach(self) -> tuple[int, int] | None:
        """The routers and peers the open session reaches now, or ``None`` when it is not
        open (or was closed under our feet)."""
        session = self.session
        if session is None or self._closed:
            return None
        try:
            return len(list(session.info.routers_zid())), len(list(session.info.peers_zid()))
        except zenoh.ZError:
            return None

    # -- callbacks (Zenoh threads: copy, hand off, return) ----------------------------------

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            key = str(sample.key_expr)
            sensor = self.keys.sensor_of(key)
            refuse = self._refuse
            if refuse is not None:
                size = len(sample.payload)
                if sensor is None:
                    detail = (
                        f"key {key!r}: a batch goes to {self.keys.detections('{sensor_id}')}, "
                        "the sensor id one chunk of 1 to 64 of A-Z a-z 0-9 _ . -"
                    )
                    refuse(size, None, "invalid_key", detail)
                    return
                limit = self._max_payload_bytes
                if limit is not None and size > limit:
                    refuse(size, sensor, "batch_too_large", too_large_detail(size, limit))
                    return
            elif sensor is None:
                log.warning("a batch on %r, which names no sensor, is ignored", key)
                return
            self._submit(sample.payload.to_bytes(), sensor, "zenoh")
        except Exception:
            log.exception("could not take a detection batch")

    def _answer(self, key: str) -> Callable[[zenoh.Query], None]:
        """The callback of the state queryable on ``key`` (answers under that key)."""
        return lambda query: self._on_query(query, key)

    def _on_query(self, query: zenoh.Query, key: str) -> None:
        try:
            params = str(query.parameters)
            if params and self._filtered is not None:
                try:
                    status, kinds = parse_selector_filters(params)
                except ValueError as exc:
                    query.reply_err(str(exc).encode(), encoding=zenoh.Encoding.TEXT_PLAIN)
                    return
                data = dumps(self._filtered(status, kinds))
            else:
                data = self._report_bytes()
            query.reply(key, data, encoding=_JSON)
        except Exception:
            log.exception("could not answer a query")
        finally:
            query.drop()

    # -- publishing (the engine's worker thread, and submitters on overload) ----------------

    def publish_tracks(self, data: bytes) -> None:
        pub = self._tracks_pub
        if self._closed or pub is None:
            return
        pub.put(data)

    def publish_error(self, sensor_id: str, data: bytes) -> None:
        session = self.session
        if self._closed or session is None:
            return
        session.put(self.keys.errors(sensor_id), data, encoding=_JSON, congestion_control=self._cc)
