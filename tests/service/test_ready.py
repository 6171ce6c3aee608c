"""``GET /ready``: 200 when the Zenoh session is open (and reaches a router or peer when the
service connects to one) and the tracker's worker runs; 503 naming what is not, beside the
liveness of ``/health``. The real service, a real Zenoh router on a loopback port."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
import zenoh

from service.keys import make_config
from tests.conftest import RunningService, free_port

from .helpers import wait_until

pytestmark = pytest.mark.timeout(60)


@pytest.fixture
def router() -> Iterator[tuple[str, zenoh.Session]]:
    """A Zenoh router in this process on a free loopback port: (endpoint, session)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = zenoh.open(make_config("router", [endpoint], []))
    try:
        yield endpoint, session
    finally:
        session.close()


def _ready(svc: RunningService) -> tuple[int, dict[str, Any]]:
    r = httpx.get(svc.url + "/ready", timeout=5)
    return r.status_code, r.json()


def test_ready_when_zenoh_is_open_and_the_worker_runs(service: RunningService) -> None:
    code, body = _ready(service)
    assert code == 200, body
    assert body == {
        "status": "ready",
        "zenoh": {"open": True, "connected": True, "mode": "peer", "routers": 0, "peers": 0},
        "worker": {"running": True},
    }

    # the worker stops: not ready, and /health (liveness) says so too
    service.engine.stop()
    code, body = _ready(service)
    assert code == 503
    assert body["status"] == "not_ready" and body["worker"] == {"running": False}
    assert body["zenoh"]["open"] is True
    assert body["detail"] == "the tracker worker is not running"
    assert httpx.get(service.url + "/health").status_code == 503

    # and the Zenoh session closes: both named
    service.app.state.runtime.zenoh.close()
    code, body = _ready(service)
    assert code == 503 and body["zenoh"]["open"] is False and body["zenoh"]["connected"] is False
    assert body["detail"] == ("the Zenoh session is not open; the tracker worker is not running")


def test_ready_follows_the_router_it_connects_to(
    service_factory: Callable[..., RunningService],
    router: tuple[str, zenoh.Session],
) -> None:
    endpoint, router_session = router
    svc = service_factory(zenoh_connect=endpoint)
    wait_until(lambda: _ready(svc)[0] == 200, timeout=10, what="ready through the router")
    code, body = _ready(svc)
    assert code == 200
    assert body["zenoh"] == {
        "open": True,
        "connected": True,
        "mode": "peer",
        "routers": 1,
        "peers": 0,
    }
    assert httpx.get(svc.url + "/health").status_code == 200

    # the router goes away: the service lives (/health) but is not ready
    router_session.close()
    wait_until(lambda: _ready(svc)[0] == 503, timeout=10, what="not ready without the router")
    code, body = _ready(svc)
    assert code == 503
    assert body["zenoh"]["open"] is True and body["zenoh"]["connected"] is False
    assert body["worker"] == {"running": True}
    assert body["detail"] == f"the Zenoh session reaches no router or peer (connect {endpoint})"
    assert httpx.get(svc.url + "/health").status_code == 200

    # it comes back on the same endpoint: ready again (the peer keeps trying to connect)
    again = zenoh.open(make_config("router", [endpoint], []))
    try:
        wait_until(lambda: _ready(svc)[0] == 200, timeout=20, what="ready again")
    finally:
        again.close()


def test_a_client_of_a_router_is_ready_only_while_connected(
    service_factory: Callable[..., RunningService],
    router: tuple[str, zenoh.Session],
) -> None:
    endpoint, router_session = router
    svc = service_factory(zenoh_mode="client", zenoh_connect=endpoint, zenoh_listen="none")
    code, body = _ready(svc)
    assert code == 200, body
    assert body["zenoh"]["mode"] == "client" and body["zenoh"]["routers"] == 1
    router_session.close()
    wait_until(lambda: _ready(svc)[0] == 503, timeout=10, what="not ready without the router")


def test_ready_is_in_the_openapi_document(service: RunningService) -> None:
    paths = httpx.get(service.url + "/openapi.json").json()["paths"]
    assert set(paths["/ready"]) == {"get"}
    assert {"200", "503"} <= set(paths["/ready"]["get"]["responses"])
