"""The service's settings: one :class:`Settings`, from CLI flags > ``TRACKER_*`` variables >
a settings file (JSON or TOML, named by ``--settings-file`` or ``TRACKER_SETTINGS_FILE``).

:func:`load_settings` parses the command line and builds the settings; it raises
:class:`SettingsLoadError` with a readable message on any bad value, which the entry point
turns into exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import secrets
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import zenoh
from pydantic import (
    Field,
    SecretStr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic_settings import (
    BaseSettings,
    NoDecode,
    PydanticBaseSettingsSource,
    SettingsConfigDict,
)

from service.keys import DEFAULT_PREFIX
from service.payload import DEFAULT_MAX_BATCH_BYTES, DEFAULT_QUEUE_BYTES
from service.schemas import MAX_REORDER_WINDOW, IngestConfig

__all__ = [
    "CONTAINER_HTTP_HOST",
    "CONTAINER_ZENOH_LISTEN",
    "DEFAULT_CONFIG_NAME",
    "DEMO_SCENARIOS",
    "Settings",
    "SettingsLoadError",
    "api_token_source",
    "build_parser",
    "default_state_dir",
    "load_settings",
    "read_token_file",
    "split_endpoints",
]

#: The config file's name in ``state_dir`` when ``config_file`` is not set.
DEFAULT_CONFIG_NAME = "config.json"

#: The demo client's scenarios (``python -m clients.demo --scenario``): ``--demo`` alone runs
#: the first, ``--demo convoy`` the one named.
DEMO_SCENARIOS = ("continuous", "reference", "convoy", "harbour", "formation")

#: Where the service listens in a container (``container``) unless told otherwise: every
#: interface, so the ports the container publishes reach it.
CONTAINER_HTTP_HOST = "0.0.0.0"
CONTAINER_ZENOH_LISTEN = "tcp/0.0.0.0:7447"

_INGEST = IngestConfig.model_fields
_KEY_PREFIX_RE = re.compile(r"^[^/*$#?\s]+(/[^/*$#?\s]+)*$")
_INSTANCE_RE = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


def default_state_dir() -> Path:
    """``$XDG_STATE_HOME/tracker-service`` when that variable is set (an absolute path), else
    ``~/.local/state/tracker-service``."""
    xdg = os.environ.get("XDG_STATE_HOME", "").strip()
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".local" / "state"
    return base / "tracker-service"


def split_endpoints(value: Any) -> list[str]:
    """``"a,b"`` or ``["a", "b"]`` -> ``["a", "b"]``; ``""``, ``"none"`` or ``None`` -> ``[]``."""
    if value is None:
        return []
    if isinstance(value, str):
        if value.strip().lower() in ("", "none"):
            return []
        items = value.split(",")
    elif isinstance(value, list | tuple):
        items = list(value)
    else:
        raise ValueError("expected a comma-separated string or a list of endpoints")
    out = []
    for item in items:
        if not isinstance(item, str):
            raise ValueError(f"endpoint {item!r} is not a string")
        item = item.strip()
        if not item:
            continue
        if "/" not in item:
            raise ValueError(f"endpoint {item!r} must look like tcp/HOST:PORT")
        out.append(item)
    return out


class Settings(BaseSettings):
    """Everything the service can be told at start-up (all also as ``TRACKER_<NAME>``)."""

    model_config = SettingsConfigDict(
        env_prefix="TRACKER_", extra="forbid", validate_default=True, case_sensitive=False
    )

    settings_file: Path | None = Field(
        default=None, description="JSON or TOML file with settings (lowest precedence)"
    )
    zenoh_mode: Literal["peer", "client", "router"] = Field(
        default="peer", description="Zenoh mode"
    )
    zenoh_listen: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["tcp/127.0.0.1:7447"],
        description="comma-separated Zenoh endpoints to listen on ('none' for none)",
    )
    zenoh_connect: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="comma-separated Zenoh endpoints to connect to"
    )
    zenoh_config_file: Path | None = Field(
        default=None,
        description="a Zenoh JSON5 config file to start from (mode/endpoints override it)",
    )
    zenoh_shared_memory: bool = Field(
        default=False,
        description=(
            "Zenoh's shared-memory transport with peers on this host (off by default: the "
            "service kept each local publisher's 16 MB pool mapped after it left, ~20 MB of "
            "memory per publisher run)"
        ),
    )
    zenoh_max_message_bytes: int = Field(
        default=64 * 1024 * 1024,
        ge=1024,
        description=(
            "largest Zenoh message the service's transport reassembles, bytes; a larger one "
            "is dropped by Zenoh as it arrives, with no Error report (at least max_batch_bytes)"
        ),
    )
    key_prefix: str = Field(
        default=DEFAULT_PREFIX, description="first chunk(s) of every key expression"
    )
    instance_id: str = Field(
        default_factory=lambda: secrets.token_hex(4),
        description="this instance's id in {prefix}/alive/{instance_id}",
    )
    detection_keys: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description=(
            "comma-separated Zenoh key expressions of the detection batches this instance "
            "takes, each under {prefix}/detections/ (for example "
            "tracking/detections/radar-west or tracking/detections/north-$*); "
            "default: every sensor's, {prefix}/detections/**"
        ),
    )
    scale_out: bool = Field(
        default=False,
        description=(
            "one of several instances sharing the work: track ids qualified by instance_id "
            "('west:T12'), reports on {prefix}/tracks/{instance_id}, a queryable on "
            "{prefix}/state/tracks/{instance_id}, configuration changes shared with every "
            "instance that has the same api_token, tracks handed over between sectors"
        ),
    )
    sector: Annotated[list[float] | None, NoDecode] = Field(
        default=None,
        description=(
            "scale-out: this instance's area, 'xmin,ymin,xmax,ymax' in metres; a confirmed "
            "individual track more than sector_margin beyond it is handed over to the "
            "instance whose sector holds it (none: no hand-over)"
        ),
    )
    sector_margin: float = Field(
        default=500.0,
        ge=0,
        allow_inf_nan=False,
        description="scale-out: metres beyond its sector a track goes before it is handed over",
    )
    federate: bool = Field(
        default=False,
        description=(
            "GET /api/v1/tracks gathers every instance's tracks over Zenoh and says which "
            "instances answered (needs scale_out)"
        ),
    )
    federate_timeout: float = Field(
        default=1.0,
        gt=0,
        le=60,
        allow_inf_nan=False,
        description="seconds a federated query waits for the other instances' answers",
    )
    http_host: str = Field(default="127.0.0.1", description="REST listen address")
    http_port: int = Field(default=8000, ge=0, le=65535, description="REST port (0: any free port)")
    api_token: SecretStr | None = Field(
        default=None, description="bearer token for writes; generated and printed once when unset"
    )
    api_token_file: Path | None = Field(
        default=None,
        description=(
            "a file holding the bearer token for writes (a mounted Docker or Kubernetes "
            "secret; surrounding white space ignored); instead of api_token"
        ),
    )
    container: bool = Field(
        default=False,
        description=(
            "run as in a container (the image sets TRACKER_CONTAINER=1): listen on all "
            f"interfaces (REST {CONTAINER_HTTP_HOST}, Zenoh {CONTAINER_ZENOH_LISTEN}) unless "
            "http_host or zenoh_listen is set, and refuse to start without api_token_file "
            "or api_token"
        ),
    )
    state_dir: Path = Field(
        default_factory=lambda: default_state_dir(),
        description=(
            "folder of the service's own files (the config file by default): "
            "$XDG_STATE_HOME/tracker-service, else ~/.local/state/tracker-service"
        ),
    )
    config_file: Path | None = Field(
        default=None,
        description=(
            "tracker configuration JSON: loaded at start, saved on each change "
            "(default <state_dir>/config.json; 'none': not loaded, not saved)"
        ),
    )
    state_file: Path | None = Field(
        default=None,
        description=(
            "tracker state file (tracks, ids, two-point candidates, last time, report seq): "
            "saved atomically every state_save_interval seconds and at shutdown, restored "
            "at start when younger than state_max_age; none: every start begins with no tracks"
        ),
    )
    state_save_interval: float = Field(
        default=10.0,
        ge=0,
        le=86400,
        allow_inf_nan=False,
        description="seconds between saves of the state file (0: only at shutdown)",
    )
    state_max_age: float = Field(
        default=300.0,
        gt=0,
        allow_inf_nan=False,
        description="a state file saved longer ago than this (s, wall clock) is not restored",
    )
    ingest_queue_size: int = Field(
        default=1024, ge=1, description="batches waiting for the tracker"
    )
    ingest_put_timeout: float = Field(
        default=2.0,
        gt=0,
        le=3600,
        description="seconds a full queue may block a sender before a drop",
    )
    ingest_queue_bytes: int = Field(
        default=DEFAULT_QUEUE_BYTES,
        ge=1024,
        description=(
            "payload bytes waiting for the tracker at most; a sender waits for room as for a "
            "full queue (at least max_batch_bytes)"
        ),
    )
    max_batch_bytes: int = Field(
        default=DEFAULT_MAX_BATCH_BYTES,
        ge=1024,
        description=(
            "largest detection batch payload, bytes: a larger one is refused unread "
            "(batch_too_large); the default holds 10,000 detections with every field"
        ),
    )
    # The ingest section's defaults: written once, in service.schemas.IngestConfig.
    max_detections_per_batch: int = Field(
        default=_INGEST["max_detections_per_batch"].default,
        ge=1,
        description="default of the config's ingest.max_detections_per_batch",
    )
    reorder_window: float = Field(
        default=_INGEST["reorder_window"].default,
        ge=0,
        le=MAX_REORDER_WINDOW,
        description="default of the config's ingest.reorder_window, s",
    )
    sensor_wait: float = Field(
        default=_INGEST["sensor_wait"].default,
        ge=0,
        le=60,
        description="default of the config's ingest.sensor_wait, s",
    )
    max_time_jump: float = Field(
        default=_INGEST["max_time_jump"].default,
        gt=0,
        allow_inf_nan=False,
        description="default of the config's ingest.max_time_jump, s",
    )
    tracks_congestion_control: Literal["block", "drop"] = Field(
        default="block", description="congestion control of the outgoing track and error reports"
    )
    log_level: Literal["critical", "error", "warning", "info", "debug"] = "info"
    demo: bool = Field(
        default=False,
        description=(
            "also run the demo client (python -m clients.demo): a simulated scenario "
            "published to this service in real time, and a summary of its tracks logged; "
            "--demo SCENARIO (or a scenario's name as the value) chooses the scenario: "
            + ", ".join(DEMO_SCENARIOS)
        ),
    )
    demo_scenario: Literal["continuous", "reference", "convoy", "harbour", "formation"] = Field(
        default="continuous",
        description=(
            "the demo's scenario: continuous (targets come and go), reference (the 100 s "
            "reference scenario in a loop), convoy or harbour (extended objects, in a loop), "
            "formation (paper 003's formations and three radars, in a loop; switches "
            "formation tracking on in the running configuration, which a later change of the "
            "configuration saves to the config file with the rest)"
        ),
    )
    demo_speed: float = Field(
        default=1.0,
        gt=0,
        le=1000,
        allow_inf_nan=False,
        description="the demo's pace, times real time",
    )
    demo_summary_interval: float = Field(
        default=5.0, gt=0, description="seconds between the demo's one-line track summaries"
    )

    @model_validator(mode="before")
    @classmethod
    def _demo_scenario(cls, data: Any) -> Any:
        """``demo`` given a scenario's name (``--demo convoy``, ``TRACKER_DEMO=convoy``):
        the demo on, with that scenario."""
        if isinstance(data, dict) and isinstance(data.get("demo"), str):
            name = data["demo"].strip().lower()
            if name in DEMO_SCENARIOS:
                data = {**data, "demo": True, "demo_scenario": name}
        return data

    @field_validator("demo_scenario", mode="before")
    @classmethod
    def _lower_scenario(cls, value: Any) -> Any:
        return value.strip().lower() if isinstance(value, str) else value

    @field_validator("zenoh_listen", "zenoh_connect", mode="before")
    @classmethod
    def _split(cls, value: Any) -> list[str]:
        return split_endpoints(value)

    @field_validator("detection_keys", mode="before")
    @classmethod
    def _split_keys(cls, value: Any) -> list[str]:
        if value is None:
            return []
        if isinstance(value, str):
            value = [] if value.strip().lower() in ("", "none") else value.split(",")
        if not isinstance(value, list | tuple):
            raise ValueError("expected a comma-separated string or a list of key expressions")
        return [str(v).strip() for v in value if str(v).strip()]

    @field_validator("sector", mode="before")
    @classmethod
    def _split_sector(cls, value: Any) -> Any:
        if isinstance(value, str):
            if value.strip().lower() in ("", "none"):
                return None
            return [v.strip() for v in value.split(",")]
        return value

    @field_validator("sector")
    @classmethod
    def _check_sector(cls, value: list[float] | None) -> list[float] | None:
        if value is None:
            return None
        if len(value) != 4 or not all(math.isfinite(v) for v in value):
            raise ValueError("must be four finite numbers: xmin,ymin,xmax,ymax")
        xmin, ymin, xmax, ymax = value
        if not (xmin < xmax and ymin < ymax):
            raise ValueError("xmin must be below xmax and ymin below ymax")
        return value

    @model_validator(mode="after")
    def _scale_out(self) -> Settings:
        """Detection keys under the prefix's detections; what needs scale_out has it."""
        head = f"{self.key_prefix}/detections/**"
        for key in self.detection_keys:
            if not detection_key_ok(key, head):
                raise ValueError(
                    _setting_error(
                        "detection_keys",
                        f"{key!r} is not a Zenoh key expression under {head}",
                    )
                )
        keys = self.detection_keys
        for i, a in enumerate(keys):
            for b in keys[i + 1 :]:
                if zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)):
                    raise ValueError(
                        _setting_error(
                            "detection_keys",
                            f"{a!r} and {b!r} overlap: a batch on both would come twice",
                        )
                    )
        if self.scale_out and self.api_token is None and self.api_token_file is None:
            raise ValueError(
                _setting_error(
                    "scale_out",
                    "needs api_token or api_token_file: the instances seal what they send "
                    "each other with the token they share (a generated one differs each start)",
                )
            )
        for name in ("federate", "sector"):
            if getattr(self, name) not in (None, False) and not self.scale_out:
                raise ValueError(
                    _setting_error(name, "needs scale_out (track ids qualified by the instance_id)")
                )
        return self

    @field_validator("log_level", "zenoh_mode", "tracks_congestion_control", mode="before")
    @classmethod
    def _lower(cls, value: Any) -> Any:
        return value.strip().lower() if isinstance(value, str) else value

    @field_validator("key_prefix")
    @classmethod
    def _check_prefix(cls, value: str) -> str:
        if not _KEY_PREFIX_RE.match(value):
            raise ValueError("must be one or more '/'-separated chunks without * $ # ? or spaces")
        return value

    @field_validator("instance_id")
    @classmethod
    def _check_instance(cls, value: str) -> str:
        if not _INSTANCE_RE.match(value):
            raise ValueError("must be 1 to 64 of A-Z a-z 0-9 _ . -")
        return value

    @field_validator("config_file", "state_file", mode="before")
    @classmethod
    def _none_path(cls, value: Any) -> Any:
        if isinstance(value, str) and value.strip().lower() in ("", "none"):
            return None
        return value

    @model_validator(mode="after")
    def _default_config_file(self) -> Settings:
        """``config_file`` left unset is ``<state_dir>/config.json`` (set to none: no file)."""
        if "config_file" not in self.model_fields_set and self.config_file is None:
            self.config_file = self.state_dir / DEFAULT_CONFIG_NAME
        config, state = self.config_file, self.state_file
        if config is not None and state is not None and state.resolve() == config.resolve():
            raise ValueError("state_file: must not be the config_file")
        return self

    @field_validator("api_token")
    @classmethod
    def _check_token(cls, value: SecretStr | None) -> SecretStr | None:
        if value is not None and not value.get_secret_value().strip():
            return None
        return value

    @field_validator("api_token_file", mode="before")
    @classmethod
    def _none_token_file(cls, value: Any) -> Any:
        if isinstance(value, str) and value.strip().lower() in ("", "none"):
            return None
        return value

    @model_validator(mode="after")
    def _token_and_container(self) -> Settings:
        """Read ``api_token_file``; in a container, listen on all interfaces unless told
        otherwise and insist on a token given as a secret (never a generated one)."""
        if self.api_token_file is not None:
            if self.api_token is not None:
                raise ValueError(
                    _setting_error("api_token_file", "set api_token_file or api_token, not both")
                )
            self.api_token = SecretStr(read_token_file(self.api_token_file))
        if self.container:
            if "http_host" not in self.model_fields_set:
                self.http_host = CONTAINER_HTTP_HOST
            if "zenoh_listen" not in self.model_fields_set:
                self.zenoh_listen = [CONTAINER_ZENOH_LISTEN]
            if self.api_token is None:
                raise ValueError(
                    "in a container (TRACKER_CONTAINER) the API token must be given as a "
                    "secret: set TRACKER_API_TOKEN_FILE to a file that holds it (a mounted "
                    "Docker or Kubernetes secret) or TRACKER_API_TOKEN; not starting"
                )
        return self

    @field_validator("max_batch_bytes")
    @classmethod
    def _check_batch_bytes(cls, value: int, info: ValidationInfo) -> int:
        for name in ("zenoh_max_message_bytes", "ingest_queue_bytes"):
            other = info.data.get(name)
            if isinstance(other, int) and value > other:
                raise ValueError(f"must not be more than {name} ({other})")
        return value

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        return (init_settings, env_settings, SettingsFileSource(settings_cls))


def detection_key_ok(key: str, head: str) -> bool:
    """Whether ``key`` is a Zenoh key expression that ``head`` (``{prefix}/detections/**``)
    includes."""
    try:
        return bool(zenoh.KeyExpr(head).includes(zenoh.KeyExpr(key)))
    except zenoh.ZError:
        return False


def _setting_error(name: str, message: str) -> str:
    """An error about one setting, worded as :func:`_describe` words a field's."""
    return f"invalid setting {name} / TRACKER_{name.upper()}: {message}"


def read_token_file(path: Path) -> str:
    """The token in ``path``, white space around it removed. Raises ``ValueError`` (naming
    the setting) when the file cannot be read, is not text, is empty or holds more than one
    line."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ValueError(
            _setting_error("api_token_file", f"cannot read {path}: {exc.strerror or exc}")
        ) from None
    except UnicodeDecodeError:
        raise ValueError(_setting_error("api_token_file", f"{path} is not UTF-8 text")) from None
    token = text.strip()
    if not token:
        raise ValueError(_setting_error("api_token_file", f"{path} is empty"))
    if any(c.isspace() for c in token):
        raise ValueError(
            _setting_error("api_token_file", f"{path}: the token must be one word, one line")
        )
    return token


class SettingsFileSource(PydanticBaseSettingsSource):
    """The settings file named by a higher source's ``settings_file`` (CLI flag or variable).

    JSON (``.json``) or TOML (anything else); keys are the setting names, optionally under a
    top-level ``[tracker]`` table."""

    def get_field_value(self, field: FieldInfo, field_name: str) -> tuple[Any, str, bool]:
        return None, field_name, False  # unused: __call__ reads the whole file at once

    def __call__(self) -> dict[str, Any]:
        path = self.current_state.get("settings_file")
        if not path:
            return {}
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise SettingsLoadError(f"settings file {path}: {exc.strerror or exc}") from None
        try:
            data = json.loads(text) if path.suffix.lower() == ".json" else tomllib.loads(text)
        except (ValueError, tomllib.TOMLDecodeError) as exc:
            raise SettingsLoadError(f"settings file {path}: {exc}") from None
        if not isinstance(data, dict):
            raise SettingsLoadError(f"settings file {path}: expected a table of settings")
        if isinstance(data.get("tracker"), dict) and len(data) == 1:
            data = data["tracker"]
        out = {}
        for key, value in data.items():
            name = str(key).lower().replace("-", "_")
            if name.startswith("tracker_"):
                name = name[len("tracker_") :]
            out[name] = value
        out.pop("settings_file", None)
        return out


class SettingsLoadError(Exception):
    """A setting could not be used; the message says which and why."""


def _default_text(name: str, field: FieldInfo) -> str | None:
    """A setting's default as its flag would take it; None when there is none to show."""
    if name == "instance_id":
        return "random"  # a new one from its factory on every start
    if name == "api_token":
        return None
    if name == "config_file":
        return f"<state_dir>/{DEFAULT_CONFIG_NAME}"
    default = field.get_default(call_default_factory=True)
    if default is None:
        return None
    if isinstance(default, list):  # endpoint lists, as split_endpoints reads them
        return ",".join(default) or "none"
    return str(default)


def build_parser(prog: str = "tracker-service") -> argparse.ArgumentParser:
    """One flag per setting (``--zenoh-mode`` for ``zenoh_mode``); unset flags do not override."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description=(
            "Real-time multi-target tracking service: detection batches in over Zenoh or "
            "REST, tracks out over Zenoh and REST. Every flag is also an environment "
            "variable TRACKER_<NAME> and a key of the settings file."
        ),
        argument_default=argparse.SUPPRESS,
    )
    for name, field in Settings.model_fields.items():
        flag = "--" + name.replace("_", "-")
        help_text = field.description or ""
        default = _default_text(name, field)
        if default is not None:
            help_text += f" (default: {default})"
        if name == "demo":  # --demo, --demo SCENARIO, --no-demo
            parser.add_argument(
                flag,
                nargs="?",
                const=True,  # --demo alone: on, with demo_scenario (continuous by default)
                choices=DEMO_SCENARIOS,
                metavar="SCENARIO",
                help=help_text,
            )
            parser.add_argument("--no-demo", dest=name, action="store_false", help="no demo")
        elif field.annotation is bool:
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, help=help_text)
        else:
            parser.add_argument(flag, metavar=name.upper(), help=help_text)
    return parser


def _describe(exc: ValidationError) -> str:
    lines = []
    for err in exc.errors(include_url=False):
        name = ".".join(str(p) for p in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        if not name:  # a check of the settings together: its message says it all
            lines.append(msg)
            continue
        value = err.get("input")
        shown = f" (got {value!r})" if isinstance(value, str | int | float) and value != "" else ""
        if err["type"] == "extra_forbidden":
            msg = "unknown setting"
        lines.append(f"invalid setting {name} / TRACKER_{name.upper()}: {msg}{shown}")
    return "\n".join(lines)


def api_token_source(argv: Sequence[str] | None = None) -> str:
    """Where the ``api_token`` that :func:`load_settings` found for ``argv`` came from (when
    one was found): the flag, the environment, or else the settings file."""
    if "api_token" in vars(build_parser().parse_known_args(argv)[0]):
        return "the --api-token flag"
    if any(k.upper() == "TRACKER_API_TOKEN" and v.strip() for k, v in os.environ.items()):
        return "the TRACKER_API_TOKEN environment variable"
    return "the settings file"


def load_settings(argv: Sequence[str] | None = None, **overrides: Any) -> Settings:
    """Settings from ``argv`` (flags), the environment and the settings file.

    ``overrides`` act like flags. Raises :class:`SettingsLoadError` on any bad value.
    """
    parser = build_parser()
    args = vars(parser.parse_args(argv))
    args.update(overrides)
    try:
        return Settings(**args)
    except ValidationError as exc:
        raise SettingsLoadError(_describe(exc)) from None
    except SettingsLoadError:
        raise
    except Exception as exc:  # pydantic-settings wraps source errors in SettingsError
        cause = exc.__cause__ or exc.__context__
        if isinstance(cause, SettingsLoadError):
            raise cause from None
        raise SettingsLoadError(str(exc)) from None
