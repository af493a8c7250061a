"""The api's outermost checks: a request id on every request and response, and NUL bytes refused.

Every response carries ``X-Request-ID`` (the error handlers also put it in the error body and the log
line of a server error, so a user's report finds the server-side traceback). A NUL byte in the path
(an id) is a 404 and one in the query string (a filter) a 422, before any route or query runs:
PostgreSQL refuses NUL in text, which answered 500 on every id route.
"""

from __future__ import annotations

import uuid
from urllib.parse import unquote_to_bytes

from fastapi.responses import JSONResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

REQUEST_ID_HEADER = "X-Request-ID"


def request_id_of(scope: Scope) -> str | None:
    state = scope.get("state")
    return state.get("request_id") if isinstance(state, dict) else None


class EdgeMiddleware:
    """Pure ASGI (no body buffering, streams pass through untouched)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        rid = uuid.uuid4().hex
        state = scope.setdefault("state", {})
        state["request_id"] = rid
        header = (REQUEST_ID_HEADER.lower().encode(), rid.encode())

        async def send_with_id(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                if all(k.lower() != header[0] for k, _ in headers):
                    headers.append(header)
                message = {**message, "headers": headers}
            await send(message)

        refused = _nul_refusal(scope)
        if refused is not None:
            status, code, message = refused
            body = {"error": {"code": code, "message": message, "detail": None, "request_id": rid}}
            await JSONResponse(body, status_code=status)(scope, receive, send_with_id)
            return
        await self.app(scope, receive, send_with_id)


def _nul_refusal(scope: Scope) -> tuple[int, str, str] | None:
    path = scope.get("path", "")
    raw_path = scope.get("raw_path") or b""
    if "\x00" in path or b"%00" in raw_path.lower():
        return 404, "not_found", "no resource has a NUL character in its path"
    query = scope.get("query_string", b"")
    if b"\x00" in query or b"\x00" in unquote_to_bytes(query):
        return 422, "invalid_input", "query parameters must not contain NUL characters"
    return None
