"""Container mode (``TRACKER_CONTAINER``, set by the image) and the token as a secret
(``TRACKER_API_TOKEN_FILE``): all interfaces by default, no start without a token, one-line
errors; outside a container nothing changes."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from service.main import main
from service.settings import Settings, SettingsLoadError, load_settings
from tests.conftest import free_port

NO_TOKEN = "in a container (TRACKER_CONTAINER) the API token must be given as a secret"


@pytest.fixture(autouse=True)
def _clean_env(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in list(os.environ):
        if name.startswith("TRACKER_"):
            monkeypatch.delenv(name)


@pytest.fixture
def token_file(tmp_path: Path) -> Path:
    path = tmp_path / "api-token"
    path.write_text("s3cret-from-a-file\n")
    return path


def test_outside_a_container_nothing_changes() -> None:
    s = load_settings([])
    assert s.container is False and s.api_token_file is None and s.api_token is None
    assert s.http_host == "127.0.0.1" and s.zenoh_listen == ["tcp/127.0.0.1:7447"]


def test_in_a_container_all_interfaces_and_the_token_from_a_file(
    monkeypatch: pytest.MonkeyPatch, token_file: Path
) -> None:
    monkeypatch.setenv("TRACKER_CONTAINER", "1")
    monkeypatch.setenv("TRACKER_API_TOKEN_FILE", str(token_file))
    s = load_settings([])
    assert s.container is True
    assert s.http_host == "0.0.0.0" and s.zenoh_listen == ["tcp/0.0.0.0:7447"]
    assert s.api_token is not None and s.api_token.get_secret_value() == "s3cret-from-a-file"
    assert "s3cret" not in repr(s)
    # what is set explicitly stays as set
    monkeypatch.setenv("TRACKER_ZENOH_LISTEN", "tcp/0.0.0.0:17447")
    s = load_settings(["--http-host", "127.0.0.1"])
    assert s.http_host == "127.0.0.1" and s.zenoh_listen == ["tcp/0.0.0.0:17447"]
    assert load_settings(["--zenoh-listen", "none"]).zenoh_listen == []
    # --no-container beats the image's variable
    assert load_settings(["--no-container"]).http_host == "127.0.0.1"


def test_in_a_container_the_variable_will_do(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TRACKER_API_TOKEN", "from-the-environment")
    s = load_settings(["--container"])
    assert s.api_token is not None and s.api_token.get_secret_value() == "from-the-environment"


@pytest.mark.parametrize("argv", [["--container"], ["--container", "--api-token", "  "]])
def test_in_a_container_no_token_no_start(argv: list[str]) -> None:
    with pytest.raises(SettingsLoadError) as exc:
        load_settings(argv)
    assert str(exc.value).startswith(NO_TOKEN) and "\n" not in str(exc.value)
    # Settings built directly (as create_app takes them) refuse too: never a generated token
    with pytest.raises(ValueError, match="must be given as a secret"):
        Settings(container=True)


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        (None, "cannot read"),
        ("", "is empty"),
        ("  \n\n", "is empty"),
        ("two words\n", "must be one word, one line"),
        ("line1\nline2\n", "must be one word, one line"),
        (b"\xff\xfe", "is not UTF-8 text"),
    ],
)
def test_bad_token_files_are_named(
    tmp_path: Path, content: str | bytes | None, fragment: str
) -> None:
    path = tmp_path / "token"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    with pytest.raises(SettingsLoadError) as exc:
        load_settings(["--container", "--api-token-file", str(path)])
    message = str(exc.value)
    assert message.startswith("invalid setting api_token_file / TRACKER_API_TOKEN_FILE: ")
    assert fragment in message and str(path) in message and "\n" not in message


def test_a_token_file_and_a_token_are_one_too_many(token_file: Path) -> None:
    with pytest.raises(SettingsLoadError, match="set api_token_file or api_token, not both"):
        load_settings(["--api-token", "x", "--api-token-file", str(token_file)])


def test_main_refuses_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--container", "--http-port", str(free_port())]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert lines == [f"tracker-service: {lines[0].removeprefix('tracker-service: ')}"]
    assert NO_TOKEN in lines[0] and "Traceback" not in captured.err


def test_the_service_takes_its_token_from_the_file(token_file: Path, tmp_path: Path) -> None:
    """A real process in container mode (on loopback here): writes need the file's token,
    and the start-up line names the file, not the token."""
    hport, zport = free_port(), free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKER_")}
    env.update(
        TRACKER_CONTAINER="1",
        TRACKER_API_TOKEN_FILE=str(token_file),
        TRACKER_HTTP_HOST="127.0.0.1",
        TRACKER_HTTP_PORT=str(hport),
        TRACKER_ZENOH_LISTEN=f"tcp/127.0.0.1:{zport}",
        TRACKER_STATE_DIR=str(tmp_path / "state"),
        TRACKER_LOG_LEVEL="warning",
    )
    proc = subprocess.Popen(
        [sys.executable, "-m", "service"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
    )
    url = f"http://127.0.0.1:{hport}"
    try:
        for _ in range(300):
            try:
                if httpx.get(url + "/ready", timeout=1).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert proc.poll() is None, proc.communicate()[1].decode()
            time.sleep(0.05)
        else:
            pytest.fail("the service did not become ready")
        assert httpx.patch(url + "/api/v1/config", json={}).status_code == 401
        auth = {"Authorization": "Bearer s3cret-from-a-file"}
        assert httpx.patch(url + "/api/v1/config", json={}, headers=auth).status_code == 200
    finally:
        proc.terminate()
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0
    text = (out + err).decode()
    assert f"the token for writes comes from the file {token_file}" in text
    assert "s3cret" not in text
