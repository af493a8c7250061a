"""One error shape for every failure: ``{"error": {"code", "message", "detail"}}``.

Domain errors (:class:`storage.errors.StorageError`) and the api's own (:class:`ApiError`) keep their
status and code; request validation errors become 422 ``invalid_input``; HTTP errors (unknown route,
wrong method) keep their status; anything else, and a domain 5xx (it may wrap a database error and its
SQL), is a 500 whose message gives nothing away. Messages and details lose server paths; every error body
has the request's ``request_id`` (also the ``X-Request-ID`` header), which the server log names too.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from backend.api.edge import REQUEST_ID_HEADER, request_id_of
from storage.errors import InsufficientStorage, ServiceError, StorageError, Unauthorized, Unreadable
from storage.redact import redact_paths

log = logging.getLogger("backend.api")

_HTTP_CODES = {
    400: "bad_request",
    401: "unauthorized",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    406: "not_acceptable",
    408: "request_timeout",
    409: "conflict",
    411: "length_required",
    413: "payload_too_large",
    415: "unsupported_media_type",
    416: "range_not_satisfiable",
    422: "invalid_input",
    429: "too_many_requests",
    431: "headers_too_large",
    507: "insufficient_storage",
}


class ApiError(ServiceError):
    """An error of the api itself (a dependency it fronts is down), not of the domain: same body shape."""

    code = "api_error"
    http_status = 503


def error_body(code: str, message: str, detail: Any = None, request_id: str | None = None) -> dict[str, Any]:
    """The error shape; ``detail`` made JSON-safe (non-finite numbers as strings), never failing."""
    try:
        safe = _json_safe(jsonable_encoder(detail))
    except Exception:  # a detail that cannot be encoded is dropped, the error still answers
        safe = None
    return {"error": {"code": code, "message": message, "detail": safe, "request_id": request_id}}


def _json_safe(value: Any, depth: int = 0) -> Any:
    if depth > 8:
        return None
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, str):
        return value[:2000]
    if isinstance(value, dict):
        return {str(k)[:200]: _json_safe(v, depth + 1) for k, v in list(value.items())[:50]}
    if isinstance(value, list | tuple):
        return [_json_safe(v, depth + 1) for v in list(value)[:50]]
    return value


ERROR_SCHEMA = {
    "type": "object",
    "properties": {
        "error": {
            "type": "object",
            "properties": {
                "code": {"type": "string"},
                "message": {"type": "string"},
                "detail": {},
                "request_id": {"type": ["string", "null"], "description": "Quote it when reporting a problem."},
            },
            "required": ["code", "message"],
        }
    },
}


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI ``responses`` entries for the error statuses a route may return."""
    return {
        s: {
            "description": _HTTP_CODES.get(s, "error").replace("_", " "),
            "content": {"application/json": {"schema": ERROR_SCHEMA}},
        }
        for s in statuses
    }


def install_error_handlers(app: FastAPI) -> None:
    """Every handler answers whatever the exception holds: no SQL, no server path, a request id."""
    data_dir = app.state.settings.data_dir

    def respond(
        request: Request, status: int, code: str, message: str, detail: Any = None,
        headers: Mapping[str, str] | None = None,
    ) -> JSONResponse:
        rid = request_id_of(request.scope)
        try:
            body = error_body(code, redact_paths(message, data_dir), _redact(detail, data_dir), rid)
            response = JSONResponse(body, status_code=status, headers=headers)
        except Exception:  # never fail while reporting a failure
            log.exception("request %s: could not build the error response", rid)
            body = error_body("internal_error", "internal server error", None, rid)
            response = JSONResponse(body, status_code=500)
        if rid:
            response.headers[REQUEST_ID_HEADER] = rid
        return response

    @app.exception_handler(ServiceError)  # the domain's (StorageError) and the api's own (ApiError)
    async def _service_error(request: Request, exc: ServiceError) -> JSONResponse:
        headers = {"WWW-Authenticate": "Bearer"} if isinstance(exc, Unauthorized) else None
        if exc.http_status >= 500 and not isinstance(exc, ApiError):
            # a domain 5xx may wrap a database error (its SQL and parameters): logged, never sent
            log.error("request %s: server error: %s", request_id_of(request.scope), exc.message, exc_info=exc)
            return respond(request, exc.http_status, exc.code, "internal server error")
        if exc.http_status >= 500:
            log.error("request %s: %s", request_id_of(request.scope), exc.message)
        return respond(request, exc.http_status, exc.code, exc.message, exc.detail, headers)

    @app.exception_handler(Unreadable)
    @app.exception_handler(InsufficientStorage)
    async def _operator_error(request: Request, exc: StorageError) -> JSONResponse:
        """Server-side conditions the operator must fix (a full disk, files it cannot read): said in words,
        since they carry no SQL (paths are redacted like every message)."""
        log.error("request %s: %s", request_id_of(request.scope), exc.message, exc_info=exc.__cause__)
        return respond(request, exc.http_status, exc.code, exc.message, exc.detail)

    @app.exception_handler(RequestValidationError)
    async def _validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            {"loc": list(e.get("loc", ())), "msg": e.get("msg", ""), "type": e.get("type", "")}
            for e in exc.errors()
        ]
        first = errors[0] if errors else {"loc": [], "msg": "invalid request"}
        where = ".".join(str(p) for p in first["loc"] if p != "body") or "request"
        return respond(request, 422, "invalid_input", f"{where}: {first['msg']}", errors)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        code = _HTTP_CODES.get(exc.status_code, "http_error")
        return respond(request, exc.status_code, code, str(exc.detail), None, exc.headers)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.error("request %s: unhandled error", request_id_of(request.scope), exc_info=exc)
        return respond(request, 500, "internal_error", "internal server error")


def _redact(detail: Any, data_dir: Path) -> Any:
    if isinstance(detail, str):
        return redact_paths(detail, data_dir)
    if isinstance(detail, dict):
        return {k: _redact(v, data_dir) for k, v in detail.items()}
    if isinstance(detail, list | tuple):
        return [_redact(v, data_dir) for v in detail]
    return detail
