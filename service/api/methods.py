"""``OPTIONS`` and ``405 Method Not Allowed`` that tell the truth about a path's methods.

Each HTTP method of a path is its own route (``GET``, ``PUT`` and ``PATCH /api/v1/config``),
and the router's 405 names only the first route's methods in ``Allow``. This ASGI middleware
answers ``OPTIONS`` with ``204`` and sets ``Allow`` on a 405 to every method the OpenAPI
document gives the path (``HEAD`` with ``GET``, and ``OPTIONS``). It costs one string
comparison on any other request.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from functools import cached_property
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

__all__ = ["AllowedMethods"]


class AllowedMethods:
    """``openapi`` gives the app's OpenAPI document, whose paths and methods are the truth."""

    def __init__(self, app: ASGIApp, openapi: Callable[[], dict[str, Any]]) -> None:
        self.app = app
        self.openapi = openapi

    @cached_property
    def _paths(self) -> list[tuple[re.Pattern[str], list[str]]]:
        out = []
        for template, operations in self.openapi().get("paths", {}).items():
            pattern = re.escape(template)
            pattern = re.sub(r"\\\{[^/]+?\\\}", "[^/]+", pattern)
            methods = {m.upper() for m in operations if m.isalpha()}
            if "GET" in methods:
                methods.add("HEAD")
            out.append((re.compile(f"^{pattern}$"), sorted(methods | {"OPTIONS"})))
        return out

    def allowed(self, path: str) -> list[str]:
        """Every method the API documents for ``path`` (with ``HEAD`` and ``OPTIONS``), or
        ``[]`` for a path it does not document."""
        for pattern, methods in self._paths:
            if pattern.match(path):
                return methods
        return []

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["method"] == "OPTIONS":
            allowed = self.allowed(scope["path"])
            if allowed:
                headers = [(b"allow", ", ".join(allowed).encode()), (b"content-length", b"0")]
                await send({"type": "http.response.start", "status": 204, "headers": headers})
                await send({"type": "http.response.body", "body": b""})
                return

        async def send_with_allow(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                allowed = self.allowed(scope["path"])
                if allowed:
                    headers: list[Any] = [
                        (k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"
                    ]
                    allow = (b"allow", ", ".join(allowed).encode())
                    message = {**message, "headers": [*headers, allow]}
            await send(message)

        await self.app(scope, receive, send_with_allow)
