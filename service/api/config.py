"""The tracker configuration: ``GET``, ``PUT`` (replace) and ``PATCH`` (merge)
``/api/v1/config``.

Writes need ``Authorization: Bearer <token>``, are validated as a whole (422 naming the
field, nothing changes), saved to the config file when one is set, and take effect on the
next batch.
"""

from __future__ import annotations

from typing import Any

import orjson
from fastapi import APIRouter, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, WriteAccess
from service.config_tree import ConfigDocument, ConfigError

__all__ = ["router"]

router = APIRouter(prefix="/config", tags=["config"])


def _body(model: str, description: str) -> dict[str, Any]:
    return {
        "requestBody": {
            "required": True,
            "description": description,
            "content": {"application/json": {"schema": {"$ref": f"#/components/schemas/{model}"}}},
        }
    }


_WRITE_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"description": "no or a wrong bearer token"},
    422: {
        "description": (
            "invalid: `detail` names the field; nothing changed. Besides the schema's types "
            "and bounds, rules across fields: `motion`'s lists have one entry per model and "
            "its mode probabilities sum to 1; the confirmation threshold (from "
            "`p_false_confirm`, `p_true_delete`) must exceed the deletion threshold"
        )
    },
}


@router.get("", response_model=ConfigDocument, summary="The tracker configuration")
async def get_config(engine: EngineDep) -> Response:
    return FastJSONResponse(engine.config_document())


async def _read_json(request: Request) -> Any:
    raw = await request.body()
    try:
        return orjson.loads(raw)
    except orjson.JSONDecodeError as exc:
        raise HTTPException(status_code=422, detail=f"invalid JSON: {exc}") from None


async def _apply(method: Any, doc: Any) -> Response:
    try:
        out = await run_in_threadpool(method, doc)
    except ConfigError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    except OSError as exc:
        raise HTTPException(status_code=500, detail=str(exc)) from None
    return FastJSONResponse(out)


@router.put(
    "",
    response_model=ConfigDocument,
    summary="Replace the configuration (missing fields take their defaults)",
    openapi_extra=_body("ConfigDocument", "the whole configuration document"),
    responses=_WRITE_RESPONSES,
)
async def put_config(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    return await _apply(engine.replace_config, await _read_json(request))


@router.patch(
    "",
    response_model=ConfigDocument,
    summary="Change some fields (JSON merge patch: null resets a field to its default)",
    openapi_extra=_body(
        "ConfigPatch", "the fields to change, nested as in the document; null resets one"
    ),
    responses=_WRITE_RESPONSES,
)
async def patch_config(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    return await _apply(engine.patch_config, await _read_json(request))
