"""The deployment files agree with the service: every ``TRACKER_*`` variable they set is a
setting, the probes ask paths the service answers, the router configuration is one Zenoh
reads in router mode, and the image is built as the issue asks. (The tools' own checks,
hadolint, kubernetes-validate and docker-compose config, and the real image run in
``deploy/test-container.sh``.)"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
import zenoh

from service.main import create_app
from service.settings import Settings

ROOT = Path(__file__).resolve().parents[2]
DEPLOY = ROOT / "deploy"


def _documents(path: Path) -> list[dict[str, Any]]:
    return [doc for doc in yaml.safe_load_all(path.read_text()) if doc]


def _k8s() -> dict[tuple[str, str], dict[str, Any]]:
    out = {}
    for path in sorted((DEPLOY / "k8s").glob("*.yaml")):
        for doc in _documents(path):
            out[(doc["kind"], doc["metadata"]["name"])] = doc
    return out


def _setting(variable: str) -> str:
    name = variable.removeprefix("TRACKER_").lower()
    assert name in Settings.model_fields, f"{variable} is not a setting"
    return name


def test_every_tracker_variable_is_a_setting() -> None:
    texts = [
        (DEPLOY / "Dockerfile").read_text(),
        (DEPLOY / "compose.yaml").read_text(),
        *(p.read_text() for p in (DEPLOY / "k8s").glob("*.yaml")),
    ]
    variables = {v for text in texts for v in re.findall(r"\bTRACKER_[A-Z_]+\b", text)}
    assert {"TRACKER_CONTAINER", "TRACKER_API_TOKEN_FILE"} <= variables
    for variable in variables:
        _setting(variable)


def test_the_probes_ask_what_the_service_answers() -> None:
    app = create_app(Settings(config_file=None, api_token="x"))
    paths = set(app.openapi()["paths"])
    tracker = _k8s()[("Deployment", "tracker")]["spec"]["template"]["spec"]
    (container,) = tracker["containers"]
    assert container["livenessProbe"]["httpGet"]["path"] == "/health"
    assert container["readinessProbe"]["httpGet"]["path"] == "/ready"
    assert {"/health", "/ready"} <= paths
    for kind in ("requests", "limits"):
        assert {"cpu", "memory"} <= set(container["resources"][kind])
    dockerfile = (DEPLOY / "Dockerfile").read_text()
    assert "/health" in dockerfile.split("HEALTHCHECK", 1)[1].split("\n\n")[0]


def test_the_token_is_a_secret_everywhere() -> None:
    k8s = _k8s()
    spec = k8s[("Deployment", "tracker")]["spec"]["template"]["spec"]
    (container,) = spec["containers"]
    env = {e["name"]: e for e in container["env"]}
    mount = next(m for m in container["volumeMounts"] if m["name"] == "api-token")
    volume = next(v for v in spec["volumes"] if v["name"] == "api-token")
    assert volume["secret"]["secretName"] == "tracker-api-token"
    assert env["TRACKER_API_TOKEN_FILE"]["value"].startswith(mount["mountPath"] + "/")
    assert "TRACKER_API_TOKEN" not in env
    assert not any("TOKEN" in key for key in k8s[("ConfigMap", "tracker-settings")]["data"])
    assert spec["securityContext"]["runAsNonRoot"] is True

    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    assert compose["secrets"]["tracker_api_token"] == {"file": "./secrets/api-token"}
    for name in ("tracker-west", "tracker-east"):
        service = compose["services"][name]
        assert service["secrets"] == ["tracker_api_token"]
        assert service["environment"]["TRACKER_API_TOKEN_FILE"] == "/run/secrets/tracker_api_token"


def test_everything_meets_at_the_router() -> None:
    compose = yaml.safe_load((DEPLOY / "compose.yaml").read_text())
    services = compose["services"]
    assert set(services) == {
        "router",
        "tracker-west",
        "tracker-east",
        "publisher-west",
        "publisher-east",
    }
    assert services["router"]["image"].startswith("docker.io/eclipse/zenoh:")
    assert "./zenoh-router.json5:/etc/zenoh/router.json5:ro" in services["router"]["volumes"]
    sectors = {}
    for side in ("west", "east"):
        env = services[f"tracker-{side}"]["environment"]
        assert env["TRACKER_ZENOH_CONNECT"] == "tcp/router:7447"
        assert env["TRACKER_INSTANCE_ID"] == side
        assert services[f"tracker-{side}"]["build"]["dockerfile"] == "deploy/Dockerfile"
        # the settings are valid, each instance on its own radar's key and sector
        settings = Settings(
            **{_setting(k): v for k, v in env.items() if k != "TRACKER_API_TOKEN_FILE"},
            api_token="x",
            config_file=None,
        )
        assert settings.scale_out and settings.federate
        sectors[side] = settings.sector
        assert settings.detection_keys == [f"tracking/detections/radar-{side}"]
        command = services[f"publisher-{side}"]["command"]
        assert command[:3] == ["python", "-m", "clients.demo"]
        assert "tcp/router:7447" in command
        assert command[command.index("--sensor-id") + 1] == f"radar-{side}"
    assert sectors["west"][2] == sectors["east"][0] == 0.0  # they meet at x = 0
    # the settings in the ConfigMap go to the router's Service
    k8s = _k8s()
    data = k8s[("ConfigMap", "tracker-settings")]["data"]
    router = k8s[("Service", "zenoh-router")]
    port = router["spec"]["ports"][0]["port"]
    assert data["TRACKER_ZENOH_CONNECT"] == f"tcp/{router['metadata']['name']}:{port}"
    Settings(**{_setting(k): v for k, v in data.items()}, api_token="x", config_file=None)


def test_the_router_config_is_zenohs() -> None:
    conf = zenoh.Config.from_file(str(DEPLOY / "zenoh-router.json5"))
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/0.0.0.0:7447"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    # room for the tracker's largest message (zenoh_max_message_bytes)
    size = json.loads(conf.get_json("transport/link/rx/max_message_size"))
    assert size >= Settings.model_fields["zenoh_max_message_bytes"].default


@pytest.mark.parametrize(
    "needle",
    [
        "ARG BASE_IMAGE=python:3.11-slim",
        "FROM ${BASE_IMAGE}",
        "ENV PATH=/opt/tracker/bin:$PATH",
        "TRACKER_CONTAINER=1",
        "EXPOSE 8000 7447",
        "USER 10001:10001",
        'CMD ["tracker-service"]',
    ],
)
def test_the_dockerfile(needle: str) -> None:
    assert needle in (DEPLOY / "Dockerfile").read_text()


def test_the_image_gets_only_what_it_needs() -> None:
    ignored = (ROOT / ".dockerignore").read_text().split()
    assert {".git", ".venv", "test-artifacts", "**/__pycache__", "tests"} <= set(ignored)
