"""The Zenoh side of the contract, in one place for the service and its clients: the key
expressions under a prefix (:class:`Keys`), the session configuration (:func:`make_config`)
and the endpoints that reach a service from the same machine (:func:`local_endpoints`).

Clients may import this module; it imports nothing else of the service.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import zenoh

__all__ = ["DEFAULT_PREFIX", "Keys", "local_endpoints", "make_config"]

DEFAULT_PREFIX = "tracking"
#: A sensor id as the contract has it (``service.schemas.SENSOR_ID_PATTERN``).
_SENSOR_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


@dataclass(frozen=True)
class Keys:
    """The key expressions under ``prefix`` (see the contract's table of keys)."""

    prefix: str = DEFAULT_PREFIX

    def detections(self, sensor_id: str) -> str:
        """Where a sensor puts its batches; ``*`` or ``**`` for a subscriber."""
        return f"{self.prefix}/detections/{sensor_id}"

    @property
    def all_detections(self) -> str:
        return self.detections("**")

    @property
    def tracks(self) -> str:
        """One Track report per processed batch."""
        return f"{self.prefix}/tracks"

    def errors(self, sensor_id: str) -> str:
        """One Error report per refused batch; ``**`` for a subscriber."""
        return f"{self.prefix}/errors/{sensor_id}"

    @property
    def all_errors(self) -> str:
        return self.errors("**")

    @property
    def state(self) -> str:
        """The queryable answering with the latest Track report."""
        return f"{self.prefix}/state/tracks"

    def instance_tracks(self, instance_id: str) -> str:
        """Scale-out: one instance's Track reports (``*`` for a subscriber: every instance;
        ``{prefix}/tracks/**`` also matches ``{prefix}/tracks``)."""
        return f"{self.prefix}/tracks/{instance_id}"

    def instance_state(self, instance_id: str) -> str:
        """Scale-out: the queryable answering with one instance's latest Track report
        (``*``: every instance's; selector parameters ``status`` and ``kind``)."""
        return f"{self.prefix}/state/tracks/{instance_id}"

    def handover(self, instance_id: str) -> str:
        """Scale-out: the queryable where an instance takes tracks leaving a neighbour's
        sector (``*`` to offer them to every instance)."""
        return f"{self.prefix}/handover/{instance_id}"

    def config(self, instance_id: str) -> str:
        """Scale-out: where an instance puts a configuration change for the others (``*``
        for a subscriber)."""
        return f"{self.prefix}/config/{instance_id}"

    def alive(self, instance_id: str) -> str:
        """A service instance's liveliness token; ``**`` for all of them."""
        return f"{self.prefix}/alive/{instance_id}"

    @staticmethod
    def last_chunk(key: str) -> str:
        """The sensor id of a detections or errors key."""
        return key.rsplit("/", 1)[-1]

    def sensor_of(self, key: str) -> str | None:
        """The sensor id of a key that is exactly ``{prefix}/detections/{sensor_id}``, the id
        one chunk of 1 to 64 of ``A-Z a-z 0-9 _ . -``; ``None`` for any other key."""
        head = f"{self.prefix}/detections/"
        if not key.startswith(head):
            return None
        sensor = key[len(head) :]
        return sensor if _SENSOR_ID.match(sensor) else None


def make_config(
    mode: str,
    listen: Sequence[str],
    connect: Sequence[str],
    *,
    config_file: Path | None = None,
    multicast_scouting: bool = False,
    shared_memory: bool = False,
    max_message_size: int | None = None,
) -> zenoh.Config:
    """A Zenoh config: ``mode``, endpoints, multicast scouting and the shared-memory transport
    off unless asked for. ``max_message_size``: the largest message (bytes) the transport
    reassembles; larger ones are dropped as they arrive (Zenoh's default is 1 GiB).

    ``config_file`` (JSON5) is the starting point when given; the other arguments override it.
    A client does not listen, so ``listen`` is ignored in client mode."""
    conf = zenoh.Config.from_file(str(config_file)) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if mode != "client":
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect or not config_file:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", "true" if multicast_scouting else "false")
    conf.insert_json5("transport/shared_memory/enabled", "true" if shared_memory else "false")
    if max_message_size is not None:
        conf.insert_json5("transport/link/rx/max_message_size", str(int(max_message_size)))
    return conf


def local_endpoints(listen: Sequence[str]) -> list[str]:
    """Endpoints to reach a service listening on ``listen`` from the same machine (a wildcard
    address becomes loopback)."""
    out = []
    for ep in listen:
        proto, _, addr = ep.partition("/")
        addr = addr.replace("0.0.0.0:", "127.0.0.1:").replace("[::]:", "[::1]:")
        out.append(f"{proto}/{addr}")
    return out
