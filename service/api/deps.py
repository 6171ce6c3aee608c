"""Dependencies of the REST routers: the engine, the stats, the settings and the write token,
as ``Annotated[..., Depends()]`` aliases; and a JSON response class serialised by orjson."""

from __future__ import annotations

import secrets
from typing import Annotated, Any

import orjson
from fastapi import Depends, HTTPException, Request, status
from fastapi.responses import JSONResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from service.engine import Engine
from service.scale_out import ScaleOut
from service.settings import Settings
from service.stats import Stats

__all__ = [
    "EngineDep",
    "FastJSONResponse",
    "SettingsDep",
    "StatsDep",
    "WriteAccess",
    "federation_of",
    "get_engine",
    "get_settings",
    "get_stats",
    "require_token",
    "shared_config",
]


class FastJSONResponse(JSONResponse):
    """JSON rendered by orjson (numpy values allowed; NaN becomes null)."""

    def render(self, content: Any) -> bytes:
        return orjson.dumps(content, option=orjson.OPT_SERIALIZE_NUMPY)


def federation_of(request: Request) -> ScaleOut | None:
    """The scale-out part that answers federated track queries (setting ``federate``)."""
    settings: Settings = request.app.state.settings
    if not settings.federate:
        return None
    scale_out: ScaleOut | None = request.app.state.runtime.scale_out
    return scale_out


def shared_config(request: Request) -> ScaleOut | None:
    """The scale-out part that shares configuration changes (setting ``scale_out``)."""
    scale_out: ScaleOut | None = request.app.state.runtime.scale_out
    return scale_out


def get_engine(request: Request) -> Engine:
    engine: Engine = request.app.state.engine
    return engine


def get_stats(request: Request) -> Stats:
    stats: Stats = request.app.state.stats
    return stats


def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


_bearer = HTTPBearer(
    auto_error=False,
    description="The service's API token (TRACKER_API_TOKEN; printed at start-up when generated).",
)


def require_token(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)],
) -> None:
    """Let the request through only with ``Authorization: Bearer <the API token>``."""
    expected: str = request.app.state.api_token
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="missing bearer token: send 'Authorization: Bearer <token>'",
            headers={"WWW-Authenticate": "Bearer"},
        )
    if not secrets.compare_digest(credentials.credentials.encode(), expected.encode()):
        raise HTTPException(
            status_code=status.HTTP_401_UNAUTHORIZED,
            detail="invalid bearer token",
            headers={"WWW-Authenticate": 'Bearer error="invalid_token"'},
        )


EngineDep = Annotated[Engine, Depends(get_engine)]
StatsDep = Annotated[Stats, Depends(get_stats)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
WriteAccess = Annotated[None, Depends(require_token)]
