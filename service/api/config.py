"""The tracker configuration: ``GET``, ``PUT`` (replace) and ``PATCH`` (merge)
``/api/v1/config``.

Writes need ``Authorization: Bearer <token>``, are validated as a whole (422 naming the
field, nothing changes), saved to the config file when one is set, and take effect on the
next batch. The answer's body is the document in force; its headers ``X-Config-Changed``
(``motion.q_cv 0.5 -> 1.0; ...``) and ``X-Config-Saved-To`` say what changed and where it
was saved, and the log says the same (``configuration applied: ...``).
"""

from __future__ import annotations

from typing import Any
from urllib.parse import quote

import orjson
from fastapi import APIRouter, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service.api.deps import EngineDep, FastJSONResponse, WriteAccess, shared_config
from service.config_tree import ConfigDocument, ConfigError
from service.engine import Engine

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


#: Headers of a PUT or PATCH answer that say what it did (the body stays the document).
CHANGED_HEADER = "X-Config-Changed"
SAVED_TO_HEADER = "X-Config-Saved-To"
_MAX_HEADER_CHARS = 4000


def _header_value(text: str) -> str:
    """``text`` as a header value: non-ASCII characters percent-encoded, cut to a length
    every proxy passes."""
    if not text.isascii():
        text = quote(text, safe=" /:;,.-_~>()[]{}\"'=+*!@$&|<")
    if len(text) > _MAX_HEADER_CHARS:
        text = text[: _MAX_HEADER_CHARS - 4] + " ..."
    return text


async def _apply(request: Request, engine: Engine, doc: Any, *, merge: bool) -> Response:
    try:
        applied = await run_in_threadpool(lambda: engine.apply_config(doc, merge=merge))
    except ConfigError as exc:
        raise HTTPException(status_code=422, detail=str(exc)) from None
    except OSError as exc:
        raise HTTPException(status_code=500, detail=str(exc)) from None
    share = shared_config(request)
    if share is not None and applied.changes:  # every instance of a scaled-out deployment
        share.share_config(applied.document)
    response = FastJSONResponse(applied.document)
    response.headers[CHANGED_HEADER] = _header_value("; ".join(applied.changes) or "none")
    if applied.saved_to is not None:
        response.headers[SAVED_TO_HEADER] = _header_value(str(applied.saved_to))
    return response


_CHANGE_HEADERS = {
    CHANGED_HEADER: {
        "description": (
            "what changed, `section.field old -> new` joined by `; ` (`none` when nothing did)"
        ),
        "schema": {"type": "string"},
    },
    SAVED_TO_HEADER: {
        "description": "the config file it was saved to (absent when there is none)",
        "schema": {"type": "string"},
    },
}
_WRITE_RESPONSES[200] = {
    "description": "the configuration now in force",
    "headers": _CHANGE_HEADERS,
}


@router.put(
    "",
    response_model=ConfigDocument,
    summary="Replace the configuration (missing fields take their defaults)",
    openapi_extra=_body("ConfigDocument", "the whole configuration document"),
    responses=_WRITE_RESPONSES,
)
async def put_config(request: Request, engine: EngineDep, _auth: WriteAccess) -> Response:
    return await _apply(request, engine, await _read_json(request), merge=False)


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
    return await _apply(request, engine, await _read_json(request), merge=True)
