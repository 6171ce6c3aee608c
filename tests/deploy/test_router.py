"""``tracker-router``: a real Zenoh router process on a free loopback port; a peer publisher
and a client subscriber that reach each other only through it; a prompt, clean stop on
SIGTERM and SIGINT; one-line errors."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from service.keys import make_config
from service.router import DEFAULT_LISTEN, router_config
from tests.conftest import free_port

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).resolve().parents[2]
ROUTER_CONFIG = ROOT / "deploy" / "zenoh-router.json5"


def _start(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "service.router", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        cwd=ROOT,
    )


def _wait_listening(proc: subprocess.Popen[str], endpoint: str, timeout: float = 15) -> None:
    """Until a client session opens on ``endpoint`` (a client fails at once with no router)."""
    deadline = time.monotonic() + timeout
    while True:
        assert proc.poll() is None, proc.communicate()[1]
        try:
            zenoh.open(make_config("client", [], [endpoint])).close()
            return
        except zenoh.ZError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)


@pytest.fixture
def stopped() -> Iterator[list[subprocess.Popen[str]]]:
    """Processes to kill if a test leaves them running."""
    procs: list[subprocess.Popen[str]] = []
    try:
        yield procs
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.communicate(timeout=10)


def _pass_a_message(endpoint: str) -> None:
    """A peer publisher and a client subscriber, each connected only to the router: a put
    reaches the subscriber."""
    got: list[bytes] = []
    arrived = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:
        got.append(sample.payload.to_bytes())
        arrived.set()

    sub_session = zenoh.open(make_config("client", [], [endpoint]))
    pub_session = zenoh.open(make_config("peer", [], [endpoint]))
    try:
        sub = sub_session.declare_subscriber("tracking/detections/**", on_sample)
        pub = pub_session.declare_publisher(
            "tracking/detections/radar-1",
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        deadline = time.monotonic() + 10
        while not pub.matching_status.matching:
            assert time.monotonic() < deadline, "the subscriber never matched through the router"
            time.sleep(0.02)
        pub.put(b'{"sensor_id": "radar-1", "time": 1.0, "detections": []}')
        assert arrived.wait(10), "nothing arrived through the router"
        assert got == [b'{"sensor_id": "radar-1", "time": 1.0, "detections": []}']
        pub.undeclare()
        sub.undeclare()
    finally:
        pub_session.close()
        sub_session.close()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_messages_pass_through_and_it_stops_promptly(
    stopped: list[subprocess.Popen[str]], sig: signal.Signals
) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = _start("--listen", endpoint)
    stopped.append(proc)
    _wait_listening(proc, endpoint)
    _pass_a_message(endpoint)

    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=10)
    took = time.monotonic() - t0
    assert proc.returncode == 0, err
    assert took < 3.0, f"took {took:.1f} s to stop"
    assert f"listening on {endpoint}" in err and "zenoh router stopped" in err


def test_the_deploy_config_file_with_endpoints_from_flags(
    stopped: list[subprocess.Popen[str]],
) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    proc = _start("--config", str(ROUTER_CONFIG), "--listen", endpoint)
    stopped.append(proc)
    _wait_listening(proc, endpoint)
    _pass_a_message(endpoint)
    proc.terminate()
    assert proc.wait(10) == 0


def test_two_routers_joined_route_between_them(stopped: list[subprocess.Popen[str]]) -> None:
    """Sites joined router to router (``--connect``): a publisher on one reaches a
    subscriber on the other."""
    a, b = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    first = _start("--listen", a)
    stopped.append(first)
    _wait_listening(first, a)
    second = _start("--listen", b, "--connect", a)
    stopped.append(second)
    _wait_listening(second, b)
    got = threading.Event()
    sub_session = zenoh.open(make_config("client", [], [a]))
    pub_session = zenoh.open(make_config("client", [], [b]))
    try:
        sub_session.declare_subscriber("tracking/tracks", lambda sample: got.set())
        pub = pub_session.declare_publisher("tracking/tracks")
        deadline = time.monotonic() + 10
        while not pub.matching_status.matching:
            assert time.monotonic() < deadline, "no match across the two routers"
            time.sleep(0.05)
        pub.put(b"{}")
        assert got.wait(10)
    finally:
        pub_session.close()
        sub_session.close()
    for proc in (second, first):
        proc.terminate()
        assert proc.wait(10) == 0


def test_a_port_in_use_is_one_line_and_status_1() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    holder = zenoh.open(make_config("router", [endpoint], []))
    try:
        proc = _start("--listen", endpoint)
        _, err = proc.communicate(timeout=20)
    finally:
        holder.close()
    assert proc.returncode == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tracker-router: cannot start the Zenoh router")


def test_bad_input_is_refused(tmp_path: Path) -> None:
    proc = _start("--listen", "localhost")
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and "must look like tcp/HOST:PORT" in err

    peer_file = tmp_path / "peer.json5"
    peer_file.write_text('{mode: "peer"}')
    proc = _start("--config", str(peer_file))
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 1
    assert "mode is 'peer'; a router needs mode 'router'" in err

    proc = _start("--config", str(tmp_path / "missing.json5"))
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 1 and "cannot start the Zenoh router" in err


def test_router_config() -> None:
    conf = router_config()
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("listen/endpoints")) == [DEFAULT_LISTEN]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    conf = router_config(config_file=ROUTER_CONFIG, connect=["tcp/10.0.0.2:7447"])
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/0.0.0.0:7447"]
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/10.0.0.2:7447"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False


def test_the_console_script_is_installed() -> None:
    """``tracker-router`` is an entry point of the package (pyproject.toml)."""
    from importlib.metadata import entry_points

    (script,) = [ep for ep in entry_points(group="console_scripts") if ep.name == "tracker-router"]
    assert script.value == "service.router:main"
