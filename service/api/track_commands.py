"""What the routes that make tracks by hand share (``POST /api/v1/tracks/extended`` and
``/formation``): the request body's schema in the OpenAPI document, and the run of one request:
its body read within a bound and decoded (422 naming the field), the command run on the
tracker's worker (:meth:`service.engine.Engine.call_in_worker`), its refusal mapped to 409 or
422 and an unavailable worker to 503, the new Track answered with 201."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from fastapi import HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response
from pydantic import BaseModel

from service.api.deps import FastJSONResponse
from service.api.detections import read_body
from service.engine import CommandRefused, EngineUnavailable

__all__ = ["json_body", "run_track_command"]

M = TypeVar("M", bound=BaseModel)


def _inlined(schema: dict[str, Any]) -> dict[str, Any]:
    """``schema`` with its ``$defs`` put in place of their ``$ref`` (none is recursive), so
    it stands on its own inside the OpenAPI document."""
    defs = schema.pop("$defs", {})

    def walk(node: Any) -> Any:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                rest = {k: v for k, v in node.items() if k != "$ref"}
                return {**walk(defs[ref.removeprefix("#/$defs/")]), **walk(rest)}
            return {k: walk(v) for k, v in node.items()}
        if isinstance(node, list):
            return [walk(v) for v in node]
        return node

    out: dict[str, Any] = walk(schema)
    return out


def json_body(model: type[BaseModel], description: str) -> dict[str, Any]:
    """The ``openapi_extra`` of a route whose required JSON body is ``model``."""
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {"application/json": {"schema": _inlined(model.model_json_schema())}},
        }
    }


async def run_track_command(
    request: Request,
    max_bytes: int,
    decode: Callable[[bytes], M],
    command: Callable[[M], Callable[[], dict[str, Any]]],
) -> Response:
    """Read and ``decode`` the body (at most ``max_bytes``), run ``command(body)()`` in a
    thread (it waits for the worker), and answer 201 with the Track it returns."""
    payload, size = await read_body(request, max_bytes)
    if payload is None:
        raise HTTPException(status_code=422, detail=f"the body is {size} bytes, over {max_bytes}")
    try:
        body = decode(payload)
    except ValueError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    try:
        track = await run_in_threadpool(command(body))
    except CommandRefused as exc:
        raise HTTPException(status_code=409 if exc.conflict else 422, detail=exc.detail) from None
    except EngineUnavailable as exc:
        raise HTTPException(status_code=503, detail=str(exc)) from None
    return FastJSONResponse(track, status_code=201)
