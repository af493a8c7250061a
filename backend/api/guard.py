"""Routes that check the API token and cap a JSON body *before* FastAPI reads the body.

FastAPI reads and parses a route's JSON body before it runs the route's dependencies. With the ``Auth``
dependency alone, an anonymous client could make the api buffer a body of any size in memory, and would
get 400/422 validation answers (learning the schema) instead of 401. :class:`GuardedRoute` runs the
same token check first and reads a JSON body itself, up to :data:`MAX_JSON_BYTES` (413 beyond), and
refuses what no JSON body may hold (:mod:`storage.jsonlimits`: deep nesting, NaN, NUL) with a 422.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any

from fastapi import Request, Response
from fastapi.routing import APIRoute
from starlette.types import Message, Receive

from backend.api.deps import check_token, require_token
from storage.errors import PayloadTooLarge
from storage.jsonlimits import parse_json

MAX_JSON_BYTES = 1 << 20
"""Job and batch requests are a few kB (config overrides are capped at 64 k characters)."""

Handler = Callable[[Request], Coroutine[Any, Any, Response]]


class GuardedRoute(APIRoute):
    """Use as ``APIRouter(route_class=GuardedRoute)``; routes with ``dependencies=[Auth]`` get the check."""

    def get_route_handler(self) -> Handler:
        handler = super().get_route_handler()
        guarded = any(dep.dependency is require_token for dep in self.dependencies)
        capped = self.body_field is not None
        if not (guarded or capped):
            return handler

        async def guarded_handler(request: Request) -> Response:
            if guarded:
                check_token(request)
            if capped:
                receive, body = await _buffered(request, MAX_JSON_BYTES)
                _check_json_body(request, body)
                request = Request(request.scope, receive)
            return await handler(request)

        return guarded_handler


def _check_json_body(request: Request, body: bytes) -> None:
    """Nesting, non-finite numbers, NUL characters (:mod:`storage.jsonlimits`) refused before any
    handler or query sees the body; a body that is no JSON at all is left to FastAPI's own 422."""
    if not body.strip() or "json" not in request.headers.get("content-type", "application/json"):
        return
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        return
    if text.lstrip()[:1] in ("{", "["):
        parse_json(text, "request body")


async def _buffered(request: Request, limit: int) -> tuple[Receive, bytes]:
    """Read the body (at most ``limit`` bytes, else 413) and give a ``receive`` that replays it."""
    length = request.headers.get("content-length", "")
    if length.isascii() and length.isdigit() and int(length) > limit:
        raise PayloadTooLarge(f"the request body is larger than {limit} bytes", {"max_bytes": limit})
    body = bytearray()
    async for chunk in request.stream():
        body += chunk
        if len(body) > limit:
            raise PayloadTooLarge(f"the request body is larger than {limit} bytes", {"max_bytes": limit})
    replayed = False

    async def receive() -> Message:
        nonlocal replayed
        if not replayed:
            replayed = True
            return {"type": "http.request", "body": bytes(body), "more_body": False}
        return await request.receive()  # after the body: disconnect notifications

    return receive, bytes(body)
