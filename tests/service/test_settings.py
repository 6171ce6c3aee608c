"""Settings: flags > TRACKER_* variables > settings file; clear errors for bad values."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.main import main
from service.settings import Settings, SettingsLoadError, load_settings, split_endpoints


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    import os

    for name in list(os.environ):
        if name.startswith("TRACKER_"):
            monkeypatch.delenv(name)


def test_defaults_match_the_contract() -> None:
    s = load_settings([])
    assert s.zenoh_mode == "peer"
    assert s.zenoh_listen == ["tcp/127.0.0.1:7447"]
    assert s.zenoh_connect == []
    assert s.key_prefix == "tracking"
    assert (s.http_host, s.http_port) == ("127.0.0.1", 8000)
    assert s.api_token is None and s.config_file == s.state_dir / "config.json"
    assert s.state_file is None
    assert s.max_detections_per_batch == 10000 and s.reorder_window == 0.0
    assert s.tracks_congestion_control == "block"
    assert len(s.instance_id) == 8 and s.instance_id != load_settings([]).instance_id


def test_precedence_flags_over_env_over_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "s.json"
    path.write_text(
        json.dumps({"http_port": 9001, "key_prefix": "file", "zenoh_mode": "client", "demo": True})
    )
    monkeypatch.setenv("TRACKER_SETTINGS_FILE", str(path))
    monkeypatch.setenv("TRACKER_HTTP_PORT", "9002")
    monkeypatch.setenv("TRACKER_KEY_PREFIX", "env")
    s = load_settings(["--key-prefix", "cli"])
    assert (s.http_port, s.key_prefix, s.zenoh_mode, s.demo) == (9002, "cli", "client", True)
    s = load_settings(["--no-demo"])
    assert s.demo is False and s.key_prefix == "env"


def test_toml_settings_file_with_a_tracker_table(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text(
        '[tracker]\nzenoh-connect = ["tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"]\n'
        'api_token = "secret"\nreorder_window = 0.25\n'
    )
    s = load_settings(["--settings-file", str(path)])
    assert s.zenoh_connect == ["tcp/10.0.0.1:7447", "tcp/10.0.0.2:7447"]
    assert s.api_token is not None and s.api_token.get_secret_value() == "secret"
    assert s.reorder_window == 0.25
    assert "secret" not in repr(s)


def test_endpoint_lists(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACKER_ZENOH_LISTEN", "tcp/0.0.0.0:7447, udp/0.0.0.0:7448")
    monkeypatch.setenv("TRACKER_ZENOH_CONNECT", "none")
    s = load_settings([])
    assert s.zenoh_listen == ["tcp/0.0.0.0:7447", "udp/0.0.0.0:7448"]
    assert s.zenoh_connect == []
    assert split_endpoints("") == [] and split_endpoints(None) == []
    with pytest.raises(ValueError):
        split_endpoints("localhost")


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["--zenoh-mode", "mesh"], "zenoh_mode"),
        (["--http-port", "-1"], "http_port"),
        (["--ingest-queue-size", "0"], "ingest_queue_size"),
        (["--tracks-congestion-control", "sometimes"], "tracks_congestion_control"),
        (["--instance-id", "a/b"], "instance_id"),
        (["--log-level", "loud"], "log_level"),
        (["--max-batch-bytes", "100"], "max_batch_bytes"),
        (
            ["--max-batch-bytes", str(64 << 20)],
            "TRACKER_MAX_BATCH_BYTES: must not be more than ingest_queue_bytes",
        ),
        (
            ["--max-batch-bytes", "5000000", "--zenoh-max-message-bytes", "4000000"],
            "TRACKER_MAX_BATCH_BYTES: must not be more than zenoh_max_message_bytes",
        ),
    ],
)
def test_bad_values_name_the_setting(argv: list[str], fragment: str) -> None:
    with pytest.raises(SettingsLoadError, match=fragment):
        load_settings(argv)


def test_bad_settings_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("http_port = [")
    with pytest.raises(SettingsLoadError, match=r"bad\.toml"):
        load_settings(["--settings-file", str(path)])
    path.write_text("unknown_thing = 1\n")
    with pytest.raises(SettingsLoadError, match="unknown setting"):
        load_settings(["--settings-file", str(path)])


def test_help_shows_the_real_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines anywhere
    assert "PydanticUndefined" not in text
    assert "to listen on ('none' for none) (default: tcp/127.0.0.1:7447)" in text
    assert "endpoints to connect to (default: none)" in text
    assert "(default: random)" in text and "(default: 8000)" in text


def test_main_exits_2_on_bad_settings(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--http-port", "http"]) == 2
    err = capsys.readouterr().err
    assert "tracker-service: invalid setting http_port" in err and "Traceback" not in err


def test_settings_model_is_the_one_place() -> None:
    names = set(Settings.model_fields)
    assert {
        "zenoh_mode",
        "zenoh_listen",
        "zenoh_connect",
        "key_prefix",
        "http_host",
        "http_port",
        "api_token",
        "config_file",
        "instance_id",
        "ingest_queue_size",
        "max_detections_per_batch",
        "reorder_window",
        "max_time_jump",
        "tracks_congestion_control",
        "log_level",
        "demo",
    } <= names


def test_the_cost_bounds(monkeypatch: pytest.MonkeyPatch) -> None:
    s = load_settings([])
    assert s.max_batch_bytes == 4 << 20
    assert s.ingest_queue_bytes == 32 << 20
    assert s.zenoh_max_message_bytes == 64 << 20
    monkeypatch.setenv("TRACKER_MAX_BATCH_BYTES", "65536")
    s = load_settings(["--ingest-queue-bytes", "65536"])
    assert (s.max_batch_bytes, s.ingest_queue_bytes) == (65536, 65536)


def test_state_dir_and_config_file_defaults(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    s = load_settings([])
    assert s.state_dir == tmp_path / "xdg" / "tracker-service"
    assert s.config_file == tmp_path / "xdg" / "tracker-service" / "config.json"
    monkeypatch.delenv("XDG_STATE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert load_settings([]).state_dir == tmp_path / "home" / ".local/state/tracker-service"
    s = load_settings(["--state-dir", str(tmp_path / "st")])
    assert s.config_file == tmp_path / "st" / "config.json"
    # set explicitly, it wins; 'none' turns saving off, by flag, variable or settings file
    s = load_settings(["--state-dir", str(tmp_path / "st"), "--config-file", "other.json"])
    assert s.config_file == Path("other.json")
    assert load_settings(["--config-file", "none"]).config_file is None
    monkeypatch.setenv("TRACKER_CONFIG_FILE", "None")
    assert load_settings([]).config_file is None
    monkeypatch.delenv("TRACKER_CONFIG_FILE")
    settings = tmp_path / "s.toml"
    settings.write_text('config_file = "none"\n')
    assert load_settings(["--settings-file", str(settings)]).config_file is None
    with pytest.raises(SettingsLoadError, match="must not be the config_file"):
        load_settings(["--state-dir", str(tmp_path), "--state-file", str(tmp_path / "config.json")])
