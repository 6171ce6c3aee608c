"""Shared fixtures: free ports, a real service (in-process uvicorn + real Zenoh peer) and a
second Zenoh session connected to it. Every Zenoh session is closed in a ``finally`` so pytest
never hangs on a live callback."""

from __future__ import annotations

import json
import os
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

SERVICE_TOKEN = "test-token"


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(autouse=True, scope="session")
def _no_real_state_folder(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Services the tests start (in process or as subprocesses, which inherit the
    environment) keep their default state folder under a temporary one, never the user's."""
    old = os.environ.get("XDG_STATE_HOME")
    os.environ["XDG_STATE_HOME"] = str(tmp_path_factory.mktemp("xdg-state"))
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("XDG_STATE_HOME", None)
        else:
            os.environ["XDG_STATE_HOME"] = old


@pytest.fixture(autouse=True)
def _own_state_folder(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each test's services keep their default state folder (their config file and track id
    reservation) in a folder of the test's own, so that no test sees another's ids."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("state")))


@pytest.fixture
def port() -> int:
    return free_port()


@dataclass
class RunningService:
    """A service running in this process: its URL, Zenoh endpoint, token and app."""

    url: str
    endpoint: str
    token: str
    prefix: str
    app: Any
    server: Any
    thread: threading.Thread
    state_dir: Path | None = None

    @property
    def engine(self) -> Any:
        return self.app.state.engine

    @property
    def auth(self) -> dict[str, str]:
        return {"Authorization": f"Bearer {self.token}"}

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        if self.state_dir is not None:
            shutil.rmtree(self.state_dir, ignore_errors=True)


def start_service(**overrides: Any) -> RunningService:
    """Start the real service (uvicorn in a thread, Zenoh peer on a free loopback port), with
    a state folder of its own (removed when it stops) unless ``state_dir`` is given."""
    import uvicorn

    from service.main import create_app
    from service.settings import Settings

    zport, hport = free_port(), free_port()
    own_state_dir = None if "state_dir" in overrides else Path(tempfile.mkdtemp("-tracker"))
    values: dict[str, Any] = {
        "zenoh_mode": "peer",
        "zenoh_listen": f"tcp/127.0.0.1:{zport}",
        "zenoh_connect": "none",
        "http_host": "127.0.0.1",
        "http_port": hport,
        "api_token": SERVICE_TOKEN,
        "key_prefix": "tracking",
        "log_level": "warning",
    }
    if own_state_dir is not None:
        values["state_dir"] = own_state_dir
    values.update(overrides)
    settings = Settings(**values)
    app = create_app(settings)
    config = uvicorn.Config(
        app,
        host="127.0.0.1",
        port=hport,
        log_config=None,
        log_level="warning",
        lifespan="on",
        timeout_graceful_shutdown=1,
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name=f"uvicorn-{hport}", daemon=True)
    thread.start()
    deadline = time.monotonic() + 15
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            thread.join(5)
            if own_state_dir is not None:
                shutil.rmtree(own_state_dir, ignore_errors=True)
            raise RuntimeError("the service did not start")
        time.sleep(0.01)
    return RunningService(
        url=f"http://127.0.0.1:{hport}",
        endpoint=(settings.zenoh_listen or settings.zenoh_connect)[0],
        token=SERVICE_TOKEN,
        prefix=settings.key_prefix,
        app=app,
        server=server,
        thread=thread,
        state_dir=own_state_dir,
    )


@pytest.fixture
def service_factory() -> Iterator[Callable[..., RunningService]]:
    """``service_factory(**settings)`` starts a service; all are stopped after the test."""
    started: list[RunningService] = []

    def factory(**overrides: Any) -> RunningService:
        svc = start_service(**overrides)
        started.append(svc)
        return svc

    try:
        yield factory
    finally:
        for svc in started:
            svc.stop()


@pytest.fixture
def service(service_factory: Callable[..., RunningService]) -> RunningService:
    """A fresh service with default settings."""
    return service_factory()


def open_peer(endpoint: str) -> Any:
    """A Zenoh peer session connected to ``endpoint`` (multicast scouting off)."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


@pytest.fixture
def peer(service: RunningService) -> Iterator[Any]:
    """A second Zenoh session connected to the ``service`` fixture's endpoint."""
    session = open_peer(service.endpoint)
    try:
        yield session
    finally:
        session.close()
