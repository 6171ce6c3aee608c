"""The service's entry module: the demo client's command line (the process itself runs in
``test_subprocess.py``)."""

from __future__ import annotations

import sys

from service.main import demo_command
from service.settings import Settings


def _command(**settings: object) -> list[str] | None:
    return demo_command(Settings(demo=True, **settings))  # type: ignore[arg-type]


def test_the_demo_client_reaches_the_service_from_this_machine() -> None:
    command = _command(
        zenoh_listen="tcp/0.0.0.0:7450,tcp/[::]:7451",
        key_prefix="site/a",
        demo_summary_interval=2.5,
        log_level="warning",
    )
    assert command == [
        sys.executable,
        "-m",
        "clients.demo",
        "--exit-with-parent",
        "--connect",
        "tcp/127.0.0.1:7450",
        "--connect",
        "tcp/[::1]:7451",
        "--prefix",
        "site/a",
        "--summary-interval",
        "2.5",
        "--log-level",
        "warning",
    ]


def test_a_client_service_shares_its_router_with_the_demo() -> None:
    command = _command(zenoh_mode="client", zenoh_connect="tcp/10.0.0.5:7447")
    assert command is not None and command[4:6] == ["--connect", "tcp/10.0.0.5:7447"]
    assert "tcp/127.0.0.1:7447" not in command  # a client does not listen
    command = _command(zenoh_listen="none", zenoh_connect="tcp/10.0.0.5:7447")
    assert command is not None and command[4:6] == ["--connect", "tcp/10.0.0.5:7447"]


def test_no_endpoint_no_demo() -> None:
    assert _command(zenoh_listen="none") is None
    assert _command(zenoh_mode="client", zenoh_listen="tcp/127.0.0.1:7447") is None
