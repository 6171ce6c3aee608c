"""Scale-out over Zenoh with real processes: a ``tracker-router`` and two service instances
(west and east sectors, each its own radar's key), joined by nothing but the router.

A target crossing from the west sector into the east one keeps one id; a federated
``GET /api/v1/tracks`` on either instance returns both instances' tracks, each with its
instance; with one instance hung (SIGSTOP) or killed, the query answers within its timeout
and names it missing; a configuration change on one instance reaches the other.
"""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import orjson
import pytest
import zenoh

from tests.conftest import free_port, open_peer

from .helpers import declare_publisher, wait_until
from .test_subprocess import ServiceProcess

pytestmark = pytest.mark.timeout(120)

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "scale-out-test-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SPEED = 150.0  # m/s, the crossing target's
DT = 1.0


class Deployment:
    """A router and two instances; ``west`` holds x < 0, ``east`` x >= 0."""

    def __init__(self) -> None:
        self.router_endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.router = subprocess.Popen(
            [sys.executable, "-m", "service.router", "--listen", self.router_endpoint],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            cwd=ROOT,
        )
        self.instances: dict[str, ServiceProcess] = {}
        self.session: zenoh.Session | None = None
        self._wait_router_listening()

    def _wait_router_listening(self, timeout: float = 30.0) -> None:
        """Until the router accepts TCP connections: an instance in client mode that finds no
        router exits at once (a loaded machine starts the router in a second or more)."""
        port = int(self.router_endpoint.rsplit(":", 1)[1])
        deadline = time.monotonic() + timeout
        while True:
            if self.router.poll() is not None:
                raise AssertionError(f"router exited: {self.router.communicate()[1]!r}")
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def start_instance(self, name: str, sector: str) -> ServiceProcess:
        proc = ServiceProcess(
            "--zenoh-mode",
            "client",  # nothing but the router joins them
            "--zenoh-connect",
            self.router_endpoint,
            "--scale-out",
            "--federate",
            "--federate-timeout",
            "1.5",
            "--instance-id",
            name,
            f"--sector={sector}",
            "--detection-keys",
            f"tracking/detections/radar-{name}",
            "--api-token",
            TOKEN,
            "--config-file",
            "none",
            "--log-level",
            "info",
        )
        self.instances[name] = proc
        proc.wait_ready()
        return proc

    def close(self) -> None:
        if self.session is not None:
            self.session.close()
        for proc in self.instances.values():
            if proc.proc.poll() is None:
                proc.proc.send_signal(signal.SIGCONT)
            proc.kill()
        self.router.kill()
        self.router.communicate(timeout=5)


@pytest.fixture
def deployment() -> Iterator[Deployment]:
    d = Deployment()
    try:
        d.start_instance("west", "-100000,-100000,0,100000")
        d.start_instance("east", "0,-100000,100000,100000")
        d.session = open_peer(d.router_endpoint)
        yield d
    finally:
        d.close()


def _batch(sensor: str, t: float, points: list[tuple[float, float]]) -> bytes:
    return orjson.dumps(
        {
            "sensor_id": sensor,
            "time": t,
            "cov": [[400.0, 0.0], [0.0, 400.0]],
            "pd": 0.99,
            "clutter_density": 1e-9,
            "detections": [{"x": x, "y": y} for x, y in points],
        }
    )


def _federated(url: str, timeout: float = 10.0) -> tuple[dict, float]:
    t0 = time.monotonic()
    answer = httpx.get(url + "/api/v1/tracks", timeout=timeout)
    assert answer.status_code == 200, answer.text
    return answer.json(), time.monotonic() - t0


def _run_crossing(d: Deployment, steps: int) -> None:
    """Each radar sees a parked target in its own sector and the crossing one within 3 km
    of the boundary on its side of it (so both see it near the boundary)."""
    assert d.session is not None
    pubs = {
        name: declare_publisher(d.session, f"tracking/detections/radar-{name}")
        for name in ("west", "east")
    }
    for k in range(steps):
        t = k * DT
        x = -8000.0 + SPEED * t
        west = [(-20000.0, 5000.0)] + ([(x, 1000.0)] if x < 3000 else [])
        east = [(20000.0, -5000.0)] + ([(x, 1000.0)] if x > -3000 else [])
        pubs["west"].put(_batch("radar-west", t, west))
        pubs["east"].put(_batch("radar-east", t, east))
        time.sleep(0.05)  # the hand-over's offer and answer go between batches
    for pub in pubs.values():
        pub.undeclare()


def _crossing_track(report: dict) -> list[dict]:
    return [t for t in report["tracks"] if abs(t["position"][1] - 1000.0) < 300]


def test_crossing_target_keeps_one_id_and_federated_query_merges(deployment: Deployment) -> None:
    d = deployment
    west, east = d.instances["west"], d.instances["east"]
    steps = 100  # the target ends at x = +7 km, well inside the east sector
    _run_crossing(d, steps)
    wait_until(
        lambda: httpx.get(east.url + "/api/v1/stats").json()["batches_processed"] >= steps,
        20,
        "east to process every batch",
    )
    for url in (west.url, east.url):
        report, _ = _federated(url)
        assert report["instances"]["answered"] == ["east", "west"]
        assert report["instances"]["missing"] == []
        crossing = _crossing_track(report)
        assert len(crossing) == 1, crossing
        track = crossing[0]
        # started in the west, handed over with its id, now held by the east
        assert track["id"].startswith("west:T"), track["id"]
        assert track["instance"] == "east"
        assert track["position"][0] > 5000
        # each instance took its own radar's key only: one parked target each
        parked = sorted(
            (t["instance"], t["id"].split(":")[0], t["position"][0] > 0)
            for t in report["tracks"]
            if t not in crossing
        )
        assert parked == [("east", "east", True), ("west", "west", False)]
    # each instance alone holds its own tracks only (no federation on the local state)
    local_east = d.session.get("tracking/state/tracks/east")  # type: ignore[union-attr]
    replies = [r.ok for r in local_east if r.ok is not None]
    assert len(replies) == 1
    east_tracks = orjson.loads(replies[0].payload.to_bytes())["tracks"]
    assert sorted(t["id"].split(":")[0] for t in east_tracks) == ["east", "west"]
    one = httpx.get(west.url + f"/api/v1/tracks/{track['id']}").json()
    assert one["instance"] == "east" and one["id"] == track["id"]


def test_federated_query_names_a_hung_or_dead_instance_and_does_not_hang(
    deployment: Deployment,
) -> None:
    d = deployment
    west, east = d.instances["west"], d.instances["east"]
    _run_crossing(d, 10)
    wait_until(
        lambda: len(_federated(west.url)[0]["instances"]["answered"]) == 2, 10, "both to answer"
    )
    east.proc.send_signal(signal.SIGSTOP)  # hung: its liveliness token stays
    try:
        report, took = _federated(west.url)
        assert report["instances"]["answered"] == ["west"]
        assert report["instances"]["missing"] == ["east"]
        assert took < 1.5 + 1.0, took
        assert all(t["instance"] == "west" for t in report["tracks"])
        assert report["tracks"], "the west's own tracks are still there"
    finally:
        east.proc.send_signal(signal.SIGCONT)
    east.proc.kill()  # dead: its token goes when the router notices
    east.proc.wait(5)
    report, took = _federated(west.url)
    assert report["instances"]["answered"] == ["west"]
    assert report["instances"]["missing"] == ["east"]
    assert took < 1.5 + 1.0, took


def test_a_configuration_change_reaches_every_instance(deployment: Deployment) -> None:
    d = deployment
    west, east = d.instances["west"], d.instances["east"]
    answer = httpx.patch(
        west.url + "/api/v1/config", json={"motion": {"q_cv": 2.5}}, headers=AUTH, timeout=10
    )
    assert answer.status_code == 200, answer.text
    wait_until(
        lambda: httpx.get(east.url + "/api/v1/config").json()["motion"]["q_cv"] == 2.5,
        10,
        "the change to reach the east",
    )
    # a change over Zenoh without the deployment's token is refused
    assert d.session is not None
    d.session.put("tracking/config/intruder", orjson.dumps({"body": "{}", "mac": "00"}))
    time.sleep(0.5)
    assert httpx.get(east.url + "/api/v1/config").json()["motion"]["q_cv"] == 2.5


# -- the parts, without processes -----------------------------------------------------------


def test_seal_round_trip_and_refusals() -> None:
    from service.scale_out import SealError, seal, unseal

    data = seal({"a": [1, 2]}, b"key")
    assert unseal(data, b"key") == {"a": [1, 2]}
    with pytest.raises(SealError, match="another api_token"):
        unseal(data, b"other")
    tampered = orjson.loads(data)
    tampered["body"] = tampered["body"].replace("1", "3")
    with pytest.raises(SealError):
        unseal(orjson.dumps(tampered), b"key")
    for junk in (b"", b"[]", b'{"body": 1, "mac": "x"}', b"\xff"):
        with pytest.raises(SealError):
            unseal(junk, b"key")


def test_sector_edges_belong_to_one_side_and_margin_is_hysteresis() -> None:
    from service.scale_out import Sector

    west, east = Sector(-10.0, -10.0, 0.0, 10.0), Sector(0.0, -10.0, 10.0, 10.0)
    assert not west.contains(0.0, 0.0) and east.contains(0.0, 0.0)
    assert not west.beyond(0.4, 0.0, 0.5) and west.beyond(0.6, 0.0, 0.5)
    assert west.beyond(-5.0, 10.6, 0.5) and not west.beyond(-5.0, 5.0, 0.5)


def test_hand_over_records_are_checked() -> None:
    import numpy as np

    from service.scale_out import _state_dict, _state_of
    from trackers.peers import PointTrackState

    st = PointTrackState("w:T1", 1.0, np.arange(5.0), np.eye(5), 3.0, 4, True, 0.0, 1.0, 2)
    back = _state_of(orjson.loads(orjson.dumps(_state_dict(st))))
    assert back.id == st.id and np.array_equal(back.x, st.x) and back.hits == 4
    assert back.instants == 2
    good = _state_dict(st)
    older = {k: v for k, v in good.items() if k != "instants"}  # an instance of before
    assert _state_of(older).instants is None
    for bad, text in (
        ({**good, "instants": -1}, "instants"),
        ({**good, "instants": True}, "instants"),
        ({**good, "instants": 2.5}, "instants"),
        ({**good, "x": [1, 2]}, "5 entries"),
        ({**good, "P": (-np.eye(5)).tolist()}, "positive definite"),
        ({**good, "time": float("nan")}, "finite"),
        ({**good, "id": ""}, "id"),
        ({k: v for k, v in good.items() if k != "score"}, "missing"),
        ([], "object"),
    ):
        with pytest.raises(ValueError, match=text):
            _state_of(bad)


def test_merge_keeps_one_copy_of_a_track_two_instances_hold() -> None:
    from service.scale_out import merge_answers

    answers = {
        "west": {"tracks": [{"id": "west:T1", "updated": 10.0}, {"id": "west:T2", "updated": 9}]},
        "east": {"tracks": [{"id": "west:T1", "updated": 12.0}, {"id": "east:T1", "updated": 3}]},
    }
    merged = {t["id"]: t["instance"] for t in merge_answers(answers)}
    assert merged == {"west:T1": "east", "west:T2": "west", "east:T1": "east"}


def test_scale_out_settings() -> None:
    from service.settings import SettingsLoadError, load_settings

    s = load_settings(
        [
            "--scale-out",
            "--api-token",
            "t",
            "--instance-id",
            "west",
            "--sector=-1e4,-5e3,0,5e3",
            "--detection-keys",
            "tracking/detections/radar-1, tracking/detections/north-$*",
            "--federate",
        ]
    )
    assert s.sector == [-1e4, -5e3, 0.0, 5e3]
    assert s.detection_keys == ["tracking/detections/radar-1", "tracking/detections/north-$*"]
    for argv, text in (
        (["--federate"], "needs scale_out"),
        (["--sector=0,0,1,1"], "needs scale_out"),
        (["--scale-out", "--api-token", "t", "--sector", "1,2,3"], "four finite numbers"),
        (["--scale-out", "--api-token", "t", "--sector", "1,2,0,3"], "below xmax"),
        (["--scale-out"], "needs api_token"),
        (["--detection-keys", "other/radar-1"], "under tracking/detections/"),
        (["--detection-keys", "tracking//x"], "not a Zenoh key expression"),
        (["--detection-keys", "tracking/detections/r-1,tracking/detections/*"], "overlap"),
    ):
        with pytest.raises(SettingsLoadError, match=text):
            load_settings(argv)
