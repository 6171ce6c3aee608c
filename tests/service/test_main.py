"""The service's entry module: the demo client's command line (the process itself runs in
``test_subprocess.py``)."""

from __future__ import annotations

import sys

import pytest

from clients.demo import SCENARIOS, build_parser
from service.main import demo_command
from service.settings import DEMO_SCENARIOS, Settings, load_settings


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


@pytest.mark.parametrize(
    ("argv", "scenario"),
    [
        (["--demo"], "continuous"),
        (["--demo", "convoy"], "convoy"),
        (["--demo", "harbour", "--log-level", "warning"], "harbour"),
        (["--demo-scenario", "convoy", "--demo"], "convoy"),
        (["--demo", "formation"], "formation"),
    ],
)
def test_demo_takes_a_scenario(argv: list[str], scenario: str) -> None:
    settings = load_settings(argv)
    assert settings.demo is True and settings.demo_scenario == scenario
    command = demo_command(settings)
    assert command is not None
    if scenario == "continuous":  # as before: the client's default scenario
        assert "--scenario" not in command
    else:
        assert command[command.index("--scenario") + 1] == scenario
    assert "--speed" not in command
    # the demo client takes the command line it is given
    args = build_parser().parse_args(command[3:])
    assert args.scenario == scenario and args.exit_with_parent


def test_demo_scenarios_and_speed() -> None:
    assert DEMO_SCENARIOS == SCENARIOS
    assert load_settings([]).demo is False
    assert load_settings(["--no-demo"]).demo is False
    assert Settings(demo="convoy").demo_scenario == "convoy"  # type: ignore[arg-type]
    command = demo_command(load_settings(["--demo", "convoy", "--demo-speed", "5"]))
    assert command is not None and command[-4:] == ["--scenario", "convoy", "--speed", "5.0"]
    with pytest.raises(SystemExit):
        load_settings(["--demo", "airshow"])


@pytest.mark.parametrize(("demo", "enabled"), [("formation", True), ("convoy", False)])
def test_the_formation_demo_switches_formations_on(tmp_path, demo: str, enabled: bool) -> None:
    """Formations are off by default; ``--demo formation`` shows them, so it turns them on."""
    from service.main import create_app

    settings = Settings(  # type: ignore[call-arg]
        demo=demo, state_dir=tmp_path, config_file="none", zenoh_listen="none"
    )
    app = create_app(settings)
    assert app.state.engine.tracker_config.formation.enabled is enabled


def test_the_formation_demo_publishes_paper_003s_three_radars() -> None:
    from clients.demo import looped_scans

    scans = looped_scans("formation")
    assert {s.sensor_id for s in scans[:3]} == {"radar-1", "radar-2", "radar-3"}
    assert len(scans[0].truth_ids) == 8
    times = [s.time for s in scans]
    assert times == sorted(times)
