"""The Zenoh side of the contract shared by the service and its clients: the key layout, the
session configuration, and the endpoints that reach a local service."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.keys import Keys, local_endpoints, make_config


def _get(conf: object, key: str) -> object:
    return json.loads(conf.get_json(key))  # type: ignore[attr-defined]


def test_defaults_peer_listening_scouting_and_shared_memory_off() -> None:
    conf = make_config("peer", ["tcp/127.0.0.1:7447"], [])
    assert _get(conf, "mode") == "peer"
    assert _get(conf, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert _get(conf, "connect/endpoints") == []
    assert _get(conf, "scouting/multicast/enabled") is False
    # the shared-memory transport kept each local publisher's pool mapped in the service
    assert _get(conf, "transport/shared_memory/enabled") is False
    assert _get(make_config("peer", [], [], shared_memory=True), "transport/shared_memory/enabled")


def test_arguments_override_the_config_file(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text(
        "{mode: 'router', listen: {endpoints: ['tcp/127.0.0.1:9']},"
        " transport: {shared_memory: {enabled: true}}, scouting: {multicast: {enabled: true}}}"
    )
    conf = make_config("client", ["tcp/127.0.0.1:7447"], ["tcp/127.0.0.1:7448"], config_file=path)
    assert _get(conf, "mode") == "client"
    assert _get(conf, "connect/endpoints") == ["tcp/127.0.0.1:7448"]
    assert _get(conf, "listen/endpoints") == ["tcp/127.0.0.1:9"]  # a client does not listen
    assert _get(conf, "transport/shared_memory/enabled") is False
    assert _get(conf, "scouting/multicast/enabled") is False


def test_the_key_layout_of_the_contract() -> None:
    keys = Keys()
    assert keys.detections("radar-1") == "tracking/detections/radar-1"
    assert keys.all_detections == "tracking/detections/**"
    assert keys.tracks == "tracking/tracks"
    assert keys.errors("radar-1") == "tracking/errors/radar-1"
    assert keys.all_errors == "tracking/errors/**"
    assert keys.state == "tracking/state/tracks"
    assert keys.alive("a1") == "tracking/alive/a1"
    site = Keys("site/a")
    assert (site.tracks, site.detections("s")) == ("site/a/tracks", "site/a/detections/s")
    assert Keys.last_chunk(site.errors("radar-7")) == "radar-7"


@pytest.mark.parametrize(
    ("listen", "expected"),
    [
        (["tcp/0.0.0.0:7447"], ["tcp/127.0.0.1:7447"]),
        (["tcp/[::]:7447", "udp/10.0.0.2:9"], ["tcp/[::1]:7447", "udp/10.0.0.2:9"]),
        ([], []),
    ],
)
def test_local_endpoints(listen: list[str], expected: list[str]) -> None:
    assert local_endpoints(listen) == expected


@pytest.mark.parametrize(
    ("key", "sensor"),
    [
        ("tracking/detections/radar-1", "radar-1"),
        ("tracking/detections/A.b_c-9", "A.b_c-9"),
        ("tracking/detections/" + "s" * 64, "s" * 64),
        ("tracking/detections/x/radar1", None),  # an extra chunk is not the sensor's key
        ("tracking/detections/radar1/x", None),
        ("tracking/detections/", None),
        ("tracking/detections/" + "s" * 65, None),
        ("tracking/detections/radar@1", None),
        ("other/detections/radar1", None),
        ("tracking/detectionsX/radar1", None),
        ("x/tracking/detections/radar1", None),
    ],
)
def test_a_sensors_key_is_exactly_prefix_detections_sensor(key: str, sensor: str | None) -> None:
    assert Keys().sensor_of(key) == sensor
    site = Keys("site/a")
    assert site.sensor_of(key.replace("tracking/", "site/a/", 1)) == sensor


def test_the_largest_message_the_transport_takes() -> None:
    assert _get(make_config("peer", [], []), "transport/link/rx/max_message_size") == 1 << 30
    conf = make_config("peer", [], [], max_message_size=64 << 20)
    assert _get(conf, "transport/link/rx/max_message_size") == 64 << 20
