"""The Zenoh side of the contract, in one place for the service and its clients: the key
expressions under a prefix (:class:`Keys`), the session configuration (:func:`make_config`)
and the endpoints that reach a service from the same machine (:func:`local_endpoints`).

Clients may import this module; it imports nothing else of the service.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import zenoh

__all__ = ["DEFAULT_PREFIX", "Keys", "local_endpoints", "make_config"]

DEFAULT_PREFIX = "tracking"


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

    def alive(self, instance_id: str) -> str:
        """A service instance's liveliness token; ``**`` for all of them."""
        return f"{self.prefix}/alive/{instance_id}"

    @staticmethod
    def last_chunk(key: str) -> str:
        """The sensor id of a detections or errors key."""
        return key.rsplit("/", 1)[-1]


def make_config(
    mode: str,
    listen: Sequence[str],
    connect: Sequence[str],
    *,
    config_file: Path | None = None,
    multicast_scouting: bool = False,
    shared_memory: bool = False,
) -> zenoh.Config:
    """A Zenoh config: ``mode``, endpoints, multicast scouting and the shared-memory transport
    off unless asked for.

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
