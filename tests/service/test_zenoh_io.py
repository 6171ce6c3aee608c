"""The Zenoh configuration the service opens its session with, and the selector filters of
the state queryable (the session itself is exercised by the integration tests)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.zenoh_io import make_config, parse_selector_filters


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


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        ("", ("confirmed", None)),
        ("status=all", ("all", None)),
        ("status=tentative;kind=individual,extended", ("tentative", {"individual", "extended"})),
        ("kind=formation&status=confirmed", ("confirmed", {"formation"})),
        ("other=1", ("confirmed", None)),
    ],
)
def test_selector_filters(parameters: str, expected: tuple[str, set[str] | None]) -> None:
    assert parse_selector_filters(parameters) == expected


def test_selector_filters_refuse_an_unknown_status() -> None:
    with pytest.raises(ValueError, match="status: one of confirmed, tentative, all, got 'bogus'"):
        parse_selector_filters("status=bogus")
